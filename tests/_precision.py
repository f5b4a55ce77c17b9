"""Reusable check: every matrix contraction of a traced function states HIGHEST precision.

On GPUs, float32 `dot_general` defaults to TF32 (10-bit mantissa), which silently breaks
float32 accuracy. Traced on the CPU, a contraction written without ``precision=`` shows up
in the jaxpr as a `dot_general` whose ``precision`` parameter is None (or DEFAULT), so the
check needs no GPU:

    from _precision import assert_contractions_precise
    assert_contractions_precise(my_fn, x32, y32, static_kw=...)

Sub-jaxprs (pjit, custom_jvp/vjp, scan, while, cond, remat, ...) are searched recursively.
"""

from __future__ import annotations

from collections.abc import Iterator

import jax
from jax.extend import core as jex_core

HIGHEST = jax.lax.Precision.HIGHEST


def _sub_jaxprs(value) -> Iterator:
    """Jaxprs held in an equation parameter (a Jaxpr, a ClosedJaxpr, or sequences of them)."""
    if isinstance(value, jex_core.ClosedJaxpr):
        yield value.jaxpr
    elif isinstance(value, jex_core.Jaxpr):
        yield value
    elif isinstance(value, (tuple, list)):
        for v in value:
            yield from _sub_jaxprs(v)


def iter_eqns(jaxpr, path=()) -> Iterator:
    """(equation, path of enclosing primitive names) over a jaxpr and all its sub-jaxprs."""
    for eqn in jaxpr.eqns:
        yield eqn, path
        for name, value in eqn.params.items():
            for sub in _sub_jaxprs(value):
                yield from iter_eqns(sub, (*path, f"{eqn.primitive.name}.{name}"))


def precision_is_highest(precision) -> bool:
    """True for Precision.HIGHEST (single or per operand) or an explicit full-float32
    dot algorithm; False for None (the backend default: TF32 on GPUs) or lower settings."""
    if precision is None:
        return False
    if isinstance(precision, tuple):
        return all(p == HIGHEST for p in precision)
    if isinstance(precision, jax.lax.DotAlgorithmPreset):
        return precision.name in ("F32_F32_F32", "F64_F64_F64")
    return precision == HIGHEST


def imprecise_contractions(fn, *args, **kwargs) -> list[str]:
    """Descriptions of the `dot_general`s of ``fn(*args, **kwargs)`` whose precision is not
    HIGHEST (keyword arguments are closed over: they may be static)."""
    closed = jax.make_jaxpr(lambda *a: fn(*a, **kwargs))(*args)
    bad = []
    for eqn, path in iter_eqns(closed.jaxpr):
        if eqn.primitive.name == "dot_general":
            p = eqn.params.get("precision")
            if not precision_is_highest(p):
                shapes = [str(v.aval) for v in eqn.invars]
                where = ""
                info = getattr(eqn, "source_info", None)
                if info is not None:
                    try:
                        from jax._src import source_info_util

                        where = " at " + source_info_util.summarize(info)
                    except Exception:  # noqa: BLE001  (best-effort location only)
                        where = ""
                bad.append(f"dot_general{shapes} precision={p} in {'/'.join(path) or 'top'}"
                           f"{where}")
    return bad


def count_contractions(fn, *args, **kwargs) -> int:
    """Number of `dot_general`s in the trace (to show that a check looked at something)."""
    closed = jax.make_jaxpr(lambda *a: fn(*a, **kwargs))(*args)
    return sum(eqn.primitive.name == "dot_general" for eqn, _ in iter_eqns(closed.jaxpr))


def assert_contractions_precise(fn, *args, **kwargs) -> None:
    """Fail if any matrix contraction traced from ``fn(*args, **kwargs)`` lacks
    ``precision=HIGHEST``."""
    bad = imprecise_contractions(fn, *args, **kwargs)
    assert not bad, "contractions without precision=HIGHEST:\n  " + "\n  ".join(bad)
