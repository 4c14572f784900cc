"""Image-quality metrics on light fields in the exchange layout [S, T, U, V, 3].

PSNR uses peak 1.0 (the normalised raw's white level) over all three channels,
as in the paper's Tables 1-2: on the centre sub-aperture view and on the mean
image (the average over u, v). The colour-artefact metrics (CIEDE2000 mean and
95th percentile, false colour on grey edges, chroma error at high frequencies;
the paper's section 5) are defined in docs/colour-metrics.md and below.
"""

from __future__ import annotations

import math

import numpy as np


def psnr(estimate: np.ndarray, truth: np.ndarray, peak: float = 1.0) -> float:
    """10 log10(peak^2 / MSE), MSE over every element, accumulated in float64."""
    if estimate.shape != truth.shape:
        raise ValueError(f"cannot compare shapes {estimate.shape} and {truth.shape}")
    mse = float(np.mean((estimate.astype(np.float64) - truth.astype(np.float64)) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(peak**2 / mse)


def centre_view(lightfield: np.ndarray) -> np.ndarray:
    """The centre sub-aperture view [S, T, 3] (u = U // 2, v = V // 2)."""
    _, _, U, V, _ = lightfield.shape
    return lightfield[:, :, U // 2, V // 2]


def mean_image(lightfield: np.ndarray) -> np.ndarray:
    """The mean over all (u, v) views [S, T, 3] (float64 accumulation)."""
    return lightfield.mean(axis=(2, 3), dtype=np.float64).astype(np.float32)


def lightfield_scores(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """PSNR of the centre view and of the mean image (the paper's two rows)."""
    if estimate.shape != truth.shape:
        raise ValueError(f"light field {estimate.shape} and truth {truth.shape} differ in shape")
    return {
        "psnr_center": psnr(centre_view(estimate), centre_view(truth)),
        "psnr_mean": psnr(mean_image(estimate), mean_image(truth)),
    }



# --- Colour-artefact metrics (docs/colour-metrics.md) -------------------------------------------
#
# Camera RGB -> CIELAB, fixed: lfcl's simulated camera RGB is linear sRGB (D65), so XYZ is
# colour-science's sRGB matrix applied to the linear values (no transfer function, no chromatic
# adaptation); both images are divided by the same constant, the 99th percentile of the *truth's*
# Y on the view being scored, so that the truth's bright regions sit near L* = 100 whatever the
# illumination; then XYZ -> L*a*b* relative to the white of that matrix (the XYZ of RGB = (1, 1, 1),
# i.e. D65 as the sRGB matrix rounds it), so a grey (R = G = B) has a* = b* = 0 exactly.

CAMERA_COLOURSPACE = "sRGB"
WHITE_PERCENTILE = 99.0        # percentile of the truth's Y that is mapped to Y = 1
ACHROMATIC_CHROMA = 2.0        # truth C*ab below this counts as grey (about one JND)
HIGH_CONTRAST_PERCENTILE = 90.0  # truth |grad L*| at or above this percentile is "high frequency"
MIN_MASK_SHARE = 0.01          # false colour needs >= 1 % of the view's pixels in its mask, else None
COLOUR_KEYS = ("de2000_mean", "de2000_p95", "false_colour", "hf_chroma_error")


def _colourspace():
    import colour

    return colour.RGB_COLOURSPACES[CAMERA_COLOURSPACE]


def _check_image_pair(estimate: np.ndarray, truth: np.ndarray) -> None:
    if estimate.shape != truth.shape:
        raise ValueError(f"cannot compare shapes {estimate.shape} and {truth.shape}")
    if truth.ndim != 3 or truth.shape[-1] != 3:
        raise ValueError(f"colour metrics need (H, W, 3) RGB images, got shape {truth.shape}")
    if truth.shape[0] < 2 or truth.shape[1] < 2:
        raise ValueError(f"colour metrics need images of at least 2x2 pixels, got shape {truth.shape}")


def camera_to_xyz(rgb: np.ndarray) -> np.ndarray:
    """Linear camera RGB (= linear sRGB, D65) -> CIE XYZ, float64, on the same scale."""
    import colour

    return colour.RGB_to_XYZ(np.asarray(rgb, dtype=np.float64), _colourspace(), illuminant=None,
                             apply_cctf_decoding=False)


def reference_white_xy() -> np.ndarray:
    """Chromaticity of camera RGB (1, 1, 1): the white L*a*b* is taken relative to (D65)."""
    import colour

    return colour.XYZ_to_xy(camera_to_xyz(np.ones(3)))


def lab_scale(truth: np.ndarray) -> float:
    """The one constant both images are divided by: the truth's 99th percentile of Y."""
    y = camera_to_xyz(truth)[..., 1]
    scale = float(np.percentile(y, WHITE_PERCENTILE))
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"the truth has no light to normalise by (99th percentile of Y is {scale:g})")
    return scale


def camera_to_lab(rgb: np.ndarray, scale: float) -> np.ndarray:
    """Linear camera RGB -> CIE L*a*b* with Y divided by ``scale`` (float64, L* = 100 at Y = scale)."""
    import colour

    return colour.XYZ_to_Lab(camera_to_xyz(rgb) / scale, reference_white_xy())


def high_contrast_mask(lightness: np.ndarray) -> np.ndarray:
    """|grad L*| (central differences) at or above its 90th percentile over the image, and > 0."""
    gy, gx = np.gradient(lightness)
    magnitude = np.hypot(gx, gy)
    return (magnitude >= np.percentile(magnitude, HIGH_CONTRAST_PERCENTILE)) & (magnitude > 0)


def colour_scores(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """CIEDE2000 (mean, 95th percentile), false colour and high-frequency chroma error of one view.

    ``estimate`` and ``truth`` are (H, W, 3) linear camera RGB on the same scale. With
    Lab_e, Lab_t the two images in CIELAB (see ``camera_to_lab``; one scale from the truth) and
    dab = sqrt((a*_e - a*_t)^2 + (b*_e - b*_t)^2) the chromatic part of the error:

    - ``de2000_mean`` / ``de2000_p95``: mean and 95th percentile of the per-pixel CIEDE2000;
    - ``hf_chroma_error``: mean dab over H, the high-contrast pixels (``high_contrast_mask`` of
      L*_t): colour errors where the truth has edges and texture;
    - ``false_colour``: mean dab over H and the achromatic truth pixels (C*ab_t < 2): the chroma the
      estimate puts on grey edges; None when that mask holds fewer than 1 % of the pixels.

    All are 0 for a perfect estimate and unchanged when both images are multiplied by one constant.
    """
    import colour

    _check_image_pair(estimate, truth)
    scale = lab_scale(truth)
    lab_t = camera_to_lab(truth, scale)
    lab_e = camera_to_lab(estimate, scale)
    de = np.asarray(colour.delta_E(lab_t, lab_e, method="CIE 2000"), dtype=np.float64)
    dab = np.hypot(lab_e[..., 1] - lab_t[..., 1], lab_e[..., 2] - lab_t[..., 2])
    high = high_contrast_mask(lab_t[..., 0])
    grey_edges = high & (np.hypot(lab_t[..., 1], lab_t[..., 2]) < ACHROMATIC_CHROMA)
    enough = grey_edges.sum() >= max(1, MIN_MASK_SHARE * grey_edges.size)
    return {
        "de2000_mean": float(de.mean()),
        "de2000_p95": float(np.percentile(de, 95)),
        "false_colour": float(dab[grey_edges].mean()) if enough else None,
        "hf_chroma_error": float(dab[high].mean()) if high.any() else None,
    }


def lightfield_colour_scores(estimate: np.ndarray, truth: np.ndarray) -> dict:
    """``colour_scores`` of the centre view and of the mean image: keys ``<metric>_center`` / ``_mean``."""
    if estimate.shape != truth.shape:
        raise ValueError(f"light field {estimate.shape} and truth {truth.shape} differ in shape")
    if truth.ndim != 5 or truth.shape[-1] != 3:
        raise ValueError(f"light fields must be [S, T, U, V, 3], got shape {truth.shape}")
    scores = {}
    for suffix, view in (("center", centre_view), ("mean", mean_image)):
        for key, value in colour_scores(view(estimate), view(truth)).items():
            scores[f"{key}_{suffix}"] = value
    return scores
