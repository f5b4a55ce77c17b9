"""Speed and agreement of `airy_reflectance` against its peers: tmm (Byrnes'
`coh_tmm`, a Python loop), a vectorised NumPy closed form of the same formula and
colour-science's `thin_film_tmm`, on angle × wavelength grids.

``python -m benchmarks.peers [--side 1000] [--out figures]`` and ``thinfilm-jax
bench`` (which also embeds the result in ``bench.json`` under "peers") write
``peers.json`` (`bench_peers` plus the machine, the targets of `peers_targets` and the copy
bandwidth of `memory_roofline`) and ``peers.md`` (`peers_markdown`): the README's peers table
and its targets text quote these files.

Example (three independent implementations of one reflectance: the Figure 7 film at 34°):
    >>> import numpy as np
    >>> from thinfilm_jax import Film, airy_reflectance
    >>> from benchmarks.peers import numpy_airy, tmm_unpolarised
    >>> ours = float(airy_reflectance(Film(600.0, 1.3, 2.0, 0.5), np.cos(0.6), 550.0))
    >>> ref = float(tmm_unpolarised(1.0, 1.3, 2.0 + 0.5j, 600.0, 0.6, 550.0))
    >>> num = float(numpy_airy(1.0, 1.3, 2.0 + 0.5j, 600.0, np.cos(0.6), 550.0))
    >>> round(ours, 6), abs(ours - ref) < 1e-13, abs(ours - num) < 1e-13
    (0.039727, True, True)
"""

from __future__ import annotations

import sys
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from thinfilm_jax.optics.airy import airy_reflectance
from thinfilm_jax.core.film import Film
from ._common import MATERIALS, BenchConfig
from ._timing import environment, log, time_call, time_host, write_report


def numpy_airy(eta_outer, eta_film, n_base, thickness, cos_theta, wavelength, *,
               real=np.float64):
    """Unpolarised Airy R (SPEC §2) in vectorised complex NumPy: the **NumPy peer** of
    `airy_reflectance` (the same closed form, written independently of it, for the speed
    and agreement comparison) and, with ``real=np.longdouble``, the **80-bit reference** of
    the stability suite (`stiff.airy_longdouble`).

    r = (r₁₂ + r₂₃e^{iδ})/(1 + r₁₂r₂₃e^{iδ}), δ = 4π d q₂/λ, q_k = √(η_k² − η₁² sin²θ₁) on the
    branch Im q ≥ 0; `n_base` = η₃ + iκ₃ complex; arrays broadcast. Computed in `real` and
    its complex type (complex128, or clongdouble: x87 80-bit on x86-64, eps 1.1e-19).
    """
    cdt = np.result_type(real, np.complex64).type
    n1, n2, d, c, lam = (np.asarray(x, real) for x in (eta_outer, eta_film, thickness,
                                                       cos_theta, wavelength))
    s2 = n1 * n1 * (1 - c) * (1 + c)

    def q(eps):
        r = np.sqrt(eps - s2.astype(cdt))
        return np.where(r.imag < 0, -r, r)

    e1, e2, e3 = (n1 * n1).astype(cdt), (n2 * n2).astype(cdt), np.asarray(n_base, cdt) ** 2
    q1, q2, q3 = (n1 * c).astype(cdt), q(e2), q(e3)
    pi = real("3.14159265358979323846264338327950288")
    phase = np.exp(cdt(4j) * pi * d * q2 / lam)
    r = np.zeros((), real)
    with np.errstate(all="ignore"):
        for r12, r23 in (((q1 - q2) / (q1 + q2), (q2 - q3) / (q2 + q3)),
                         ((e2 * q1 - e1 * q2) / (e2 * q1 + e1 * q2),
                          (e3 * q2 - e2 * q3) / (e3 * q2 + e2 * q3))):
            amp = (r12 + r23 * phase) / (1 + r12 * r23 * phase)
            r = r + (amp.real**2 + amp.imag**2) / 2
    return r


def tmm_unpolarised(eta_outer, eta_film, n_base, thickness, theta, wavelength):
    """½(R_s + R_p) from `tmm.coh_tmm` (one (θ, λ) pair, two calls)."""
    import tmm

    n_list = [eta_outer, eta_film, n_base]
    d_list = [np.inf, thickness, np.inf]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return 0.5 * (tmm.coh_tmm("s", n_list, d_list, theta, wavelength)["R"]
                      + tmm.coh_tmm("p", n_list, d_list, theta, wavelength)["R"])


def colour_unpolarised(eta_outer, eta_film, n_base, thickness, theta, wavelength):
    """½(R_s + R_p) from `colour.phenomena.thin_film_tmm` on the outer product
    θ (A,) × λ (W,) → (A, W). colour takes degrees and returns (W, A, T, 2)."""
    from colour.phenomena import thin_film_tmm

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        r, _ = thin_film_tmm([eta_outer, eta_film, n_base], thickness, wavelength,
                             np.rad2deg(theta))
    return r[:, :, 0, :].mean(axis=-1).T


def bench_peers(cfg: BenchConfig, verbose: bool = True) -> dict:
    """Throughput of `airy_reflectance` (value; value + gradient) against tmm, NumPy and
    colour-science on side × side (θ, λ) grids, θ ∈ [0°, 89°], λ ∈ [380, 780] nm."""
    import colour

    out = {"colour_function": "colour.phenomena.thin_film_tmm",
           "colour_version": colour.__version__, "grids": {},
           "colour_note": "colour.phenomena.tmm.snell_law takes np.real of both indices, so the "
                          "angle in an absorbing base is real: wrong R at oblique incidence on "
                          "absorbing bases (max_abs_diff.colour_vs_tmm; dielectric films agree "
                          "to rounding) and NaN beyond a critical angle (arcsin > 1)"}
    rng = np.random.default_rng(1959)
    films = (("fig7", "complex"), ("tio2_glass", "real"))
    for mat, arith in films if cfg.extras else films[1:]:
        eta2, eta3, kap3, eta1 = MATERIALS[mat]
        n3 = complex(eta3, kap3)
        d = 600.0
        film = Film(d, eta2, eta3, kap3, eta1)
        for side in cfg.peer_sides:
            key = f"{mat}/{side}x{side}"
            log(f"(peers) {key}", verbose)
            th = np.deg2rad(np.linspace(0.0, 89.0, side))
            lam = np.linspace(380.0, 780.0, side)
            c = np.cos(th)[:, None]
            n_eval = side * side
            value = jax.jit(lambda f, c, lam, a=arith: airy_reflectance(f, c, lam, arithmetic=a))
            vg = jax.jit(jax.value_and_grad(
                lambda f, c, lam, a=arith: jnp.sum(airy_reflectance(f, c, lam, arithmetic=a)),
                argnums=(0, 1)))
            ours, t_val = time_call(value, (film, c, lam[None, :]), cfg.repeats)
            _, t_vg = time_call(vg, (film, c, lam[None, :]), cfg.repeats)
            ours = np.asarray(ours)
            npy = numpy_airy(eta1, eta2, n3, d, c, lam[None, :])
            t_np = time_host(lambda: numpy_airy(eta1, eta2, n3, d, c, lam[None, :]), cfg.repeats)
            # the same pairs as flat arrays: no outer-product structure for NumPy to exploit
            cf, lf = (x.ravel() for x in np.meshgrid(np.cos(th), lam, indexing="ij"))
            _, t_val_flat = time_call(value, (film, cf, lf), cfg.repeats)
            t_np_flat = time_host(lambda: numpy_airy(eta1, eta2, n3, d, cf, lf), cfg.repeats)
            # the float32 option of the same call (the real-time dtype)
            f32 = film.astype(jnp.float32)
            _, t_val32 = time_call(value, (f32, c.astype(np.float32),
                                           lam[None, :].astype(np.float32)), cfg.repeats)
            _, t_val32_flat = time_call(value, (f32, cf.astype(np.float32),
                                                lf.astype(np.float32)), cfg.repeats)
            col = colour_unpolarised(eta1, eta2, n3, d, th, lam)
            t_col = time_host(lambda: colour_unpolarised(eta1, eta2, n3, d, th, lam),
                              cfg.repeats)
            k = min(cfg.tmm_calls, n_eval)
            ia, iw = rng.integers(0, side, k), rng.integers(0, side, k)

            def tmm_loop(ia=ia, iw=iw):
                return np.array([tmm_unpolarised(eta1, eta2, n3, d, th[i], lam[j])
                                 for i, j in zip(ia, iw)])

            t0 = time.perf_counter()
            ref = tmm_loop()
            t_tmm = time.perf_counter() - t0
            per = {"airy_value": t_val.warm_s / n_eval, "airy_value_and_grad": t_vg.warm_s / n_eval,
                   "numpy_closed_form": t_np.warm_s / n_eval,
                   "airy_value_flat": t_val_flat.warm_s / n_eval,
                   "numpy_closed_form_flat": t_np_flat.warm_s / n_eval,
                   "airy_value_f32": t_val32.warm_s / n_eval,
                   "airy_value_flat_f32": t_val32_flat.warm_s / n_eval,
                   "colour_thin_film_tmm": t_col.warm_s / n_eval, "tmm_coh_tmm": t_tmm / k}
            col_bad = ~np.isfinite(col)
            out["grids"][key] = {
                "material": mat, "arithmetic": arith, "thickness_nm": d, "n_eval": n_eval,
                "tmm_calls": int(k), "s_per_eval": per,
                "compile_s": {"airy_value": t_val.compile_s,
                              "airy_value_and_grad": t_vg.compile_s},
                "speedup_airy_vs": {
                    **{name: per[name] / per["airy_value"]
                       for name in ("numpy_closed_form", "colour_thin_film_tmm", "tmm_coh_tmm")},
                    "numpy_closed_form_flat": per["numpy_closed_form_flat"]
                    / per["airy_value_flat"],
                    "numpy_closed_form_vs_f32": per["numpy_closed_form"] / per["airy_value_f32"],
                    "numpy_closed_form_flat_vs_f32": per["numpy_closed_form_flat"]
                    / per["airy_value_flat_f32"]},
                "grad_over_value_cost": per["airy_value_and_grad"] / per["airy_value"],
                "max_abs_diff": {
                    "airy_vs_tmm": float(np.abs(ours[ia, iw] - ref).max()),
                    "numpy_vs_airy": float(np.abs(npy - ours).max()),
                    "colour_vs_tmm": float(np.nanmax(np.abs(col[ia, iw] - ref))),
                    "colour_vs_airy": float(np.nanmax(np.abs(col - ours))),
                },
                "colour_nonfinite": int(col_bad.sum()),
            }
    return out


def peers_table(peers) -> str:
    """The peers table as markdown (µs per (θ, λ) evaluation, speed-ups, agreement)."""
    lines = ["| grid | airy value µs | airy value+grad µs | NumPy µs | colour µs | tmm µs "
             "| ×NumPy | ×colour | ×tmm | flat pairs: airy µs | NumPy µs | ×NumPy "
             "| max \\|airy−tmm\\| | max \\|colour−tmm\\| |",
             "|" + "---|" * 14]
    for key, g in peers.get("grids", {}).items():
        p, s, m = g["s_per_eval"], g["speedup_airy_vs"], g["max_abs_diff"]
        lines.append(
            f"| {key} ({g.get('arithmetic', g.get('base'))}) | {p['airy_value'] * 1e6:.3g} "
            f"| {p['airy_value_and_grad'] * 1e6:.3g} | {p['numpy_closed_form'] * 1e6:.3g} "
            f"| {p['colour_thin_film_tmm'] * 1e6:.3g} | {p['tmm_coh_tmm'] * 1e6:.3g} "
            f"| {s['numpy_closed_form']:.3g} | {s['colour_thin_film_tmm']:.3g} "
            f"| {s['tmm_coh_tmm']:.3g} | {p['airy_value_flat'] * 1e6:.3g} "
            f"| {p['numpy_closed_form_flat'] * 1e6:.3g} | {s['numpy_closed_form_flat']:.3g} "
            f"| {m['airy_vs_tmm']:.2g} | {m['colour_vs_tmm']:.2g} |")
    return "\n".join(lines)


TARGET_VS_NUMPY = 2.0  # airy_reflectance ≥ 2× the NumPy closed form at 10⁶ (θ, λ) pairs
TARGET_VS_TMM = 100.0  # airy_reflectance ≥ 100× tmm's Python loop per evaluation
TARGET_N_EVAL = 10**6


def peers_targets(peers) -> dict:
    """The two speed targets (README, "Targets") against `bench_peers`' result: the speed-ups
    over tmm (every grid) and over NumPy (grid and flat pairs, grids of ≥ 10⁶ pairs), their ranges
    and whether each target is met (the smallest speed-up reaches it)."""
    grids = peers.get("grids", {})
    tmm = [g["speedup_airy_vs"]["tmm_coh_tmm"] for g in grids.values()]
    big = {k: g for k, g in grids.items() if g["n_eval"] >= TARGET_N_EVAL}
    npy = {k: {"grid": g["speedup_airy_vs"]["numpy_closed_form"],
               "flat": g["speedup_airy_vs"]["numpy_closed_form_flat"]} for k, g in big.items()}
    vals = [v for d in npy.values() for v in d.values()]
    return {
        "airy_vs_tmm": {"target": TARGET_VS_TMM, "min": min(tmm, default=None),
                        "max": max(tmm, default=None),
                        "met": bool(tmm) and min(tmm) >= TARGET_VS_TMM},
        "airy_vs_numpy_1e6": {"target": TARGET_VS_NUMPY, "n_eval_at_least": TARGET_N_EVAL,
                              "per_grid": npy, "min": min(vals, default=None),
                              "met": (min(vals) >= TARGET_VS_NUMPY) if vals else None},
    }


def memory_roofline(n: int = 10**7, repeats: int = 5) -> dict:
    """Copy bandwidth of this machine (a NumPy copy of `n` float64) and the memory floor of a
    flat (θ, λ) pair it implies: read cos θ and λ, write R, 24 B in float64."""
    buf = np.random.default_rng(0).random(n)
    t = time_host(lambda: buf.copy(), repeats).warm_s
    bandwidth = 2 * buf.nbytes / t
    return {"copy_bandwidth_GBps": bandwidth / 1e9, "bytes_per_flat_pair_f64": 24,
            "floor_ns_per_flat_pair_f64": 24 / bandwidth * 1e9}


def peers_markdown(result) -> str:
    """``peers.md``: the machine, the peers table, the targets and the roofline."""
    env = result.get("environment", {})
    lines = ["## airy_reflectance against its peers", ""]
    if env:
        lines += [f"Devices: {env.get('devices')}, {env.get('cpu_count')} CPUs, jax "
                  f"{env.get('jax')}, load average at start {env.get('load_average')}, "
                  f"{env.get('date')}.", ""]
    if result.get("note"):
        lines += [result["note"], ""]
    lines += ["µs per (θ, λ) evaluation; ×: speed-up of airy_reflectance value.", "",
              peers_table(result), ""]
    t = result.get("targets") or peers_targets(result)
    tm, tn = t["airy_vs_tmm"], t["airy_vs_numpy_1e6"]
    if tm["min"] is not None:
        lines.append(f"- airy ≥ {tm['target']:g}× tmm: {'met' if tm['met'] else 'missed'} "
                     f"({tm['min']:.3g}–{tm['max']:.3g}×)")
    per = "; ".join(f"{k}: {v['grid']:.3g}× grid, {v['flat']:.3g}× flat"
                    for k, v in tn["per_grid"].items())
    lines.append(f"- airy ≥ {tn['target']:g}× NumPy at ≥ {tn['n_eval_at_least']:.0e} pairs: "
                 + (f"{'met' if tn['met'] else 'missed'} ({per})" if per
                    else "not measured (no grid that large)"))
    r = result.get("roofline")
    if r:
        lines.append(f"- copy bandwidth {r['copy_bandwidth_GBps']:.1f} GB/s: memory floor "
                     f"{r['floor_ns_per_flat_pair_f64']:.2f} ns per flat float64 pair")
    return "\n".join(lines) + "\n"


def write_peers(peers, out, *, environment_=None, config=None, command=None) -> dict:
    """Write ``out/peers.json`` and ``out/peers.md`` from `bench_peers`' result (plus the
    machine, the run's settings and the targets); returns what was written."""
    result = {"command": command, "environment": environment_ or environment(),
              "config": config, **peers, "targets": peers_targets(peers)}
    write_report(out, "peers", result, peers_markdown)
    return result


def main(argv=None) -> None:
    """``python -m benchmarks.peers``: the peers on the 10³ × 10³ grid only (≈ 1 min),
    with the float32 option and the memory roofline of this machine; writes peers.json and
    peers.md into ``--out`` (default figures)."""
    import argparse

    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--side", type=int, default=1000)
    p.add_argument("--out", default="figures", help="output folder ('' for none)")
    a = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    cfg = BenchConfig(peer_sides=(a.side,), tmm_calls=50)
    env = environment()
    out = bench_peers(cfg, verbose=False)
    out["roofline"] = memory_roofline(10**7 if a.side >= 1000 else 10**6)
    command = "python -m benchmarks.peers " + " ".join(
        sys.argv[1:] if argv is None else argv)
    if a.out:
        out = write_peers(out, a.out, environment_=env, command=command.strip(),
                          config={"peer_sides": [a.side], "tmm_calls": cfg.tmm_calls,
                                  "repeats": cfg.repeats})
    print(peers_markdown(out))
    for key, g in out["grids"].items():
        p, s = g["s_per_eval"], g["speedup_airy_vs"]
        print(f"{key}: float64 {s['numpy_closed_form']:.2f}x (grid) / "
              f"{s['numpy_closed_form_flat']:.2f}x (flat); float32 "
              f"{s['numpy_closed_form_vs_f32']:.2f}x / {s['numpy_closed_form_flat_vs_f32']:.2f}x "
              f"NumPy float64; flat float64 {p['airy_value_flat'] * 1e9:.0f} ns/pair")


if __name__ == "__main__":
    main()
