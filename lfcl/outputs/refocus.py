"""Shift-and-add refocusing of a 4D light field (docs/outputs.md).

A light field in the exchange layout ``[S, T, U, V, C]`` is refocused at a *slope*
``a`` (lenses of shift per pixel step of ``u`` and ``v`` away from the centre
``(u0, v0) = (U // 2, V // 2)``)::

    image(s, t) = mean over (u, v) of  L(s + a (u - u0),  t + a (v - v0),  u,  v)

The view ``(u, v)`` is sampled at the sub-lens position by bilinear interpolation.
Each of the (up to) four bilinear taps that falls outside the ``S x T`` array is
left out, and the sum is divided by the weight actually used, so the border pixels
are the mean of the samples that exist (a constant light field refocuses to the
same constant everywhere, at every slope). The centre view always contributes
with weight 1, so no pixel is left without samples.

A fronto-parallel plane whose image moves by ``d`` lenses per step of ``u`` (and
of ``v``), ``L(s, t, u, v) = texture(s - d (u - u0), t - d (v - v0))``, is brought
back into focus at ``a = d``; ``a = 0`` is the mean image (the focus of the main
lens). Slopes are in lenses, i.e. pixels of the sub-aperture views.
"""

from __future__ import annotations

import math
import re

import numpy as np

#: The most slopes one ``--refocus`` spec may ask for.
MAX_SLOPES = 1000


def _taps(shift: float):
    """``[(offset, weight), ...]`` of linear interpolation at ``x + shift`` (zero weights dropped)."""
    k = math.floor(shift)
    f = shift - k
    taps = [(k, 1.0 - f), (k + 1, f)]
    return [(o, w) for o, w in taps if w > 1e-12]


def _valid(n: int, offset: int) -> tuple[slice, slice]:
    """Destination and source slices of ``dest[i] += src[i + offset]`` for ``0 <= i, i + offset < n``."""
    lo = max(0, -offset)
    hi = min(n, n - offset)
    if hi <= lo:
        return slice(0, 0), slice(0, 0)
    return slice(lo, hi), slice(lo + offset, hi + offset)


def refocus(lightfield: np.ndarray, slope: float, centre: tuple[int, int] | None = None) -> np.ndarray:
    """The light field ``[S, T, U, V, C]`` refocused at ``slope``: ``[S, T, C]`` float32 (module docstring).

    ``centre``: ``(u0, v0)``, default ``(U // 2, V // 2)``.
    """
    lightfield = np.asarray(lightfield)
    if lightfield.ndim != 5:
        raise ValueError(f"a light field must have shape [S, T, U, V, C], got {lightfield.shape}")
    slope = float(slope)
    if not math.isfinite(slope):
        raise ValueError(f"the refocus slope must be finite, got {slope!r}")
    S, T, U, V, C = lightfield.shape
    u0, v0 = (U // 2, V // 2) if centre is None else centre
    total = np.zeros((S, T, C), np.float64)
    weight = np.zeros((S, T), np.float64)
    for u in range(U):
        rows = _taps(slope * (u - u0))
        for v in range(V):
            cols = _taps(slope * (v - v0))
            view = lightfield[:, :, u, v]
            for ro, rw in rows:
                dr, sr = _valid(S, ro)
                for co, cw in cols:
                    dc, sc = _valid(T, co)
                    w = rw * cw
                    total[dr, dc] += w * view[sr, sc]
                    weight[dr, dc] += w
    # weight >= 1 everywhere: the centre view (u0, v0) is never shifted
    return (total / weight[:, :, None]).astype(np.float32)


def focal_stack(lightfield: np.ndarray, slopes) -> list[np.ndarray]:
    """:func:`refocus` at every slope of ``slopes``."""
    return [refocus(lightfield, a) for a in slopes]


_NUMBER = r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?"


def parse_slopes(spec: str) -> list[float]:
    """Slopes from ``start:stop:step`` (stop included when it lands on the grid) or a comma list.

    ``-1:1:0.25`` -> -1, -0.75, ..., 1; ``0:1:0.3`` -> 0, 0.3, 0.6, 0.9; ``0.5,-0.5,2``
    -> as given. Repeated values are kept once, in order. ``ValueError`` (one line)
    for anything else: a malformed number, a zero step, a step pointing away from
    stop, more than :data:`MAX_SLOPES` slopes.
    """
    text = str(spec).strip()
    if not text:
        raise ValueError("empty --refocus: give start:stop:step (e.g. -1:1:0.25) or a comma list of slopes")

    def number(part: str) -> float:
        part = part.strip()
        if not re.fullmatch(_NUMBER, part):
            raise ValueError(f"malformed --refocus {spec!r}: {part!r} is not a number "
                             "(expected start:stop:step, e.g. -1:1:0.25, or a comma list such as -0.5,0,0.5)")
        return float(part)

    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise ValueError(f"malformed --refocus {spec!r}: a range is start:stop:step, e.g. -1:1:0.25")
        start, stop, step = (number(p) for p in parts)
        if step == 0:
            raise ValueError(f"malformed --refocus {spec!r}: the step must not be 0")
        span = (stop - start) / step
        if span < -1e-9:
            raise ValueError(f"malformed --refocus {spec!r}: a step of {step:g} never gets from {start:g} to {stop:g}")
        count = math.floor(max(span, 0.0) + 1e-9) + 1
        if count > MAX_SLOPES:
            raise ValueError(f"--refocus {spec!r} asks for {count} slopes; at most {MAX_SLOPES}")
        values = [start + i * step for i in range(count)]
    else:
        values = [number(p) for p in text.split(",")]
        if len(values) > MAX_SLOPES:
            raise ValueError(f"--refocus {spec!r} asks for {len(values)} slopes; at most {MAX_SLOPES}")
    out: list[float] = []
    for value in values:
        value = round(value, 9) + 0.0  # 0.1 * 3 -> 0.3; -0.0 -> 0.0
        if not math.isfinite(value):
            raise ValueError(f"malformed --refocus {spec!r}: slopes must be finite")
        if value in out:
            continue
        clash = [v for v in out if slope_label(v) == slope_label(value)]
        if clash:
            raise ValueError(f"--refocus slopes {clash[0]!r} and {value!r} differ only past 6 significant digits "
                             "(their files would share a name)")
        out.append(value)
    return out


def slope_label(slope: float) -> str:
    """The slope as it appears in file names: ``+0.25``, ``-1``, ``+0``."""
    text = f"{float(slope) + 0.0:+.6g}"
    return "+0" if text in ("+0", "-0") else text
