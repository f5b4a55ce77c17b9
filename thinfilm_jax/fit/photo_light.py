r"""The light's variation across a photograph for `fit_photo(..., illumination="smooth")`
(SPEC §14): vignetting, a lamp off to one side.

The model of `fit.photo` becomes o_pc = L(x_p) · g_c · (C s(d_p))_c with a smooth positive
field

$$ L(x) = \exp\Big(\sum_{0 < i + j \le 2} a_{ij}\, u^i v^j\Big), \qquad
   u = 2x/W - 1,\; v = 2y/H - 1, $$

the exponential of a degree-2 polynomial in normalised pixel coordinates without its
constant (5 parameters: u, v, u², uv, v²; the constant is the exposure), positive by
construction, then scaled so that its peak over the fitted pixels is 1 (the exposure is the
peak's). It is fitted by alternation on a subsample of pixels (every pad pixel included):
the thicknesses at the current field (each pixel's best fringe order by the screen, then
refined), then the field and three gain corrections from the pixels' log ratios
log(o_pc / ĝ_c s_c(d_p)) by weighted least squares (weights (ŝ/σ)², the delta method),
made robust by Tukey's biweight at 4.685 robust standard deviations (MAD), so that pixels
in a wrong fringe order do not pull the field; `_ROUNDS` times. Reference pixels enter at
their known thickness and pin the field there. The photograph is then divided by the field
and fitted as under uniform light. A channel clipped at full scale stays censored at 1 in
the divided image: the true bound 1/L ≥ 1 is stronger, so the censored term errs only on
the permissive side.

Identifiability. A film's colours determine the field only where a change of light cannot
pass for a change of thickness: with the per-pixel thickness eliminated, the information on
the field's coefficients is Σ_p B_pᵀB_p, B_p = P⊥_p (q_p φ_pᵀ), q_p = ŝ_p/σ_p the pixel's
scaled colour, φ_p its 5 basis values and P⊥_p the projection off ∂(ŝ/σ)/∂d (none for a
pad). `identifiability` returns the smallest generalised eigenvalue of that information
against the one with every thickness known (1: the colours pin the field as well as known
thicknesses would; 0: not at all); below `MIN_IDENTIFIABLE` `fit_photo` warns.

Example (a field recovered from pixels of known colour by Gauss–Newton steps):
    >>> import numpy as np
    >>> from thinfilm_jax.fit.photo_light import N_FIELD, basis, fit_field
    >>> phi = basis(np.arange(64), 8, 8)
    >>> a = np.linspace(-0.2, 0.2, N_FIELD)
    >>> pred = np.tile([0.3, 0.5, 0.4], (64, 1))
    >>> obs = pred * np.exp(phi @ a)[:, None]
    >>> coef = np.zeros(N_FIELD)
    >>> for _ in range(6):
    ...     coef += fit_field(obs, np.full_like(obs, 1e-3), np.zeros(obs.shape, int),
    ...                       pred * np.exp(phi @ coef)[:, None], phi)[0]
    >>> bool(np.allclose(coef, a, atol=1e-9))
    True
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ILLUMINATIONS",
    "DEGREE",
    "N_FIELD",
    "MIN_IDENTIFIABLE",
    "basis",
    "fit_field",
    "identifiability",
    "fit_light",
]

ILLUMINATIONS = ("uniform", "smooth")
DEGREE = 3  # the field's polynomial degree
N_FIELD = (DEGREE + 1) * (DEGREE + 2) // 2 - 1  # its parameters, without the constant
_ROUNDS = 6  # alternations of the thicknesses and the field
_SAMPLE = 8192  # pixels of the alternation (every pad pixel besides)
_TUKEY = 4.685  # Tukey's biweight constant (robust standard deviations)
_IRLS = 8  # reweighting iterations of one field fit
MIN_IDENTIFIABLE = 0.08  # `identifiability` below this: the field is not determined


def basis(where, h: int, w: int, degree: int = DEGREE) -> np.ndarray:
    """(n, N_FIELD) the monomials u^i v^j, 0 < i + j ≤ `degree`, at the flat pixel indices
    `where` of an (h, w) image (pixel centres; u, v ∈ [−1, 1])."""
    y, x = np.divmod(np.asarray(where), w)
    u = 2.0 * (x + 0.5) / w - 1.0
    v = 2.0 * (y + 0.5) / h - 1.0
    return np.stack([u ** (t - j) * v ** j for t in range(1, degree + 1)
                     for j in range(t + 1)], axis=-1)


def fit_field(obs, sig, cens, pred, phi, dpred=None):
    """(δa (N_FIELD,), per-channel gain factors (3,)): one robust Gauss–Newton step of the
    field's coefficients and three gain corrections, o_pc ≈ pred_pc · exp(δc_c + φ_p·δa),
    over the uncensored readings (module docstring). With `dpred` = ∂pred/∂d (n, 3) each
    pixel's thickness moves too and is eliminated (its tangent projected out: the joint
    step; NaN rows: a pad, whose thickness is known)."""
    n, nb = obs.shape[0], phi.shape[1]
    use = (cens == 0) & (pred > 0)
    z = np.where(use, (obs - pred) / sig, 0.0)  # (n, 3)
    q = np.where(use, pred / sig, 0.0)
    x = q[..., None] * np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)),
                                       np.broadcast_to(phi[:, None, :], (n, 3, nb))], -1)
    if dpred is not None:  # project each pixel's thickness direction out
        t = np.where(use, np.nan_to_num(dpred) / sig, 0.0)
        tn = t / np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-300)
        tn = np.where(np.isnan(dpred[:, :1]), 0.0, tn)
        z = z - tn * np.sum(tn * z, -1, keepdims=True)
        x = x - tn[..., None] * np.einsum("pc,pcj->pj", tn, x)[:, None, :]
    xf, zf = x.reshape(-1, 3 + nb), z.reshape(-1)
    rob = use.reshape(-1).astype(float)
    beta = np.zeros(3 + nb)
    for _ in range(_IRLS):
        a = (xf * rob[:, None]).T @ xf
        beta = np.linalg.solve(a + 1e-12 * np.trace(a) * np.eye(3 + nb), xf.T @ (rob * zf))
        e = (zf - xf @ beta)[use.reshape(-1)]
        mad = np.median(np.abs(e)) / 0.6745 if e.size else 1.0
        tt = np.clip((zf - xf @ beta) / max(_TUKEY * mad, 1e-300), -1.0, 1.0)
        rob = np.where(use.reshape(-1), (1.0 - tt * tt) ** 2, 0.0)
    return beta[3:], np.exp(beta[:3])


def identifiability(pred, dpred, sig, phi, known) -> float:
    """The share of the information on the three gains and the field's coefficients that
    the film's colours keep once each pixel's thickness is free (module docstring): pred,
    dpred = ĝ s(d), ĝ ∂s/∂d (n, 3), σ (n, 3), φ (n, N_FIELD), `known` (n,) bool the pads."""
    n, nb = phi.shape
    q = pred / sig
    x = q[..., None] * np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)),
                                       np.broadcast_to(phi[:, None, :], (n, 3, nb))], -1)
    t = dpred / sig
    tn = t / np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-300)
    tn = np.where(known[:, None], 0.0, tn)
    xp = x - tn[..., None] * np.einsum("pc,pcj->pj", tn, x)[:, None, :]
    full = np.einsum("pci,pcj->ij", x, x)
    kept = np.einsum("pci,pcj->ij", xp, xp)

    def share(block):
        f, k = full[block, block], kept[block, block]
        ci = np.linalg.inv(np.linalg.cholesky(f + 1e-12 * np.trace(f) * np.eye(f.shape[0])))
        return float(np.linalg.eigvalsh(ci @ k @ ci.T).min())

    return min(share(slice(0, 3)), share(slice(3, None)))


def fit_light(obs, sig, cens, known, phi, gm, colour, screen, refine):
    """(L (n,) the field at every pixel, peak 1; gm (3, B) the gains, corrected; the
    subsample's identifiability) by the alternation of the module docstring.

    colour(d) → (ĝ-free s(d) (m, B), ∂s/∂d (m, B)) of the table; screen(o, σ, c, gm) → each
    pixel's best thickness on the screen grid; refine(o, σ, c, d0, gm) → refined d."""
    n = obs.shape[0]
    pads = np.isfinite(known)
    sub = np.unique(np.r_[np.arange(0, n, max(1, n // _SAMPLE)), np.flatnonzero(pads)])
    o, sg, cs, kn, ph = obs[sub], sig[sub], cens[sub], known[sub], phi[sub]
    a = np.zeros(phi.shape[1])
    for _ in range(_ROUNDS):
        lf = np.exp(ph @ a)[:, None]
        oc, sc = o / lf, sg / lf
        d = screen(oc, sc, cs, gm)
        d = np.where(np.isfinite(kn), kn, refine(oc, sc, cs, d, gm))
        s, ds = colour(d)
        dp = np.where(np.isfinite(kn)[:, None], np.nan, ds @ gm.T * lf)
        a_new, corr = fit_field(o, sg, cs, s @ gm.T * lf, ph, dp)
        a = a + a_new
        gm = corr[:, None] * gm
        if np.max(np.abs(a_new)) < 1e-6 and np.max(np.abs(np.log(corr))) < 1e-6:
            break
    s, ds = colour(d)
    lf = np.exp(ph @ a)[:, None]
    ident = identifiability(s @ gm.T * lf, ds @ gm.T * lf, sg, ph, np.isfinite(kn))
    logl = phi @ a
    peak = logl.max()
    return np.exp(logl - peak), gm * np.exp(peak), ident
