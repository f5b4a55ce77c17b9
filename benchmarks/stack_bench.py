"""Speed and agreement of `stack_reflectance` / `stack_transmittance` (SPEC §12) against the
peer multilayer codes on one CPU: `tmm` (Byrnes' `coh_tmm`, one (θ, λ, polarisation) per
Python call, float64), `tmmax` (JAX, float32 only) and `tmm_fast` (PyTorch, float64).

``python -m benchmarks.stack_bench --out figures`` writes ``stack_bench.json`` and
``stack_bench.md`` (`write_report`). Not run by the test suite. Needs `tmm` and `tmmax`
(``pip install tmmax``: the stacks are built from its material tables); `tmm_fast` runs in a
separate interpreter (``--peers-python``, default ``/tmp/peers-venv/bin/python``) and is
skipped, reported as such, when that interpreter or the package is missing.

**The stacks are tmmax's own materials**, so that tmmax can be called through its public API
(`tmmax.tmm(material_list, thickness_list, wavelength_arr, angle_of_incidences,
polarization=...)`, which takes materials by name only): outer medium ``"Air"``, then
alternating ``"SiO2"`` (95 nm) / ``"TiO2"`` (60 nm), the last layer 15 nm of ``"Ge"`` (an
absorbing layer, κ ≈ 1.4–2.8 here; tmmax has no silver), on a ``"SiO2"`` base; 8 and 80
layers; 64 angles (0–85°) × 100 wavelengths (400–800 nm). Every other code gets the same n and
κ: tmmax's tables (``tmmax/nk_data/numpy/<name>.npy``, the files `tmmax.tmm` loads; λ in µm)
as our `TabulatedIndex` (linear in λ, n and κ separately, as tmmax's `jnp.interp`), evaluated
at the grid for tmm and tmm_fast. tmmax interpolates its float32 table itself.

tmmax's conventions (1.1.4, read from its source): SI units (thicknesses and wavelengths in
m; its tables' µm are scaled by 1e-6), angles in radians (checked to lie in [0, π/2]), the
material list from the outer medium to the base with both semi-infinite media included and
the thickness list for the N layers only, results of shape (angles, wavelengths), one
polarisation per call; complex64 is hard-coded (it fails to trace with x64 on), so it runs in
a subprocess with JAX's default x64 off.

**tmmax 1.1.4 is wrong for two or more layers** (`tmmax_quarter_wave` and the table's
max |Δ| show it): in ``tmmax/cascaded_matmul.py:coh_matmul`` each layer matrix entry is built
as ``exp(jnp.array([-1j]) * phase)``, shape (1,), so the "2 × 2" matrix has shape (2, 2, 1) and
``jnp.matmul(carry, M)`` broadcasts as a batch of two columns: the scan returns
``M_k · C_{k−1}ᵀ`` instead of ``C_{k−1} · M_k`` (for one layer C = I and the result is right).
The study therefore runs tmmax twice in separate interpreters: as shipped, and with that one
function replaced by the intended product ``C · M_k`` (`_TMMAX_FIX`: same operations on
scalar entries; nothing else of tmmax changed). The ratio against tmmax is reported only for
a run whose R and T agree with tmm within `TOL_TMMAX`.

Work per code: R and T, both polarisations, on the whole grid (for tmm on a random subset of
`--tmm-calls` (θ, λ) pairs, scaled to the grid). tmmax is timed two ways: its public
`tmmax.tmm` (which also reloads the tables from disk and rebuilds them on every call, as
written) and the jitted kernel it dispatches to, `tmmax.tmm.vectorized_coh_tmm`, on the data
array `tmmax.data.create_data` builds (made once, outside the timing). Ours is timed in
float64 and float32 (tmmax computes in float32). Warm time: the median of `--repeats` calls
after the first; compile time: first call minus warm.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.core.stack import Stack
from thinfilm_jax.optics.index import TabulatedIndex
from thinfilm_jax.optics.stack import stack_reflectance, stack_transmittance
from ._timing import environment, fmt, log, time_call, time_host, write_report

N_ANGLES, N_WAVELENGTHS = 64, 100
OUTER, LOW, HIGH, ABSORBER, BASE = "Air", "SiO2", "TiO2", "Ge", "SiO2"
D_LOW, D_HIGH, D_ABSORBER = 95.0, 60.0, 15.0

#: Agreement required of a tmmax run (float32) with tmm (float64) before its time is compared:
#: max |ΔR|, |ΔT| over both polarisations at the tmm pairs. Our own float32 reaches ~1e-5 on
#: these stacks (the table's "ours f32" column), so 1e-3 leaves float32 room, and a wrong
#: product (errors of 0.1 to 10³ here) cannot pass.
TOL_TMMAX = 1e-3

#: Targets (reported, not asserted): ours at least this many times tmm's Python loop, faster
#: than tmmax in the same run, and the ambition of 3× tmmax.
TARGET_VS_TMM, TARGET_VS_TMMAX, AMBITION_VS_TMMAX = 100.0, 1.0, 3.0


def tmmax_table(name: str) -> TabulatedIndex:
    """tmmax's table of material `name` (``nk_data/numpy/<name>.npy``: rows λ (µm), n, κ,
    float32) as a `TabulatedIndex` (λ in nm, rounded to 1e-4 nm so that float32's 0.4 µm is
    400 nm, not 400.000006)."""
    import tmmax

    t = np.load(os.path.join(tmmax.nk_data_dir, "numpy", f"{name}.npy")).astype(float)
    return TabulatedIndex(np.round(t[0] * 1e3, 4), t[1], t[2], name=f"tmmax {name}",
                          citation="tmmax 1.1.4 nk_data")


def layout(n_layers: int):
    """(thickness (N,) nm, the N + 2 tmmax material names from the outer medium to the base):
    SiO₂/TiO₂ pairs, the last layer the absorber."""
    names = [LOW if i % 2 == 0 else HIGH for i in range(n_layers - 1)] + [ABSORBER]
    d = [D_LOW if i % 2 == 0 else D_HIGH for i in range(n_layers - 1)] + [D_ABSORBER]
    return np.array(d), [OUTER, *names, BASE]


def grid():
    theta = np.linspace(0.0, np.radians(85.0), N_ANGLES)
    lam = np.linspace(400.0, 800.0, N_WAVELENGTHS)
    return theta, lam


def index_table(models, lam):
    """(N + 2, L) complex indices of the outer medium, the layers and the base at `lam` (nm):
    the values ours interpolates, given to tmm and tmm_fast."""
    return np.stack([np.asarray(m(jnp.asarray(lam)), complex) for m in models])


# ---------------------------------------------------------------------------- the codes


def ours_fns(models):
    """Jitted (R_s, R_p, T_s, T_p) and unpolarised R alone, thickness (nm) as argument;
    `models` the N + 2 index models from the outer medium to the base."""
    outer, *eta, base = models

    def st(thickness):
        return Stack(thickness, tuple(eta), base, outer)

    @jax.jit
    def rt(thickness, cos, lam):
        s = st(thickness)
        return (stack_reflectance(s, cos, lam, "s"), stack_reflectance(s, cos, lam, "p"),
                stack_transmittance(s, cos, lam, "s"), stack_transmittance(s, cos, lam, "p"))

    @jax.jit
    def r_only(thickness, cos, lam):
        return stack_reflectance(st(thickness), cos, lam)

    return rt, r_only


#: The one function of tmmax 1.1.4 replaced in the "fixed" run: `coh_matmul`, the scan step
#: of `coh_cascaded_matrix_multiplication`, with the layer matrix
#: M_k = (1/t_k) [[e^{-iδ}, r_k e^{-iδ}], [r_k e^{iδ}, e^{iδ}]] built from scalar entries and
#: multiplied on the right of the carry, C_k = C_{k-1} · M_k (Byrnes, "Multilayer optical
#: calculations", arXiv:1603.02720, eq. 9–12), complex64 as tmmax.
_TMMAX_FIX = r"""
import jax.numpy as jnp
import tmmax.cascaded_matmul as _cm

def coh_matmul(carry, phase_r_t):
    phase, r, t = phase_r_t[0], phase_r_t[1], phase_r_t[2]
    e_minus, e_plus = jnp.exp(-1j * phase), jnp.exp(1j * phase)
    m = jnp.stack([jnp.stack([e_minus, r * e_minus]), jnp.stack([r * e_plus, e_plus])]) / t
    out = jnp.matmul(carry, m)
    return out, out

_cm.coh_matmul = coh_matmul
"""

_TMMAX_SCRIPT = r"""
import json, sys, time, statistics
import numpy as np, jax, jax.numpy as jnp   # JAX defaults: x64 off (tmmax hard-codes complex64)
mode, repeats = sys.argv[2], int(sys.argv[3])
if mode == "fixed":
    exec(open(sys.argv[4]).read())
import tmmax
from tmmax.tmm import tmm, vectorized_coh_tmm
from tmmax.data import create_data, material_distribution_to_set
z = np.load(sys.argv[1])
materials = json.loads(str(z["materials"]))
d = jnp.asarray(z["T"], jnp.float32)          # the N layer thicknesses, m
lam = jnp.asarray(z["lam"], jnp.float32)      # m
theta = jnp.asarray(z["theta"], jnp.float32)  # rad

def public():  # the documented entry point, one polarisation per call
    (rs, ts), (rp, tp) = (tmm(materials, d, lam, theta, polarization=p) for p in "sp")
    return rs, rp, ts, tp

material_set, distribution = material_distribution_to_set(materials)
data = create_data(material_set)                 # what tmm() builds on every call
ps, pp = jnp.array([False]), jnp.array([True])

def kernel():  # the jitted function tmm() dispatches to
    rs, ts = vectorized_coh_tmm(data, distribution, d, lam, theta, ps)
    rp, tp = vectorized_coh_tmm(data, distribution, d, lam, theta, pp)
    return rs, rp, ts, tp

def timed(fn):
    t0 = time.perf_counter(); out = jax.block_until_ready(fn()); first = time.perf_counter() - t0
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter(); jax.block_until_ready(fn()); ts.append(time.perf_counter() - t0)
    return out, {"first_s": first, "warm_s": statistics.median(ts), "min_s": min(ts),
                 "max_s": max(ts), "repeats": repeats}

out, t_public = timed(public)
out_k, t_kernel = timed(kernel)
same = max(float(np.nanmax(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(out, out_k))
np.savez(sys.argv[1] + ".out.npz", **dict(zip(("Rs", "Rp", "Ts", "Tp"), map(np.asarray, out))))

# Quarter-wave check at normal incidence, λ0 = 550 nm, lossless constant indices through the
# same kernel (tables of two nodes): air | L | H | ... | base; closed form below.
lam0, nL, nH, ns = 550e-9, 1.46, 2.3, 1.52
wl = jnp.array([300e-9, 1000e-9], jnp.float32)
tab = jnp.stack([jnp.stack([wl, jnp.full(2, n, jnp.float32), jnp.zeros(2, jnp.float32)])
                 for n in (1.0, nL, nH, ns)])
qw = []
for k in (1, 2, 3, 4):
    layers = [1 + (i % 2) for i in range(k)]
    dq = jnp.array([lam0 / (4 * (nL, nH)[i - 1]) for i in layers], jnp.float32)
    R, T = vectorized_coh_tmm(tab, jnp.array([0, *layers, 3]), dq, jnp.array([lam0], jnp.float32),
                              jnp.array([0.0], jnp.float32), ps)
    qw.append({"layers": k, "R": float(np.ravel(R)[0]), "T": float(np.ravel(T)[0])})

from importlib.metadata import version
print(json.dumps({"public": t_public, "kernel": t_kernel, "public_vs_kernel": same,
                  "quarter_wave": qw, "tmmax": version("tmmax"), "jax": jax.__version__,
                  "x64": bool(jax.config.jax_enable_x64), "dtype": str(out[0].dtype),
                  "shape": list(np.shape(out[0]))}))
"""


_TMM_FAST_SCRIPT = r"""
import json, sys, time, statistics
import numpy as np, torch
from tmm_fast import coh_tmm
torch.set_num_threads(int(sys.argv[3]))
z = np.load(sys.argv[1])
N, T, th, lam = z["N"][None], z["T"][None], z["theta"], z["lam"]
repeats = int(sys.argv[2])
def run():
    out = {}
    for pol in "sp":
        o = coh_tmm(pol, N, T, th, lam)
        out["R" + pol], out["T" + pol] = np.asarray(o["R"])[0], np.asarray(o["T"])[0]
    return out
t0 = time.perf_counter(); out = run(); first = time.perf_counter() - t0
ts = []
for _ in range(repeats):
    t0 = time.perf_counter(); run(); ts.append(time.perf_counter() - t0)
np.savez(sys.argv[1] + ".out.npz", **out)
import tmm_fast
print(json.dumps({"first_s": first, "warm_s": statistics.median(ts), "min_s": min(ts),
                  "torch": torch.__version__,
                  "tmm_fast": getattr(tmm_fast, "__version__", "?"),
                  "dtype": str(torch.as_tensor(N).dtype)}))
"""


def quarter_wave_closed_form(k: int, n_low=1.46, n_high=2.3, n_base=1.52, n_outer=1.0) -> float:
    """R at normal incidence of k alternating quarter-wave layers L, H, L, ... (L next to the
    outer medium) on the base: a quarter-wave layer of index n turns the admittance Y below
    it into n²/Y (Macleod, *Thin-Film Optical Filters*, §2.4), from Y = n_base up; then
    R = ((n_outer − Y)/(n_outer + Y))²."""
    y = n_base
    for i in reversed(range(k)):
        y = (n_low, n_high)[i % 2] ** 2 / y
    return ((n_outer - y) / (n_outer + y)) ** 2


def _run(cmd, f, key_order=("Rs", "Rp", "Ts", "Tp"), shape=None):
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_ENABLE_X64")}
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env)
    if p.returncode:
        last = (p.stderr.strip().splitlines() or ["?"])[-1]
        return {"skipped": f"failed: {last}"}, None
    info = json.loads(p.stdout.strip().splitlines()[-1])
    o = np.load(f + ".out.npz")
    out = tuple(np.asarray(o[k], float) for k in key_order)
    if shape is not None and out[0].shape != shape:
        out = tuple(x.T for x in out)
    return info, out


def run_tmmax(materials, d, theta, lam, repeats, mode):
    """tmmax in this interpreter's own subprocess (x64 off), `mode` "shipped" or "fixed"
    (`_TMMAX_FIX` applied before tmmax is imported): its timings (public API and kernel), the
    quarter-wave check, and (R_s, R_p, T_s, T_p) (angles, wavelengths) from the public API."""
    try:
        import tmmax  # noqa: F401
    except ImportError:
        return {"skipped": "tmmax not installed"}, None
    with tempfile.TemporaryDirectory() as tmp:
        f = os.path.join(tmp, "in.npz")
        np.savez(f, materials=json.dumps(materials), T=d * 1e-9, theta=theta, lam=lam * 1e-9)
        script, fix = os.path.join(tmp, "run.py"), os.path.join(tmp, "fix.py")
        with open(script, "w") as fh:
            fh.write(_TMMAX_SCRIPT)
        with open(fix, "w") as fh:
            fh.write(_TMMAX_FIX)
        return _run([sys.executable, script, f, mode, str(repeats), fix], f,
                    shape=(len(theta), len(lam)))


def run_tmm_fast(python, nk, d, theta, lam, repeats):
    """tmm_fast in interpreter `python` on our index table (SI units): timing dict and
    (R_s, R_p, T_s, T_p), or ({"skipped": why}, None)."""
    if not os.path.exists(python):
        return {"skipped": f"no interpreter {python}"}, None
    with tempfile.TemporaryDirectory() as tmp:
        f = os.path.join(tmp, "in.npz")
        t = np.concatenate([[np.inf], d * 1e-9, [np.inf]])
        np.savez(f, N=nk, T=t, theta=theta, lam=lam * 1e-9)
        script = os.path.join(tmp, "run.py")
        with open(script, "w") as fh:
            fh.write(_TMM_FAST_SCRIPT)
        threads = str(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
                      else os.cpu_count())
        return _run([python, script, f, str(repeats), threads], f, shape=(len(theta), len(lam)))


def run_tmm(nk, d, theta, lam, n_calls, seed=0):
    """tmm's coh_tmm on `n_calls` random (θ, λ) pairs, both polarisations: (seconds per
    (θ, λ) pair for R and T of s and p, pair indices, (R_s, R_p, T_s, T_p) at them)."""
    import tmm

    rng = np.random.default_rng(seed)
    ia = rng.integers(0, len(theta), n_calls)
    iw = rng.integers(0, len(lam), n_calls)
    d_list = [np.inf, *d, np.inf]
    out = np.zeros((4, n_calls))

    def loop():
        for k in range(n_calls):
            n_list = list(nk[:, iw[k]])
            for p, pol in enumerate("sp"):
                o = tmm.coh_tmm(pol, n_list, d_list, theta[ia[k]], lam[iw[k]])
                out[p, k], out[2 + p, k] = o["R"], o["T"]

    t = time_host(loop, 1)
    return t.warm_s / n_calls, (ia, iw), out


# ---------------------------------------------------------------------------- the study


def _max_diff(a, b):
    return float(max(np.nanmax(np.abs(np.asarray(x) - np.asarray(y))) for x, y in zip(a, b)))


def bench_stacks(layer_counts=(8, 80), *, repeats=10, tmm_calls=200,
                 peers_python="/tmp/peers-venv/bin/python", verbose=True) -> dict:
    import tmm

    theta, lam = grid()
    cos = np.cos(theta)[:, None]
    n_pairs = N_ANGLES * N_WAVELENGTHS
    rows, quarter_wave = [], {}
    for n in layer_counts:
        d, materials = layout(n)
        models = [tmmax_table(m) for m in materials]
        nk = index_table(models, lam)
        row = {"layers": n, "pairs": n_pairs, "materials": materials, "thickness_nm": d}
        log(f"{n} layers: ours", verbose)
        rt, r_only = ours_fns(models)
        args = (jnp.asarray(d), jnp.asarray(cos), jnp.asarray(lam))
        ours, t_rt = time_call(rt, args, repeats)
        _, t_r = time_call(r_only, args, repeats)
        ours = [np.asarray(x) for x in ours]
        row["ours_rt"] = t_rt._asdict() | {"compile_s": t_rt.compile_s}
        row["ours_r"] = t_r._asdict() | {"compile_s": t_r.compile_s}
        ours32, t32 = time_call(jax.jit(rt.__wrapped__),
                                tuple(jnp.asarray(a, jnp.float32) for a in args), repeats)
        row["ours_rt_float32"] = t32._asdict() | {"compile_s": t32.compile_s}
        diff = row["max_abs_diff"] = {"ours_float32_vs_float64": _max_diff(ours32, ours)}

        log(f"{n} layers: tmm ({tmm_calls} pairs)", verbose)
        per_pair, (ia, iw), ref = run_tmm(nk, d, theta, lam, tmm_calls)
        row["tmm"] = {"s_per_pair": per_pair, "grid_s": per_pair * n_pairs, "calls": tmm_calls}
        diff["ours_vs_tmm"] = _max_diff([o[ia, iw] for o in ours], ref)
        diff["ours_float32_vs_tmm"] = _max_diff([np.asarray(o)[ia, iw] for o in ours32], ref)

        warm, warm32 = row["ours_rt"]["warm_s"], row["ours_rt_float32"]["warm_s"]
        row["ratio"] = {"tmm": row["tmm"]["grid_s"] / warm}
        for mode in ("shipped", "fixed"):
            key = f"tmmax_{mode}"
            log(f"{n} layers: tmmax {mode} (subprocess)", verbose)
            info, out = run_tmmax(materials, d, theta, lam, repeats, mode)
            row[key] = info
            if out is None:
                continue
            quarter_wave.setdefault(mode, info.pop("quarter_wave"))
            for t in ("public", "kernel"):
                info[t]["compile_s"] = max(info[t]["first_s"] - info[t]["warm_s"], 0.0)
            diff[f"{key}_vs_tmm"] = _max_diff([o[ia, iw] for o in out], ref)
            diff[f"{key}_vs_ours"] = _max_diff(out, ours)
            row[f"{key}_nan"] = int(sum(np.isnan(x).sum() for x in out))
            info["agrees_with_tmm"] = ok = bool(diff[f"{key}_vs_tmm"] <= TOL_TMMAX
                                                and row[f"{key}_nan"] == 0)
            for t in ("public", "kernel"):  # ratios only for a run that computes the physics
                row["ratio"][f"{key}_{t}"] = info[t]["warm_s"] / warm if ok else None
                row["ratio"][f"{key}_{t}_vs_ours_float32"] = (info[t]["warm_s"] / warm32
                                                              if ok else None)

        log(f"{n} layers: tmm_fast (subprocess)", verbose)
        info, out = run_tmm_fast(peers_python, nk, d, theta, lam, repeats)
        row["tmm_fast"] = info
        if out is not None:
            row["tmm_fast"]["compile_s"] = max(info["first_s"] - info["warm_s"], 0.0)
            diff["tmm_fast_vs_tmm"] = _max_diff([o[ia, iw] for o in out], ref)
            diff["tmm_fast_vs_ours"] = _max_diff(out, ours)
            row["ratio"]["tmm_fast"] = info["warm_s"] / warm
        rows.append(row)

    checks = []
    for k in (1, 2, 3, 4):
        layers = [1.46 if i % 2 == 0 else 2.3 for i in range(k)]
        dq = [550.0 / (4 * x) for x in layers]
        checks.append({"layers": k, "closed_form": quarter_wave_closed_form(k),
                       "tmm": tmm.coh_tmm("s", [1.0, *layers, 1.52], [np.inf, *dq, np.inf],
                                          0.0, 550.0)["R"]}
                      | {f"tmmax_{m}": q[k - 1]["R"] for m, q in quarter_wave.items()})
    return {"rows": rows, "quarter_wave": checks, "tol_tmmax": TOL_TMMAX,
            "grid": {"angles": N_ANGLES, "wavelengths": N_WAVELENGTHS,
                     "theta_max_deg": 85.0, "lambda_nm": [400.0, 800.0]},
            "targets": {"vs_tmm": TARGET_VS_TMM, "vs_tmmax": TARGET_VS_TMMAX,
                        "ambition_vs_tmmax": AMBITION_VS_TMMAX}}


def _ms(x):
    return fmt(None if x is None else x * 1e3)


def _min_ratios(r: dict) -> str:
    """'N layers: × tmmax fixed kernel a (f64) / b (f32)' on the fastest calls."""
    k = r.get("tmmax_fixed", {}).get("kernel")
    if k is None or not r["tmmax_fixed"].get("agrees_with_tmm"):
        return f"{r['layers']} layers: –"
    return (f"{r['layers']} layers × tmmax fixed kernel {k['min_s'] / r['ours_rt']['min_s']:.3g}"
            f" (ours f64) / {k['min_s'] / r['ours_rt_float32']['min_s']:.3g} (ours f32)")


def markdown(res: dict) -> str:
    rows = res["rows"]
    env = res.get("environment", {})
    load = env.get("load_average")
    load_end = res.get("load_average_end")
    lines = [
        "# Layer stacks against their peers (CPU)",
        "",
        f"{res['grid']['angles']} angles (0–85°) × {res['grid']['wavelengths']} wavelengths "
        "(400–800 nm). Stacks from tmmax's own material tables: Air | (SiO2 95 nm / TiO2 60 nm)"
        " … | Ge 15 nm | SiO2 base; ours, tmm and tmm_fast get the same n, κ (tmmax's tables, "
        "interpolated linearly in λ). Work: R and T, both polarisations, on the whole grid (tmm: "
        "a random subset of pairs, scaled). Warm: median of repeated calls; compile: first call "
        "minus warm. One run; the machine is shared, so the ratios within it are what count"
        + (f" (load average {load[0]:.2f} at the start" if load else "")
        + (f", {load_end[0]:.2f} at the end)" if load_end else (")" if load else "")) + ".",
        "",
        "## Times (ms) and ratios (peer time / ours)",
        "",
        "| layers | ours f64 | ours f64 R only | ours f32 | tmm (grid) | tmm_fast f64 "
        "| tmmax shipped: kernel / public | tmmax fixed: kernel / public "
        "| × tmm | × tmm_fast | × tmmax fixed kernel (ours f64 / f32) "
        "| × tmmax fixed public (ours f64 / f32) |",
        "|" + "---|" * 12,
    ]
    for r in rows:
        q = r["ratio"]
        ts, tf = r.get("tmmax_shipped", {}), r.get("tmmax_fixed", {})

        def tx(info):
            if "kernel" not in info:
                return info.get("skipped", "–")
            return f"{_ms(info['kernel']['warm_s'])} / {_ms(info['public']['warm_s'])}"

        lines.append(
            f"| {r['layers']} | {_ms(r['ours_rt']['warm_s'])} | {_ms(r['ours_r']['warm_s'])} "
            f"| {_ms(r['ours_rt_float32']['warm_s'])} | {r['tmm']['grid_s'] * 1e3:.4g} "
            f"| {_ms(r['tmm_fast'].get('warm_s'))} | {tx(ts)} | {tx(tf)} "
            f"| {fmt(q.get('tmm'))} | {fmt(q.get('tmm_fast'))} "
            f"| {fmt(q.get('tmmax_fixed_kernel'))} / "
            f"{fmt(q.get('tmmax_fixed_kernel_vs_ours_float32'))} "
            f"| {fmt(q.get('tmmax_fixed_public'))} / "
            f"{fmt(q.get('tmmax_fixed_public_vs_ours_float32'))} |")
    lines += ["", "Fastest call instead of the median (the load varies within the run): "
              + "; ".join(_min_ratios(r) for r in rows) + ". Compile (first call minus warm, s): "
              + "; ".join(f"{r['layers']} layers ours f64 {fmt(r['ours_rt']['compile_s'])}, "
                          f"f32 {fmt(r['ours_rt_float32']['compile_s'])}, tmmax fixed "
                          f"{fmt(r.get('tmmax_fixed', {}).get('public', {}).get('compile_s'))}"
                          " (its public call's first call, which compiles the kernel too)"
                          for r in rows) + "."]
    lines += [
        "",
        f"## Agreement (max |Δ| over R_s, R_p, T_s, T_p; tmmax must be within {res['tol_tmmax']:g}"
        " of tmm before its time is compared)",
        "",
        "| layers | ours f64 vs tmm | ours f32 vs tmm | ours f32 vs f64 | tmm_fast vs tmm "
        "| tmmax shipped vs tmm | tmmax fixed vs tmm | tmmax fixed vs ours (grid) |",
        "|" + "---|" * 8,
    ]
    for r in rows:
        m = r["max_abs_diff"]
        lines.append(
            f"| {r['layers']} | {fmt(m.get('ours_vs_tmm'), '.2g')} "
            f"| {fmt(m.get('ours_float32_vs_tmm'), '.2g')} "
            f"| {fmt(m.get('ours_float32_vs_float64'), '.2g')} "
            f"| {fmt(m.get('tmm_fast_vs_tmm'), '.2g')} "
            f"| {fmt(m.get('tmmax_shipped_vs_tmm'), '.2g')} "
            f"| {fmt(m.get('tmmax_fixed_vs_tmm'), '.2g')} "
            f"| {fmt(m.get('tmmax_fixed_vs_ours'), '.2g')} |")
    qw = res.get("quarter_wave", [])
    if qw:
        lines += [
            "",
            "## tmmax and a closed form: quarter-wave layers at normal incidence",
            "",
            "λ0 = 550 nm, air | L H L … | base, n_L = 1.46, n_H = 2.3, n_base = 1.52 (constant, "
            "lossless), s-polarised, through `tmmax.tmm.vectorized_coh_tmm`. Closed form: each "
            "quarter-wave layer maps the admittance Y below it to n²/Y (Macleod, Thin-Film "
            "Optical Filters, §2.4), R = ((1 − Y)/(1 + Y))².",
            "",
            "| layers | closed form | tmm | tmmax 1.1.4 shipped | tmmax, `coh_matmul` fixed |",
            "|---|---|---|---|---|",
        ]
        for c in qw:
            lines.append(f"| {c['layers']} | {c['closed_form']:.6f} | {c['tmm']:.6f} "
                         f"| {fmt(c.get('tmmax_shipped'), '.6f')} "
                         f"| {fmt(c.get('tmmax_fixed'), '.6f')} |")
    lines += [
        "",
        "tmmax 1.1.4 as shipped computes the wrong product for two or more layers: in "
        "`tmmax/cascaded_matmul.py:coh_matmul` the layer-matrix entries have shape (1,) "
        "(`jnp.array([-1j]) * phase`), so `jnp.matmul(carry, M)` with M of shape (2, 2, 1) "
        "broadcasts and the scan returns M_k · C_{k−1}ᵀ instead of C_{k−1} · M_k (right for one "
        "layer, where C = I). \"Fixed\" replaces only that function by the intended product on "
        "scalar entries (`_TMMAX_FIX` in the study); everything else is tmmax's code. Ratios "
        "against a tmmax run are given only when it agrees with tmm.",
        "",
        "How each peer is called: tmm `coh_tmm(pol, n_list, d_list_nm, θ, λ_nm)` per (θ, λ, "
        "pol), float64; tmm_fast `coh_tmm(pol, N[None], T[None], θ, λ)` (SI units, float64, "
        "PyTorch threads = cores) in its own interpreter; tmmax public: `tmmax.tmm(material_list,"
        " thickness_list_m, wavelength_arr_m, angle_of_incidences_rad, polarization='s'|'p')` "
        "(float32, x64 off, reloads its tables every call); tmmax kernel: "
        "`vectorized_coh_tmm(create_data(set), distribution, d, λ, θ, pol)` on data built once.",
    ]
    skipped = [f"{p} ({r['layers']} layers): {r[p]['skipped']}" for r in rows
               for p in ("tmmax_shipped", "tmmax_fixed", "tmm_fast")
               if "skipped" in r.get(p, {})]
    if skipped:
        lines += ["", "Skipped: " + "; ".join(skipped)]
    t = res["targets"]
    lines += ["", f"Targets (reported, not asserted): ≥ {t['vs_tmm']:g}× tmm, faster than tmmax "
              f"(a correct run), ambition {t['ambition_vs_tmmax']:g}× tmmax.", ""]
    if "command" in res:
        lines += [f"Command: `{res['command']}`", ""]
    return "\n".join(lines)


def main(argv=None) -> None:
    """``python -m benchmarks.stack_bench``: writes stack_bench.json and
    stack_bench.md into ``--out`` (default figures)."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--out", default="figures", help="output folder ('' for none)")
    p.add_argument("--layers", default="8,80", help="comma-separated layer counts")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--tmm-calls", type=int, default=200)
    p.add_argument("--peers-python", default="/tmp/peers-venv/bin/python",
                   help="interpreter with tmm_fast (and PyTorch) installed")
    a = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    env = environment()
    t0 = time.perf_counter()
    res = bench_stacks(tuple(int(x) for x in a.layers.split(",")), repeats=a.repeats,
                       tmm_calls=a.tmm_calls, peers_python=a.peers_python)
    res["run_s"] = time.perf_counter() - t0
    res["environment"] = env
    res["load_average_end"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    res["command"] = ("python -m benchmarks.stack_bench "
                      + " ".join(sys.argv[1:] if argv is None else argv)).strip()
    from importlib.metadata import version

    res["tmmax_version"] = version("tmmax")
    text = markdown(res)
    if a.out:
        text = write_report(a.out, "stack_bench", res, markdown)
    print(text)


if __name__ == "__main__":
    main()
