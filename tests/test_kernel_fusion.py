"""The real-time kernels compile to few, fused loops: XLA's cost analysis per shading point.

Deterministic (no timing): `jax.jit(f).lower(...).compile().cost_analysis()` of the float32
kernels on 65,536 abstract points (`jax.ShapeDtypeStruct`: nothing is evaluated). Before the
kernels were written for fusion (explicit real-part arithmetic, flat LUT indices, no
contraction or reduction), XLA:CPU materialised their intermediates between ~35 loops:
3,300 bytes accessed per point for `filtered_kernel` and 3,052 for `ideal_kernel`, with 19
and 17 transcendentals (`thinfilm_jax.studies.kernel_bench` measures both versions).
The bounds pin what the fused kernels achieve (measured: 1,462 and 914 bytes, 7 and 5
transcendentals, jax 0.10.2 on x86-64) with a 10 % margin; a kernel that falls back to
unfused loops (a contraction, a reduction or a stacked polarisation axis) exceeds them.
"""

import jax
import jax.numpy as jnp
import pytest

from thinfilm_jax import Film
from thinfilm_jax.kernels import filtered_kernel, ideal_kernel
from thinfilm_jax.lut import build_shat_lut

N = 65536
F32 = jnp.float32


def _spec(*shape):
    return jax.ShapeDtypeStruct((N, *shape), F32)


def _cost(fn, *args):
    compiled = jax.jit(fn).lower(*args).compile()
    ca = compiled.cost_analysis()
    ca = ca[0] if isinstance(ca, list) else ca
    return {k: ca.get(k, 0.0) / N for k in ("bytes accessed", "transcendentals")}, \
        compiled.as_text()


@pytest.fixture(scope="module")
def lut():
    return build_shat_lut(dtype=F32)


@pytest.mark.parametrize("kernel, max_bytes, max_trans", [("filtered", 1610, 7.5),
                                                          ("ideal", 1010, 5.5)])
def test_kernel_bytes_per_point(lut, kernel, max_bytes, max_trans):
    film = Film(*(_spec() for _ in range(5)))
    if kernel == "filtered":
        cost, hlo = _cost(lambda f, w, m, c, t: filtered_kernel(f, w, m, c, shat="lut", lut=t),
                          film, _spec(3), _spec(3), _spec(3, 3), lut)
    else:
        cost, hlo = _cost(lambda f, c, t: ideal_kernel(f, c, shat="lut", lut=t), film,
                          _spec(), lut)
    assert cost["bytes accessed"] < max_bytes, cost
    assert cost["transcendentals"] < max_trans, cost
    entry = hlo[hlo.index("ENTRY"):]
    assert " dot(" not in entry and "__ynn_fusion" not in entry  # no contraction/reduction
