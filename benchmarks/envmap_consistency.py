r"""The uniform-light consistency of the real-time environment-map methods (SPEC §7, §9).

Under a constant map L ≡ (1, 1, 1) a real-time method's map path must give its own
uniform-light patch model: ``envmap_radiance(film, α, n, ω_o, prefilter_envmap(ones),
method=m)`` = ``patch_radiance(film, θ_o, α, method=m)`` (Karis' normalisation makes every
prefiltered level exactly 1, so what differs is only how the map path reads its tables).
This study prints the worst absolute band difference per (map size, film, method, α) in four
θ_o bands, and with ``--table`` the error of the A(θ_o, α) table's bilinear read
(`prefilter.lookup_albedo`) against the quadrature it tabulates (`microfacet.albedo`).

Views: θ_o from 0 to 89.9° about two normals (+z, and one tilted 50° at azimuth 1, so that
the mirror directions fall elsewhere on the map), azimuth 0.3 about each. Films: the paper's
(d = 600 nm, η₂ = 1.3, η₃ = 2.0 + 0.5i) and its bare base (d = 0). Methods: ideal, filtered,
improved at the presets "fast", "default" and "accurate" (`ModelOptions.preset`).

Run: ``python -m benchmarks.envmap_consistency [--sizes 64,32] [--table]`` (float64,
≈ 2-4 min a map size on a 2-core CPU). Nothing is asserted here: the pins are in
tests/shading/test_ibl.py.

Example (the two frames of views, every view in front of its normal):
    >>> import numpy as np
    >>> from benchmarks.envmap_consistency import frames
    >>> [(v.shape, bool(np.all(v @ n > 0))) for n, v in frames()]
    [((18, 3), True), ((18, 3), True)]
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

ALPHAS = (0.005, 0.01, 0.02, 0.05, 0.1, 0.25, 0.6)
THETA_DEG = np.array([0, 20, 40, 55, 60, 65, 70, 75, 80, 83, 85, 86, 87, 88, 88.5, 89,
                      89.5, 89.9])
BANDS = ((0, 60), (60, 80), (80, 88), (88, 90.01))
METHODS = (("ideal", None), ("filtered", None), ("improved", "fast"),
           ("improved", "default"), ("improved", "accurate"))


def frames():
    """Two unit normals and, about each, the views of `THETA_DEG` at azimuth 0.3."""
    th = np.deg2rad(THETA_DEG)
    local = np.stack([np.sin(th) * np.cos(0.3), np.sin(th) * np.sin(0.3), np.cos(th)], -1)
    out = [(np.array([0.0, 0.0, 1.0]), local)]
    b, a = np.deg2rad(50.0), 1.0
    rot_y = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rot_z = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rot = rot_z @ rot_y
    out.append((rot[:, 2], local @ rot.T))
    return out


def sweep(sizes):
    """{(h, film, method label, α): (4,) worst difference per θ_o band}."""
    from thinfilm_jax import (Film, ModelOptions, envmap_radiance, load_envmap,
                              patch_radiance, prefilter_envmap)

    films = {"d600": Film(600.0, 1.3, 2.0, 0.5), "bare": Film(0.0, 1.3, 2.0, 0.5)}
    th = np.deg2rad(THETA_DEG)
    alpha = np.array(ALPHAS)[:, None]
    out = {}
    for h in sizes:
        pref = prefilter_envmap(load_envmap(np.ones((h, 2 * h, 3))))
        for fname, film in films.items():
            for method, preset in METHODS:
                opts = ModelOptions.preset(preset) if preset else ModelOptions()
                want = np.asarray(patch_radiance(film, th[None, :], alpha, method=method,
                                                 options=ModelOptions(bins=opts.bins)))
                diff = 0.0
                for n, v in frames():
                    got = np.asarray(envmap_radiance(film, alpha, n, v[None], pref,
                                                     method=method, options=opts))
                    diff = np.maximum(diff, np.abs(got - want).max(-1))
                label = method + (f"/{preset}" if preset else "")
                for i, a in enumerate(ALPHAS):
                    out[h, fname, label, a] = np.array([
                        diff[i, (THETA_DEG >= lo) & (THETA_DEG < hi)].max() for lo, hi in BANDS])
    return out


def table_error(n_theta: int = 161, n_alpha: int = 31):
    """The A table's bilinear read against `microfacet.albedo` over θ_o ∈ [0, 90°] (dense
    above 80°) and α ∈ [0.002, 1]: {(band, "α ≤ 0.02" | "α > 0.02"): worst}."""
    import jax.numpy as jnp

    from thinfilm_jax.brdf.microfacet import albedo
    from thinfilm_jax.shading.prefilter import albedo_table, lookup_albedo, PrefilteredEnvMap

    deg = np.concatenate([np.linspace(0, 80, 33), np.linspace(80, 88, 33)[1:],
                          np.linspace(88, 90, n_theta - 64)[1:]])
    th = np.minimum(np.deg2rad(deg), np.pi / 2)
    al = np.concatenate([np.geomspace(0.002, 0.05, n_alpha // 2),
                         np.linspace(0.06, 1.0, n_alpha - n_alpha // 2)])
    exact = np.asarray(albedo(th[:, None], al[None, :]))
    pref = PrefilteredEnvMap(None, None, None, jnp.asarray(albedo_table()), None)
    got = np.asarray(lookup_albedo(pref, jnp.asarray(np.cos(th))[:, None],
                                   jnp.asarray(np.sqrt(al))[None, :]))
    err = np.abs(got - exact)
    out = {}
    for lo, hi in BANDS:
        rows = (deg >= lo) & (deg < hi)
        for name, cols in (("α ≤ 0.02", al <= 0.02), ("α > 0.02", al > 0.02)):
            out[(lo, min(hi, 90)), name] = float(err[rows][:, cols].max())
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="64,32", help="map heights (maps are h × 2h)")
    p.add_argument("--table", action="store_true", help="also the A table's read error")
    args = p.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    t0 = time.perf_counter()
    if args.table:
        print("A table read − microfacet.albedo (worst |Δ|):")
        for (band, name), e in table_error().items():
            print(f"  θ_o {band[0]:>2}–{band[1]:<2}°  {name}: {e:.1e}")
    res = sweep([int(s) for s in args.sizes.split(",")])
    bands = "  ".join(f"{lo:>2}–{min(hi, 90):<2}°" for lo, hi in BANDS)
    print(f"worst |envmap − patch| per θ_o band (L ≡ 1, band radiance)\n"
          f"{'h':>3} {'film':5} {'method':18} {'α':>6}  {bands}")
    for (h, film, label, a), row in res.items():
        print(f"{h:>3} {film:5} {label:18} {a:>6}  " + "  ".join(f"{x:.1e}" for x in row))
    print("\nsummary: worst over α (and presets) per (h, film, method, α group, θ_o band)")
    for h in sorted({k[0] for k in res}, reverse=True):
        for film in ("d600", "bare"):
            for method in ("ideal", "filtered", "improved"):
                for name, sel in (("α ≤ 0.02", lambda a: a <= 0.02),
                                  ("α > 0.02", lambda a: a > 0.02)):
                    rows = [r for (hh, f, m, a), r in res.items()
                            if hh == h and f == film and m.split("/")[0] == method and sel(a)]
                    print(f"{h:>3} {film:5} {method:9} {name:9}  "
                          + "  ".join(f"{x:.1e}" for x in np.max(rows, axis=0)))
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
