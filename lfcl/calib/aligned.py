"""The aligned square grid of integer pitch that a calibration describes (docs/outputs.md, "Lens grid").

The paper's camera (docs/layout.md) has lenses on an aligned square grid of
integer pitch: such a mosaic is sliced into the 4D light field exactly. A
calibration (``lfcl calibrate``) describes any grid; :func:`aligned_geometry`
accepts it when every calibrated lens centre lies within
:data:`ALIGNED_TOLERANCE_PX` of the same lens on an aligned grid of pitch
``round(pitch)``, and names the geometry otherwise (rotated, non-integer pitch,
sub-pixel offset, hexagonal), which the demosaic stage cannot take yet.
"""

from __future__ import annotations

import math

import numpy as np

#: A calibrated grid is processed as aligned when every lens centre on the sensor is
#: closer than this to the centre of the same lens on an aligned integer-pitch grid.
ALIGNED_TOLERANCE_PX = 0.5


def aligned_geometry(cal, what: str = "the calibration") -> dict:
    """The aligned square grid of integer pitch that ``cal`` describes, or a one-line ``ValueError``.

    Returns ``pitch`` (int), ``first`` (sensor row, col of the first whole lens's
    top-left pixel), ``lenses`` (S, T of whole lenses from there) and
    ``max_deviation_px`` (largest distance of a calibrated lens centre from the
    aligned grid's). ``what`` names the calibration's origin in the messages.
    """
    g = cal.grid
    H, W = cal.sensor_shape
    desc = (f"pitch {g.pitch:.4f} px, rotation {g.rotation_deg:+.4f} deg, "
            f"offset {g.offset[0]:.3f},{g.offset[1]:.3f} px")
    tail = "is not implemented yet: lfcl process takes aligned square grids of integer pitch and zero rotation"
    if g.packing != "square":
        raise ValueError(f"processing a hexagonal lens grid ({what}: {desc}) {tail}")
    P = round(g.pitch)
    i, j, rows, cols = cal.centres()
    if P < 2 or rows.size == 0:
        raise ValueError(f"{what} has no usable lenses on its {H}x{W} sensor ({desc})")
    half = (P - 1) / 2
    R0 = round(float(np.median(rows - i * P)) - half)
    C0 = round(float(np.median(cols - j * P)) - half)
    deviation = float(np.max(np.hypot(rows - (R0 + half + i * P), cols - (C0 + half + j * P))))
    if not deviation < ALIGNED_TOLERANCE_PX:
        span = max(H, W)
        kinds = []
        if abs(math.radians(g.rotation_deg)) * span > 0.1:
            kinds.append("rotated")
        if abs(g.pitch - P) * span / g.pitch > 0.1:
            kinds.append("non-integer-pitch")
        if not kinds:
            kinds.append("sub-pixel-offset" if abs(g.offset[0] - round(g.offset[0])) > 0.1
                         or abs(g.offset[1] - round(g.offset[1])) > 0.1 else "non-aligned")
        raise ValueError(
            f"processing a {', '.join(kinds)} square lens grid ({what}: {desc}; lens centres up to "
            f"{deviation:.2f} px off the nearest aligned grid of pitch {P}, less than {ALIGNED_TOLERANCE_PX:g} px "
            f"is processed as aligned) {tail}")
    r0, c0 = R0 % P, C0 % P
    S, T = (H - r0) // P, (W - c0) // P
    if S < 1 or T < 1:
        raise ValueError(f"{what}: no whole {P}x{P} lens fits on the {H}x{W} sensor from pixel ({r0}, {c0})")
    return {"pitch": P, "first": (r0, c0), "lenses": (S, T), "max_deviation_px": deviation}


def calibration_metadata(cal, how: str, path, geo: dict) -> dict:
    """What the outputs record about the calibration used (``calibration`` in docs/outputs.md).

    ``how``: ``--calibration`` or ``--white``; ``path``: the file given; ``geo``: from
    :func:`aligned_geometry`.
    """
    g = cal.grid
    return {
        "how": how, "file": None if path is None else str(path), "source": cal.source,
        "packing": g.packing, "pitch_px": g.pitch, "rotation_deg": g.rotation_deg, "offset_px": list(g.offset),
        "sensor_shape": list(cal.sensor_shape), "aligned_max_deviation_px": geo["max_deviation_px"],
    }
