"""The sampling model of any lens grid: the regular 4D light field the solvers estimate, and the sensor.

A calibrated grid (:class:`lfcl.grid.Calibration`, or the simulator's
:class:`lfcl.sim.geometry.GridGeometry`) may be rotated, of non-integer pitch or
hexagonal. The methods still estimate a *regular* light field ``[S, T, U, V, 3]``
(planes ``[3, S*U, T*V]``, docs/layout.md); this module says where each of its
samples lies on the sensor and builds the two sparse maps between them
(docs/geometry.md has the full model and its conventions):

* **lenses** ``(s, t)``: the largest ``S x T`` block of calibration lens indices
  ``(i, j) = (i0 + s, j0 + t)`` whose lenses lie wholly on the sensor. Hexagonal
  grids keep the calibration's numbering, in which odd lens rows ``i`` are shifted
  by half a pitch along the row; ``i0`` is even, so odd ``s`` are the shifted rows.
* **views** ``(u, v)``: ``U x V`` (default ``round(pitch)`` each) positions spread
  evenly over one pitch along the lens grid's own axes, centred on the lens:

      p(s, t, u, v) = centre(i0 + s, j0 + t) + (u - u0) e_u + (v - v0) e_v
      e_v = col_step / V,   e_u = row_step / (h U),   u0 = (U - 1) / 2, v0 = (V - 1) / 2

  (``h`` = 1 square, sqrt(3)/2 hex). For an aligned square grid of integer pitch
  ``e_u = (1, 0)``, ``e_v = (0, 1)`` and every sample is a sensor pixel.
* **forward map** ``A`` (the data term of the ADMM methods): every sensor pixel
  whose white-image weight is at least ``threshold`` and whose nearest lens is in
  the block is one measurement: its colour's plane, interpolated bilinearly at the
  pixel's continuous ``(u, v)`` *within its own lens* (clamped to the lens's
  ``U x V`` samples), i.e. ``A = CFA-pick(R x)``, at most 4 taps a row. Pixels
  with a low weight (between micro-images) are left out.
* **resampling map** ``M`` (the malvar method and the ADMM start): every regular
  sample is the bilinear interpolation of a full-colour sensor image at
  ``p(s, t, u, v)``, using only the (up to 4) neighbouring pixels that are valid
  and belong to the same lens (weights renormalised); a sample with none takes the
  taps of the nearest sample of its lens that has some.

The data term works on the flat-fielded raw: ``b = raw / response`` with weight
``response^2`` (lfcl/grid/vignetting.py), ``response`` the white-image weight.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.sparse

from ..layout import LightFieldShape, channel_map, parse_pattern

DEFAULT_THRESHOLD = 0.2
SNAP = 1e-9  # view steps
EDGE = 0.5  # px: how far a lens's outermost samples may lie past the outermost pixel centres
CORE = 0.2  # pitches: the micro-image core whose median calibration weight is taken as 1
FILL_STEPS = 6  # dark-pixel fill before a 2D demosaic: reaches 12 px from a micro-image


def _complete_lenses(grid, sensor_shape, views):
    """Lens index ranges and a mask of the lenses whose U x V sample square lies on the sensor.

    "On the sensor": within the pixels' own area, ``-EDGE .. H - 1 + EDGE``, so that a
    calibration a hair off an aligned grid keeps the lenses at the sensor's edges.

    Returns ``(i_values [ni], j_values [nj], complete [ni, nj])``.
    """
    H, W = sensor_shape
    m_lo, m_hi, n_lo, n_hi = grid.lattice_range((H, W))
    i_values = np.arange(m_lo, m_hi + 1)
    shift = (m_lo // 2, m_hi // 2) if grid.packing == "hex" else (0, 0)
    j_values = np.arange(n_lo + min(shift) - 1, n_hi + max(shift) + 2)
    ii, jj = np.meshgrid(i_values, j_values, indexing="ij")
    rows, cols = grid.centre(ii, jj)
    eu, ev = view_steps(grid, views)
    U, V = views
    complete = np.ones(ii.shape, bool)
    for a in (-(U - 1) / 2, (U - 1) / 2):
        for b in (-(V - 1) / 2, (V - 1) / 2):
            r = rows + a * eu[0] + b * ev[0]
            c = cols + a * eu[1] + b * ev[1]
            complete &= (r >= -EDGE) & (r <= H - 1 + EDGE) & (c >= -EDGE) & (c <= W - 1 + EDGE)
    return i_values, j_values, complete


def _largest_block(i_values, j_values, complete, even_start: bool):
    """The largest rectangle of lens indices inside ``complete``: ``(i0, j0, S, T)``."""
    ni = len(i_values)
    has = complete.any(axis=1)
    first = np.where(has, complete.argmax(axis=1), 0)
    last = np.where(has, complete.shape[1] - 1 - complete[:, ::-1].argmax(axis=1), -1)
    best = (0, 0, 0, 0, 0)  # area, i0, j0, S, T
    for a in range(ni):
        if not has[a] or (even_start and i_values[a] % 2):
            continue
        lo, hi = first[a], last[a]
        for b in range(a, ni):
            if not has[b]:
                break
            lo, hi = max(lo, first[b]), min(hi, last[b])
            if hi < lo:
                break
            area = (b - a + 1) * (hi - lo + 1)
            if area > best[0]:
                best = (area, int(i_values[a]), int(j_values[lo]), b - a + 1, int(hi - lo + 1))
    return best[1:]


def view_steps(grid, views):
    """``(e_u, e_v)``: the sensor displacement (rows, cols) of one view step along u and along v."""
    U, V = views
    ev = np.asarray(grid.col_step, np.float64) / V
    eu = np.asarray(grid.row_step, np.float64) / (grid.row_factor * U)
    return eu, ev


@dataclasses.dataclass(frozen=True, eq=False)
class SamplingModel:
    """The regular light field of a lens grid on a sensor, and its maps to and from the sensor.

    Build with :func:`sampling_model`. ``response`` is the white-image weight of
    every pixel ([H, W], 1 = best lit) and ``threshold`` the weight below which a
    pixel is left out of the data term.
    """

    grid: object  # lfcl.grid.LensGrid
    sensor_shape: tuple[int, int]
    pattern: str
    views: tuple[int, int]
    lens_origin: tuple[int, int]  # calibration index (i0, j0) of regular lens (0, 0)
    lenses: tuple[int, int]  # (S, T)
    response: np.ndarray  # float32 [H, W]
    threshold: float

    # --- shapes ---------------------------------------------------------------
    @property
    def shape(self) -> LightFieldShape:
        return LightFieldShape(self.lenses[0], self.lenses[1], self.views[0], self.views[1])

    @property
    def planes_shape(self) -> tuple[int, int, int]:
        return self.shape.planes_shape

    @property
    def samples(self) -> int:
        """Samples per colour plane, S*U*T*V."""
        S, T = self.lenses
        U, V = self.views
        return S * T * U * V

    @property
    def steps(self):
        """``(e_u, e_v)``: see :func:`view_steps`."""
        return view_steps(self.grid, self.views)

    @property
    def exact(self) -> bool:
        """Whether every regular sample is a sensor pixel (an aligned grid of integer pitch)."""
        eu, ev = self.steps
        rows, cols = self.lens_centres()
        U, V = self.views
        top = (rows - (U - 1) / 2, cols - (V - 1) / 2)
        return bool(np.allclose(eu, (1, 0), atol=1e-9) and np.allclose(ev, (0, 1), atol=1e-9)
                    and all(np.allclose(a, np.rint(a), atol=1e-9) for a in top))

    # --- geometry ---------------------------------------------------------------
    def lens_centres(self):
        """Sensor ``(rows, cols)`` of the centres of the regular lenses, each ``[S, T]``."""
        S, T = self.lenses
        i0, j0 = self.lens_origin
        ii, jj = np.meshgrid(np.arange(S) + i0, np.arange(T) + j0, indexing="ij")
        return self.grid.centre(ii, jj)

    def sample_positions(self):
        """Sensor ``(rows, cols)`` of every regular sample, each ``[S, T, U, V]`` float64."""
        rows, cols = self.lens_centres()
        U, V = self.views
        eu, ev = self.steps
        du = (np.arange(U) - (U - 1) / 2)[:, None]
        dv = (np.arange(V) - (V - 1) / 2)[None, :]
        r = rows[:, :, None, None] + du * eu[0] + dv * ev[0]
        c = cols[:, :, None, None] + du * eu[1] + dv * ev[1]
        return r, c

    def pixel_coordinates(self, rows, cols):
        """Each sensor position's nearest lens and continuous view: ``(s, t, u, v)``.

        ``s, t`` (int64) are regular lens indices (outside ``[0, S) x [0, T)`` for
        lenses not in the block); ``u, v`` (float64) are unclamped, so a pixel near
        the rim of its micro-image can lie beyond ``[0, U - 1]``.
        """
        i, j, dr, dc = self.grid.nearest(rows, cols)
        eu, ev = self.steps
        inverse = np.linalg.inv(np.stack([eu, ev], axis=1))
        U, V = self.views
        u = (U - 1) / 2 + inverse[0, 0] * dr + inverse[0, 1] * dc
        v = (V - 1) / 2 + inverse[1, 0] * dr + inverse[1, 1] * dc
        # rounding noise of the lattice inverse: snap to the sample a pixel sits on, so an
        # aligned grid of integer pitch gives one tap of weight 1, not four with 1e-15 in them
        u = np.where(np.abs(u - np.rint(u)) < SNAP, np.rint(u), u)
        v = np.where(np.abs(v - np.rint(v)) < SNAP, np.rint(v), v)
        return i - self.lens_origin[0], j - self.lens_origin[1], u, v

    def _pixel_lenses(self):
        """Flat index s*T + t of each sensor pixel's nearest lens ([H, W] int64, -1 outside the block)."""
        H, W = self.sensor_shape
        rows, cols = np.meshgrid(np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64), indexing="ij")
        s, t, _, _ = self.pixel_coordinates(rows, cols)
        S, T = self.lenses
        inside = (s >= 0) & (s < S) & (t >= 0) & (t < T)
        return np.where(inside, s * T + t, -1)

    def valid(self) -> np.ndarray:
        """``[H, W]`` bool: pixels bright enough (weight >= threshold) to be measurements."""
        return self.response >= self.threshold

    # --- the data term -----------------------------------------------------------
    def measured_pixels(self) -> np.ndarray:
        """Flat sensor indices (ascending) of the pixels in the data term."""
        lens = self._pixel_lenses()
        return np.flatnonzero((lens >= 0) & self.valid())

    def forward_matrix(self, pixels: np.ndarray | None = None) -> scipy.sparse.csr_matrix:
        """A: ``[n_pixels, 3 * S*U*T*V]`` CSR (float64), row k = measured pixel ``pixels[k]``.

        Columns index the planes ``[3, S*U, T*V]`` flattened; a row holds the
        bilinear weights of its pixel's position in its own lens and colour plane.
        """
        if pixels is None:
            pixels = self.measured_pixels()
        rows, cols = np.divmod(pixels, self.sensor_shape[1])
        s, t, u, v = self.pixel_coordinates(rows.astype(np.float64), cols.astype(np.float64))
        S, T = self.lenses
        U, V = self.views
        if np.any((s < 0) | (s >= S) | (t < 0) | (t >= T)):
            raise ValueError("a measured pixel lies outside the regular lens block")
        colour = channel_map((2, 2), self.pattern)[rows % 2, cols % 2]
        iu, fu = _bilinear_index(u, U)
        iv, fv = _bilinear_index(v, V)
        plane = colour * self.samples
        taps_col, taps_w = [], []
        for du, wu in ((0, 1 - fu), (1, fu)):
            for dv, wv in ((0, 1 - fv), (1, fv)):
                taps_col.append(plane + (s * U + iu + du) * (T * V) + t * V + iv + dv)
                taps_w.append(wu * wv)
        return _csr_from_taps(np.stack(taps_col, 1), np.stack(taps_w, 1), (pixels.size, 3 * self.samples))

    def data(self, mosaic: np.ndarray, pixels: np.ndarray | None = None, interpolation_weight: float = 0.0):
        """``(b, weights)`` of the data term: the flat-fielded raw at the measured pixels, ``response^2``.

        ``interpolation_weight`` k > 0 divides a pixel's weight by ``1 + k g``, ``g =
        2 (fu (1 - fu) + fv (1 - fv))`` in 0..1 from its fractional view position:
        trust pixels between regular samples less (their bilinear model is worst
        there). 0 (default): the plain weighted data term.
        """
        if pixels is None:
            pixels = self.measured_pixels()
        response = self.response.ravel()[pixels].astype(np.float64)
        b = np.asarray(mosaic, np.float64).ravel()[pixels] / response
        weights = response**2
        if interpolation_weight:
            if not (math.isfinite(interpolation_weight) and interpolation_weight > 0):
                raise ValueError(f"interpolation_weight must be a finite number >= 0, got {interpolation_weight!r}")
            rows, cols = np.divmod(pixels, self.sensor_shape[1])
            _, _, u, v = self.pixel_coordinates(rows.astype(np.float64), cols.astype(np.float64))
            _, fu = _bilinear_index(u, self.views[0])
            _, fv = _bilinear_index(v, self.views[1])
            weights = weights / (1 + interpolation_weight * 2 * (fu * (1 - fu) + fv * (1 - fv)))
        return b.astype(np.float32), weights.astype(np.float32)

    def flat_field(self, mosaic: np.ndarray, fill_steps: int = FILL_STEPS) -> np.ndarray:
        """The raw divided by the response where valid, the dark pixels between micro-images filled: [H, W] float32.

        For a 2D demosaic of the whole sensor (the malvar method): left dark, the
        pixels between micro-images would leak into the 5x5 filters of every pixel
        near a micro-image's rim. Each dark pixel takes the mean of its valid (or
        already filled) same-colour neighbours two pixels away along a row or
        column, repeated ``fill_steps`` times; what is still unreached keeps its raw value.
        """
        mosaic = np.asarray(mosaic, np.float32)
        valid = self.valid()
        image = np.where(valid, mosaic / np.where(valid, self.response, 1), mosaic).astype(np.float64)
        known = valid.copy()
        H, W = image.shape
        for _ in range(fill_steps):
            if known.all():
                break
            values = np.pad(np.where(known, image, 0.0), 2)
            counts = np.pad(known.astype(np.float64), 2)
            total = np.zeros((H, W))
            count = np.zeros((H, W))
            for dr, dc in ((2, 0), (-2, 0), (0, 2), (0, -2)):
                total += values[2 + dr:2 + dr + H, 2 + dc:2 + dc + W]
                count += counts[2 + dr:2 + dr + H, 2 + dc:2 + dc + W]
            reached = ~known & (count > 0)
            image[reached] = total[reached] / count[reached]
            known |= reached
        return image.astype(np.float32)

    # --- the resampling map (malvar, the ADMM start) -------------------------------
    def resample_matrix(self, chunk_lenses: int = 512) -> scipy.sparse.csr_matrix:
        """M: ``[S*U*T*V, H*W]`` CSR (float64) from one full-colour sensor plane to one regular plane.

        Row order is the planes layout (``(s*U + u) * T*V + t*V + v``). See the
        module docstring for which pixels a sample may use.
        """
        H, W = self.sensor_shape
        S, T = self.lenses
        U, V = self.views
        lens = self._pixel_lenses().ravel()
        usable = self.valid().ravel() & (lens >= 0)
        r, c = self.sample_positions()  # [S, T, U, V]
        own = (np.arange(S)[:, None] * T + np.arange(T)[None, :])[:, :, None, None]
        r0, c0 = np.floor(r).astype(np.int64), np.floor(c).astype(np.int64)
        fr, fc = r - r0, c - c0
        pix, wts = [], []
        for dr, wr in ((0, 1 - fr), (1, fr)):
            for dc, wc in ((0, 1 - fc), (1, fc)):
                rr, cc = r0 + dr, c0 + dc
                on = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
                index = np.where(on, rr * W + cc, 0)
                ok = on & usable[index] & (lens[index] == own)
                pix.append(index)
                wts.append(np.where(ok, wr * wc, 0.0))
        pix = np.stack(pix, -1).reshape(S * T, U * V, 4)
        wts = np.stack(wts, -1).reshape(S * T, U * V, 4)
        total = wts.sum(-1)
        wts = np.divide(wts, total[..., None], out=np.zeros_like(wts), where=total[..., None] > 0)
        source = _nearest_with_taps(total > 0, self._view_distances(), chunk_lenses)  # [S*T, UV]
        pix = np.take_along_axis(pix, source[..., None], axis=1)
        wts = np.take_along_axis(wts, source[..., None], axis=1)
        # lens-major [S, T, U, V] -> planes order [S, U, T, V]
        pix = pix.reshape(S, T, U, V, 4).transpose(0, 2, 1, 3, 4).reshape(-1, 4)
        wts = wts.reshape(S, T, U, V, 4).transpose(0, 2, 1, 3, 4).reshape(-1, 4)
        return _csr_from_taps(pix, wts, (self.samples, H * W))

    def _view_distances(self) -> np.ndarray:
        """Sensor distance between any two of a lens's U*V samples, [UV, UV]."""
        U, V = self.views
        eu, ev = self.steps
        du, dv = np.meshgrid(np.arange(U, dtype=np.float64), np.arange(V, dtype=np.float64), indexing="ij")
        pr = (du * eu[0] + dv * ev[0]).ravel()
        pc = (du * eu[1] + dv * ev[1]).ravel()
        return np.hypot(pr[:, None] - pr[None, :], pc[:, None] - pc[None, :])

    def as_meta(self) -> dict:
        eu, ev = self.steps
        return {
            "grid": self.grid.as_dict(),
            "lens_origin": list(self.lens_origin),
            "lenses": list(self.lenses),
            "views": list(self.views),
            "view_step_u": eu.tolist(),
            "view_step_v": ev.tolist(),
            "threshold": self.threshold,
            "sample_position": "centre(i0 + s, j0 + t) + (u - (U-1)/2) * view_step_u + (v - (V-1)/2) * view_step_v",
        }


def _bilinear_index(coordinate, n: int):
    """Lower tap and fraction of a position clamped to ``[0, n - 1]`` (n >= 2)."""
    clamped = np.clip(coordinate, 0.0, n - 1.0)
    lower = np.minimum(np.floor(clamped).astype(np.int64), n - 2)
    return lower, clamped - lower


def _csr_from_taps(columns: np.ndarray, weights: np.ndarray, shape) -> scipy.sparse.csr_matrix:
    """A CSR matrix whose row k holds ``weights[k]`` at ``columns[k]`` (zero weights dropped)."""
    rows = np.broadcast_to(np.arange(columns.shape[0])[:, None], columns.shape)
    keep = weights != 0
    matrix = scipy.sparse.csr_matrix((weights[keep], (rows[keep], columns[keep])), shape=shape)
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


def _nearest_with_taps(has_taps: np.ndarray, distances: np.ndarray, chunk: int) -> np.ndarray:
    """For every sample of every lens [L, UV], the nearest sample of the same lens with taps (itself if it has)."""
    L, n = has_taps.shape
    source = np.broadcast_to(np.arange(n), (L, n)).copy()
    for l0 in range(0, L, chunk):
        block = has_taps[l0:l0 + chunk]
        masked = np.where(block[:, None, :], distances[None], np.inf)  # [l, to, from]
        nearest = masked.argmin(axis=2)
        source[l0:l0 + chunk] = np.where(block, source[l0:l0 + chunk], nearest)
    return source


def _core_normalised(weight: np.ndarray, grid) -> np.ndarray:
    """``weight`` divided by its median over the micro-image cores (within CORE x pitch of a lens centre).

    A calibration's weight is 1 at its *best-lit* pixels, a maximum that noise and
    the coarse global map bias upwards (about 4 % on the simulator's whites), so
    the lit cores come out near 0.96 and a flat field by it would brighten the whole
    light field. Flat-fielding must leave the core of a micro-image as it is.
    """
    H, W = weight.shape
    rows, cols = np.meshgrid(np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64), indexing="ij")
    _, _, dr, dc = grid.nearest(rows, cols)
    core = np.hypot(dr, dc) <= CORE * grid.pitch
    level = float(np.median(weight[core])) if core.any() else 0.0
    if not level > 0:
        raise ValueError("the calibration's weight model is zero at the lens centres: recalibrate")
    return (weight / level).astype(np.float32)


def sampling_model(source, pattern: str | None = None, *, views=None, threshold: float | None = None,
                   lenses=None, response: np.ndarray | None = None) -> SamplingModel:
    """The :class:`SamplingModel` of a calibration or a simulated grid geometry.

    ``source``: a :class:`lfcl.grid.Calibration` (its grid, sensor, pattern and
    weight model: response = ``weight_map()``, threshold = its ``valid_threshold``)
    or a :class:`lfcl.sim.geometry.GridGeometry` (response = its noise-free
    micro-image disc, threshold 0.2). A calibration's weights are rescaled so that
    the micro-image cores have median 1 (:func:`_core_normalised`). ``views``: ``(U, V)`` or an int, default
    ``round(pitch)``. ``lenses``: ``(i0, j0, S, T)`` to force the lens block (else
    the largest block on the sensor). ``response`` [H, W] overrides the source's.
    """
    from . import Calibration

    if isinstance(source, Calibration):
        grid, shape = source.grid, source.sensor_shape
        if pattern is None:
            pattern = source.pattern
        source.check(shape, pattern, "the raw")
        if response is None and source.weight is not None:
            response = _core_normalised(source.weight_map(), grid)
        if threshold is None:
            threshold = source.weight.valid_threshold if source.weight is not None else 0.0
    elif hasattr(source, "lens_grid") and hasattr(source, "white_expected"):
        grid, shape = source.lens_grid(), source.sensor_shape
        if response is None:
            response = source.white_expected(None, 1.0)
    else:
        raise ValueError(f"expected a Calibration or a GridGeometry, got {type(source).__name__}")
    if pattern is None:
        raise ValueError("the Bayer pattern is unknown: give it (the calibration does not record one)")
    pattern = parse_pattern(pattern)
    threshold = DEFAULT_THRESHOLD if threshold is None else float(threshold)
    if not (0 <= threshold < 1):
        raise ValueError(f"the weight threshold must be in [0, 1), got {threshold!r}")
    H, W = (int(n) for n in shape)
    if response is None:
        response = np.ones((H, W), np.float32)
    response = np.asarray(response, np.float32)
    if response.shape != (H, W) or not np.all(np.isfinite(response)) or response.min() < 0:
        raise ValueError(f"the response must be a finite, non-negative {H}x{W} array, got shape {response.shape}")
    if views is None:
        views = max(2, round(grid.pitch))
    views = (int(views), int(views)) if np.isscalar(views) else tuple(int(n) for n in views)
    if len(views) != 2 or min(views) < 2:
        raise ValueError(f"views must be at least 2x2, got {views!r}")
    if lenses is None:
        i_values, j_values, complete = _complete_lenses(grid, (H, W), views)
        i0, j0, S, T = _largest_block(i_values, j_values, complete, even_start=grid.packing == "hex")
        if S < 1 or T < 1:
            raise ValueError(f"no whole lens of pitch {grid.pitch:.3f} px fits on the {H}x{W} sensor")
    else:
        i0, j0, S, T = (int(n) for n in lenses)
        if S < 1 or T < 1:
            raise ValueError(f"the lens block must hold at least one lens, got {S}x{T}")
        if grid.packing == "hex" and i0 % 2:
            raise ValueError(f"a hexagonal grid's lens block must start at an even lens row, got {i0}")
    return SamplingModel(grid, (H, W), pattern, views, (i0, j0), (S, T), response, threshold)
