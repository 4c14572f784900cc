"""Which path a calibrated lens grid takes in `lfcl process` (docs/outputs.md, "Lens grid").

The paper's camera (docs/layout.md) has lenses on an aligned square grid of
integer pitch: such a mosaic is sliced into the 4D light field exactly. A
calibration (``lfcl calibrate``) describes any grid; :func:`fit_grid` takes the
slicing path (kind ``aligned-square``) when every calibrated lens centre lies
within :data:`ALIGNED_TOLERANCE_PX` of the same lens on an aligned grid of pitch
``round(pitch)``, and the resampling path (kind ``resampled``,
lfcl/demosaic/resampled.py, docs/geometry.md) otherwise, naming why: rotated,
non-integer pitch, sub-pixel offset, hexagonal.
"""

from __future__ import annotations

import math

import numpy as np

#: A calibrated grid is processed as aligned when every lens centre on the sensor is
#: closer than this to the centre of the same lens on an aligned integer-pitch grid.
ALIGNED_TOLERANCE_PX = 0.5
ALIGNED, RESAMPLED = "aligned-square", "resampled"


def describe_grid(cal) -> str:
    """``pitch 9.4000 px, rotation +0.7000 deg, offset 0.300,-0.200 px`` (for messages and summaries)."""
    g = cal.grid
    return (f"pitch {g.pitch:.4f} px, rotation {g.rotation_deg:+.4f} deg, "
            f"offset {g.offset[0]:.3f},{g.offset[1]:.3f} px")


def fit_grid(cal, what: str = "the calibration") -> dict:
    """The processing path of calibration ``cal``: a dict with ``kind`` and what that kind needs.

    Always: ``kind`` (:data:`ALIGNED` or :data:`RESAMPLED`), ``features`` (why a grid is
    resampled: ``hexagonal``, ``rotated``, ``non-integer-pitch``, ``sub-pixel-offset`` or
    ``non-aligned``; empty when aligned) and ``max_deviation_px`` (largest distance of a
    calibrated lens centre from the nearest aligned grid's; None for hexagonal grids).
    Aligned: also ``pitch`` (int), ``first`` (sensor row, col of the first whole lens's
    top-left pixel) and ``lenses`` (S, T of whole lenses from there). ``what`` names the
    calibration's origin in the one-line ``ValueError`` of a grid with no usable lens.
    """
    g = cal.grid
    H, W = cal.sensor_shape
    if g.packing != "square":
        return {"kind": RESAMPLED, "features": ["hexagonal"], "max_deviation_px": None}
    P = round(g.pitch)
    i, j, rows, cols = cal.centres()
    if P < 2 or rows.size == 0:
        raise ValueError(f"{what} has no usable lenses on its {H}x{W} sensor ({describe_grid(cal)})")
    half = (P - 1) / 2
    R0 = round(float(np.median(rows - i * P)) - half)
    C0 = round(float(np.median(cols - j * P)) - half)
    deviation = float(np.max(np.hypot(rows - (R0 + half + i * P), cols - (C0 + half + j * P))))
    if not deviation < ALIGNED_TOLERANCE_PX:
        span = max(H, W)
        features = []
        if abs(math.radians(g.rotation_deg)) * span > 0.1:
            features.append("rotated")
        if abs(g.pitch - P) * span / g.pitch > 0.1:
            features.append("non-integer-pitch")
        if not features:
            features.append("sub-pixel-offset" if abs(g.offset[0] - round(g.offset[0])) > 0.1
                            or abs(g.offset[1] - round(g.offset[1])) > 0.1 else "non-aligned")
        return {"kind": RESAMPLED, "features": features, "max_deviation_px": deviation}
    r0, c0 = R0 % P, C0 % P
    S, T = (H - r0) // P, (W - c0) // P
    if S < 1 or T < 1:
        raise ValueError(f"{what}: no whole {P}x{P} lens fits on the {H}x{W} sensor from pixel ({r0}, {c0})")
    return {"kind": ALIGNED, "features": [], "max_deviation_px": deviation, "pitch": P, "first": (r0, c0),
            "lenses": (S, T)}


def aligned_geometry(cal, what: str = "the calibration") -> dict:
    """:func:`fit_grid` of a grid that must be aligned (square, integer pitch): else a one-line ``ValueError``."""
    geo = fit_grid(cal, what)
    if geo["kind"] != ALIGNED:
        packing = "hexagonal" if cal.grid.packing == "hex" else f"{', '.join(geo['features'])} square"
        raise ValueError(f"{what} describes a {packing} lens grid ({describe_grid(cal)}), not an aligned square "
                         f"grid of integer pitch (within {ALIGNED_TOLERANCE_PX:g} px): it is processed by "
                         "resampling (lfcl.demosaic.resampled)")
    return geo


def calibration_metadata(cal, how: str, path, geo: dict) -> dict:
    """What the outputs record about the calibration used (``calibration`` in docs/outputs.md).

    ``how``: ``--calibration`` or ``--white``; ``path``: the file given; ``geo``: from
    :func:`fit_grid`.
    """
    g = cal.grid
    return {
        "how": how, "file": None if path is None else str(path), "source": cal.source,
        "packing": g.packing, "pitch_px": g.pitch, "rotation_deg": g.rotation_deg, "offset_px": list(g.offset),
        "sensor_shape": list(cal.sensor_shape), "aligned_max_deviation_px": geo["max_deviation_px"],
    }
