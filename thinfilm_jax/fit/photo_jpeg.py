r"""The compression noise of a JPEG's colour, for `fit_photo` (SPEC §13–§14).

A baseline JPEG (ITU-T T.81; JFIF, ITU-T T.871) stores the luma Y at full resolution and the
chroma Cb, Cr at half resolution in each direction (4:2:0: one chroma sample per 2 × 2
block, libjpeg's default at every quality), then quantises each 8 × 8 block's cosine
coefficients, the chroma's with coarser steps than the luma's. The decoder interpolates the
chroma back ("fancy" triangular upsampling). A pixel's decoded chroma is therefore not its
own but a blend of the samples around it, one chroma pitch (2 pixels) apart, whose
high-frequency content the quantiser has cut: where the film's colour changes fast (the
saturated low fringe orders of a soap film, a few pixels per fringe) the decoded colour is
off by up to a tenth of full scale, hundreds of times the sensor noise, and it is off in
chroma, not in luma.

The model has two terms, both in the encoded domain (code values / 255), per channel.

1. **The sensor's noise as the JPEG kept it.** The quantiser removes most of the noise's
   highest spatial frequencies, which are what Immerkær's estimator measures (`core.image
   .estimate_noise`: on the decoded soap film of `benchmarks.photo_light` it reads 2–3 ×
   below the noise actually left in the pixels), but keeps the lower ones, which a
   per-pixel fit feels in full. The noise is therefore measured on the image binned 2 × 2
   (the chroma's sampling grid): σ_n = 2 σ_Immerkær(binned), which equals the per-pixel σ
   for white noise (a mean of 4 has σ/2) and sees the noise the JPEG left at the
   block scale (on that film within 20 % of the truth per channel); plus the 8-bit
   quantisation (1/255)²/12.
2. **The 4:2:0 chroma.** A pixel's chroma is its 2 × 2 block's (the encoder's box mean),
   sampled at the block's centre, ½ pixel from the pixel in x and in y: it is off by the
   chroma's gradient times that offset, (±½, ±½) · ∇C, of variance

   $$ \sigma_{C}^2 = \tfrac14\left[\left(\frac{\partial C}{\partial x}\right)^2
      + \left(\frac{\partial C}{\partial y}\right)^2\right] \quad (C = C_b, C_r;
      \text{central differences of the decoded image}), $$

   independent between Cb and Cr, carried to R′G′B′ by the JFIF inverse transform
   R′ = Y + 1.402 Cr, G′ = Y − 0.344136 Cb − 0.714136 Cr, B′ = Y + 1.772 Cb (its per-channel
   variances; the cross-channel covariance is not kept, as the fit's noise is per channel).

The sum is carried to linear values by the slope of the decoding (dL/dv of IEC 61966-2-1 for
sRGB) and replaces the reader's noise of a JPEG in `fit_photo`: the pixels whose colour
JPEG blurs weigh less in the gains and in the choice of fringe order, instead of pulling the
white balance off (on that soap film: the red gain 4 % low without it) and so shifting every
washed-out high-order colour to a wrong order; and the standard errors come from the noise
that is in the pixels.

A camera clips a colour outside its gamut (a negative sRGB channel) to black before it
encodes the JPEG, whose chroma then rings the clipped channel back up by a few codes: a
JPEG's reading is compared with the clipped colour, max(g C s(d), 0) (`photo_screen
.residual`, the third clip level), and a colour the camera clipped does not inform the
gains.

Example (a horizontal ramp of Cr by 4 codes per pixel: σ_Cr = ½ · 4 codes, so
σ_R′ = 1.402 · 2 and σ_B′ = 0; a flat image has no chroma noise):
    >>> import numpy as np
    >>> from thinfilm_jax.fit.photo_jpeg import chroma_sigma
    >>> cr = np.tile(4.0 * np.arange(6), (4, 1))
    >>> rgb = np.stack([128 + 1.402 * cr, 128 - 0.714136 * cr, 128 + 0 * cr], -1) / 255
    >>> s = chroma_sigma(rgb) * 255
    >>> np.round(s[2, 2], 4).tolist()
    [2.804, 1.4283, 0.0]
    >>> float(np.abs(chroma_sigma(np.full((4, 4, 3), 0.5))).max())
    0.0
"""

from __future__ import annotations

import numpy as np

from ..core.image import Photo, estimate_noise, srgb_decoding_derivative, srgb_encoding

__all__ = ["block_noise", "chroma_sigma", "jpeg_noise"]

#: JFIF (ITU-T T.871) R′G′B′ → Cb, Cr rows (full-range BT.601)
_TO_CHROMA = np.array([[-0.168736, -0.331264, 0.5], [0.5, -0.418688, -0.081312]])
#: ∂(R′, G′, B′)/∂(Cb, Cr) of the JFIF inverse transform
_FROM_CHROMA = np.array([[0.0, 1.402], [-0.344136, -0.714136], [1.772, 0.0]])


def chroma_sigma(encoded) -> np.ndarray:
    """σ (H, W, 3) of each encoded channel (the units of `encoded`, an (H, W, 3) R′G′B′
    image) from the 4:2:0 chroma: ½ |∇C| per chroma channel (module docstring, term 2)."""
    v = np.asarray(encoded, np.float64)
    if v.ndim != 3 or v.shape[-1] != 3:
        raise ValueError(f"encoded must be an (H, W, 3) image, got shape {v.shape}")
    chroma = v @ _TO_CHROMA.T  # (H, W, 2)
    var = np.zeros_like(chroma)
    for axis in (0, 1):
        if v.shape[axis] > 1:
            var += 0.25 * np.gradient(chroma, axis=axis) ** 2
    return np.sqrt(var @ (_FROM_CHROMA ** 2).T)


def block_noise(encoded, valid=None) -> np.ndarray:
    """σ (3,) of the noise at the 2 × 2 block scale: 2 × Immerkær's estimate on the image
    binned 2 × 2 (`valid` (H, W): the blocks of valid pixels only; module docstring, term 1)."""
    v = np.asarray(encoded, np.float64)
    h, w = (s - s % 2 for s in v.shape[:2])
    binned = v[:h, :w].reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))
    ok = None if valid is None else np.asarray(valid, bool)[:h, :w].reshape(
        h // 2, 2, w // 2, 2).all(axis=(1, 3))
    return 2.0 * estimate_noise(binned, ok)


def jpeg_noise(photo: Photo, valid=None) -> np.ndarray:
    """σ (H, W, 3) of a decoded 8-bit JPEG's linear values (module docstring): the noise at
    the block scale, the quantisation and the 4:2:0 chroma, times dL/dv of its encoding.
    `valid` (H, W): the pixels with no clipped channel (the noise is measured on them)."""
    srgb = photo.encoding == "srgb"
    v = np.clip(srgb_encoding(photo.linear), 0.0, 1.0) if srgb else photo.linear
    var = block_noise(v, valid) ** 2 + 1.0 / (12 * 255 ** 2) + chroma_sigma(v) ** 2
    return np.sqrt(var) * (srgb_decoding_derivative(v) if srgb else 1.0)

