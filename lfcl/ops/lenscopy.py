"""Copy whole lenses from one lens grid to another (gather and scatter of lens sets).

Arrays are stacks of sensor-shaped planes, ``[..., S*U, T*V]`` (docs/layout.md): the
colour planes, the gradient blocks ``[k, C, H, W]`` or a mosaic ``[H, W]``. A pair
``(i, j)`` copies lens ``i = s * T + t`` of the source to lens ``j`` of the destination,
in every plane; a pair ``(-1, j)`` sets lens ``j`` to zero; lenses no pair names keep their
values. lfcl/demosaic/methods.py uses it to pack the lenses that are not flat into a smaller solver and to put them back (lfcl/demosaic/flat_lenses.py), where
``fill_lenses`` gives the flat ones their colour means.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.lenscopy import copy_lenses_np
    >>> src = np.arange(2 * 4, dtype=np.float32).reshape(2, 4)  # 1x2 lenses of 2x2 pixels
    >>> copy_lenses_np(src, np.zeros((2, 2), np.float32), [(1, 0)], (2, 2))
    array([[2., 3.],
           [6., 7.]], dtype=float32)
"""

from __future__ import annotations

import numpy as np

from ..device import grid_defines
from . import check_device_array


def lens_pairs(pairs) -> np.ndarray:
    """``pairs`` as an int32 [n, 2] array (source lens or -1 for zeros, destination lens)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs[:, 0].min() < -1 or pairs[:, 1].min() < 0):
        raise ValueError("lens indices must be >= 0 (a source of -1: zeros)")
    return pairs.astype(np.int32)


def _lens_view(array: np.ndarray, pitch) -> np.ndarray:
    """``[..., S*U, T*V]`` as ``[P, S, U, T, V]`` (a view when ``array`` is contiguous)."""
    U, V = pitch
    H, W = array.shape[-2:]
    if H % U or W % V:
        raise ValueError(f"planes {H}x{W} are not a whole number of {U}x{V} lenses")
    return array.reshape(-1, H // U, U, W // V, V)


def copy_lenses_np(src: np.ndarray, dst: np.ndarray, pairs, pitch) -> np.ndarray:
    """A copy of ``dst`` with lens ``j`` of every plane replaced by lens ``i`` of ``src`` (zeros for
    ``i = -1``), (i, j) in ``pairs``."""
    pairs = lens_pairs(pairs)
    source, out = _lens_view(np.asarray(src), pitch), np.array(dst, copy=True)
    target = _lens_view(out, pitch)
    if source.shape[0] != target.shape[0]:
        raise ValueError(f"src and dst must hold as many planes: {source.shape[0]} and {target.shape[0]}")
    for name, grid, column in (("source", source, 0), ("destination", target, 1)):
        if pairs.size and pairs[:, column].max() >= grid.shape[1] * grid.shape[3]:
            raise ValueError(f"a {name} lens index is past the {grid.shape[1]}x{grid.shape[3]} lenses")
    lenses_s, lenses_t = source.shape[3], target.shape[3]
    for i, j in pairs:
        target[:, j // lenses_t, :, j % lenses_t] = 0 if i < 0 else source[:, i // lenses_s, :, i % lenses_s]
    return out


def fill_lenses_np(dst: np.ndarray, lenses, values, pitch) -> np.ndarray:
    """``dst`` [P, S*U, T*V] (in place) with every pixel of lens ``lenses[k]`` (index s * T + t) of
    plane p set to ``values[k, p]``; returns dst."""
    lenses = np.asarray(lenses, np.int64).reshape(-1)
    values = np.asarray(values, dst.dtype).reshape(len(lenses), -1)
    grid = _lens_view(dst, pitch)
    if values.shape[1] != grid.shape[0]:
        raise ValueError(f"values hold {values.shape[1]} planes, dst {grid.shape[0]}")
    if lenses.size and not 0 <= lenses.min() <= lenses.max() < grid.shape[1] * grid.shape[3]:
        raise ValueError(f"a lens index is outside the {grid.shape[1]}x{grid.shape[3]} lenses")
    s, t = np.divmod(lenses, grid.shape[3])
    grid[:, s, :, t, :] = values[:, :, None, None]  # [n, P, U, V]
    return dst


class LensCopy:
    """copy_lenses_np and fill_lenses_np on the device (lfcl/kernels/lenscopy.cl), for lenses of one pitch."""

    def __init__(self, runtime, pitch):
        self.runtime = runtime
        self.U, self.V = (int(p) for p in pitch)

    def upload(self, pairs):
        """The pairs as a device table, to reuse for several arrays (``None`` for no pair)."""
        pairs = lens_pairs(pairs)
        return self.runtime.to_device(pairs) if pairs.size else None

    def __call__(self, src, dst, pairs):
        """Copy lens i of ``src`` to lens j of ``dst`` for every (i, j) in ``pairs`` (a list or an
        :meth:`upload` table; the caller keeps indices inside both grids). Returns ``dst``."""
        if pairs is None:
            return dst
        table = self.upload(pairs) if isinstance(pairs, (list, tuple, np.ndarray)) else pairs
        if table is None:
            return dst
        (planes, src_rows, src_lenses), (dst_planes, dst_rows, dst_lenses) = (self._grid(src, "src"),
                                                                              self._grid(dst, "dst"))
        if planes != dst_planes:
            raise ValueError(f"src and dst must hold as many planes: {planes} and {dst_planes}")
        count = table.shape[0]
        self.runtime.launch(
            "lenscopy", "copy_lenses", (count, planes), src.data, np.int32(src_lenses), np.int32(src_rows),
            dst.data, np.int32(dst_lenses), np.int32(dst_rows), table.data, np.int32(count),
            defines=grid_defines((self.U, self.V), 0),
        )
        return dst

    def fill(self, dst, lenses, values):
        """Set lens ``lenses[k]`` of every plane p of ``dst`` to ``values[k, p]`` (host arrays). Returns dst."""
        planes, rows, lens_count = self._grid(dst, "dst")
        lenses = np.asarray(lenses, np.int32).reshape(-1)
        values = np.ascontiguousarray(np.asarray(values, np.float32).reshape(len(lenses), -1))
        if values.shape[1] != planes:
            raise ValueError(f"values hold {values.shape[1]} planes, dst {planes}")
        if not lenses.size:
            return dst
        if not 0 <= lenses.min() <= lenses.max() < rows * lens_count:
            raise ValueError(f"a lens index is outside the {rows}x{lens_count} lenses")
        self.runtime.launch(
            "lenscopy", "fill_lenses", (lenses.size, planes), dst.data, np.int32(lens_count), np.int32(rows),
            self.runtime.to_device(lenses).data, self.runtime.to_device(values).data, np.int32(lenses.size),
            defines=grid_defines((self.U, self.V), 0),
        )
        return dst

    def _grid(self, array, name: str) -> tuple[int, int, int]:
        """(planes, lens rows, lenses per row) of a device array of this pitch's lenses."""
        H, W = array.shape[-2:]
        check_device_array(array, array.shape, name)
        if H % self.U or W % self.V:
            raise ValueError(f"{name}: planes {H}x{W} are not a whole number of {self.U}x{self.V} lenses")
        return array.size // (H * W), H // self.U, W // self.V
