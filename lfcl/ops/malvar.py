"""Malvar-He-Cutler linear demosaicing of a Bayer mosaic.

H. S. Malvar, L. He, R. Cutler, "High-quality linear interpolation for
demosaicing of Bayer-patterned color images", Proc. IEEE ICASSP 2004, vol. 3,
pp. 485-488. Each missing colour is a 5x5 linear filter of the mosaic (a bilinear
estimate plus a gain times the Laplacian of the colour measured at the pixel);
the four filter kinds are G at R/B, R/B at G with the sought colour left/right,
R/B at G with it above/below, and R at B / B at R. Measured samples are kept
as they are and nothing is clipped.

The formulas are those of colour-demosaicing's ``demosaicing_CFA_Bayer_Malvar2004``;
the border differs: the mosaic is extended by *mirror* reflection about the edge
sample without repeating it (index -1 -> 1, -2 -> 2, n -> n-2, n+1 -> n-3: numpy
``np.pad(mode="reflect")``, scipy.ndimage ``mode="mirror"``). The extension is
periodic with period 2(n-1), so every extended sample keeps its true CFA colour;
colour-demosaicing's scipy ``mode="reflect"`` repeats the edge sample and breaks
the CFA parity at the border. Tiny images: along an axis of 2 pixels the fold
repeats (-2 -> 0, 3 -> 1); along an axis of 1 pixel every index maps to 0 (the
filters are then applied to that constant extension as they are). The numpy twin
:func:`malvar_np` and the kernel ``lfcl/kernels/malvar.cl`` follow the same rule.

``lens=(U, V)`` bounds the filters to each lens of an aligned lens grid: the same mirror
about the lens's edge samples, so that no filter reads a neighbouring micro-image (the
lens-bounded Malvar, an ADMM start: lfcl.demosaic.methods ``start="lens-malvar"``, docs/auto.md).

Layouts: the mosaic is ``[H, W]``; the device class returns planes ``[3, H, W]``
(docs/layout.md); the public :func:`malvar` returns ``(H, W, 3)``.

Example::

    >>> import numpy as np
    >>> from lfcl.ops.malvar import malvar_np
    >>> planes = malvar_np(np.full((4, 6), 0.5, np.float32), "GRBG")
    >>> planes.shape, planes.dtype
    ((3, 4, 6), dtype('float32'))
    >>> bool(np.allclose(planes, 0.5))  # a flat grey mosaic stays flat grey
    True
"""

from __future__ import annotations

import itertools

import numpy as np

from ..layout import packed_pattern, parse_pattern, pattern_channels
from . import check_device_array, output


def mirror_index(index, n: int):
    """Mirror (numpy ``'reflect'``) extension: index into ``[0, n)``, period ``2(n-1)``."""
    index = np.asarray(index)
    if n <= 1:
        return np.zeros_like(index)
    period = 2 * (n - 1)
    m = np.mod(index, period)
    return np.where(m < n, m, period - m)


def _check_mosaic(mosaic: np.ndarray, name: str = "mosaic"):
    if mosaic.ndim != 2:
        raise ValueError(f"{name} must have shape [H, W], got {mosaic.shape}")


def _neighbour_index(n: int, offset: int, span: int | None) -> np.ndarray:
    """Index of each pixel's neighbour ``offset`` away along an axis of ``n``, mirrored at the
    axis's ends (span None) or at the ends of each run of ``span`` pixels (a lens)."""
    index = np.arange(n)
    if span is None:
        return mirror_index(index + offset, n)
    local = index % span
    return index - local + mirror_index(local + offset, span)


def malvar_np(mosaic: np.ndarray, pattern: str, origin=(0, 0), lens=None) -> np.ndarray:
    """Malvar-He-Cutler demosaic: ``[H, W]`` mosaic -> ``[3, H, W]`` float32 planes.

    Computed in float64 with the mirror border of the module docstring; ``lens=(U, V)``:
    mirrored at every lens's border instead (H and W whole lenses).
    """
    mosaic = np.asarray(mosaic)
    _check_mosaic(mosaic)
    pattern = parse_pattern(pattern)
    H, W = mosaic.shape
    spans = (None, None) if lens is None else _lens_spans(lens, (H, W))
    values = mosaic.astype(np.float64)

    def at(dr, dc):
        return values[np.ix_(_neighbour_index(H, dr, spans[0]), _neighbour_index(W, dc, spans[1]))]

    C = at(0, 0)
    N1, S1, W1, E1 = at(-1, 0), at(1, 0), at(0, -1), at(0, 1)
    N2, S2, W2, E2 = at(-2, 0), at(2, 0), at(0, -2), at(0, 2)
    D = at(-1, -1) + at(-1, 1) + at(1, -1) + at(1, 1)

    # The four filter kinds of the paper (coefficients / 8).
    g_at_rb = (4 * C + 2 * (N1 + S1 + W1 + E1) - (N2 + S2 + W2 + E2)) / 8
    rb_at_g_horizontal = (5 * C + 4 * (W1 + E1) - (W2 + E2) - D + 0.5 * (N2 + S2)) / 8
    rb_at_g_vertical = (5 * C + 4 * (N1 + S1) - (N2 + S2) - D + 0.5 * (W2 + E2)) / 8
    rb_at_br = (6 * C + 2 * D - 1.5 * (N2 + S2 + W2 + E2)) / 8

    # Colours by sensor parity: own colour, and the colour to the right.
    cells = pattern_channels(pattern, origin)
    rows = (np.arange(H) % 2)[:, None]
    cols = (np.arange(W) % 2)[None, :]
    own = cells[rows, cols]
    right = cells[rows, (cols + 1) % 2]
    green_site = own == 1
    r_row = green_site & (right == 0)  # G pixel with R left/right (R row, B column)

    red = np.where(own == 0, C, np.where(own == 2, rb_at_br, np.where(r_row, rb_at_g_horizontal, rb_at_g_vertical)))
    green = np.where(green_site, C, g_at_rb)
    blue = np.where(own == 2, C, np.where(own == 0, rb_at_br, np.where(r_row, rb_at_g_vertical, rb_at_g_horizontal)))
    return np.stack([red, green, blue]).astype(np.float32)


def _lens_spans(lens, shape) -> tuple[int, int]:
    U, V = (int(p) for p in lens)
    if U < 1 or V < 1 or shape[0] % U or shape[1] % V:
        raise ValueError(f"a lens-bounded Malvar needs whole lenses: {shape[0]}x{shape[1]} pixels, lenses {U}x{V}")
    return U, V


class Malvar:
    """Malvar-He-Cutler demosaicing on the device for an ``(H, W)`` sensor (``lens``: bounded to
    each lens of an aligned grid, module docstring)."""

    def __init__(self, runtime, sensor_shape, pattern: str, origin=(0, 0), lens=None):
        self.runtime = runtime
        self.height, self.width = (int(n) for n in sensor_shape)
        if self.height < 1 or self.width < 1:
            raise ValueError(f"sensor shape must be positive, got {tuple(sensor_shape)}")
        self.lens = (0, 0) if lens is None else _lens_spans(lens, (self.height, self.width))
        self.pattern = packed_pattern(pattern, origin)
        self.mosaic_shape = (self.height, self.width)
        self.planes_shape = (3, self.height, self.width)
        self.image_shape = (self.height, self.width, 3)

    def _args(self, mosaic_data, out_data):
        return (mosaic_data, out_data, np.int32(self.height), np.int32(self.width), self.pattern,
                np.int32(self.lens[0]), np.int32(self.lens[1]))

    def forward(self, mosaic, out=None):
        """``[H, W]`` float32 mosaic -> ``[3, H, W]`` float32 planes (into ``out`` if given)."""
        check_device_array(mosaic, self.mosaic_shape, "mosaic")
        out = output(self.runtime, out, self.planes_shape)
        self.runtime.launch("malvar", "malvar", (self.width, self.height), *self._args(mosaic.data, out.data))
        return out

    def image_rows(self, queue, mosaic_buffer, image_buffer, rows: tuple[int, int], wait_for=None):
        """Enqueue the rows ``[r0, r1)`` of the ``(H, W, 3)`` image on ``queue`` (device buffers of the whole
        mosaic and image; the filters read rows r0 - 2 .. r1 + 1, which must be on the device)."""
        r0, r1 = rows
        kernel = self.runtime.kernel("malvar", "malvar", defines=(("INTERLEAVED", 1),))
        return kernel(queue, (self.width, r1 - r0), None, *self._args(mosaic_buffer, image_buffer),
                      global_offset=(0, r0), wait_for=wait_for)


#: Rows per band of the streamed public call on a GPU: upload, filters and download of successive bands
#: overlap (BENCHMARKS.md, "lfcl bench api" on a GPU).
STREAM_ROWS = 512


def row_bands(height: int, rows: int) -> list[tuple[int, int]]:
    """``[r0, r1)`` bands of ``rows`` rows covering ``height`` (the last takes up to ``rows + 1``), none shorter
    than 2 rows unless the image is (the filters' reach), so that a band's halo lies in its two neighbours."""
    if rows < 2:
        raise ValueError(f"bands need at least 2 rows, got {rows}")
    edges = list(range(0, height, rows)) + [height]
    if len(edges) > 2 and edges[-1] - edges[-2] < 2:
        edges.pop(-2)
    return list(itertools.pairwise(edges))


def malvar_planes(runtime, mosaic: np.ndarray, pattern: str, origin=(0, 0)) -> np.ndarray:
    """Malvar of a host float32 ``[H, W]`` mosaic -> host ``[3, H, W]`` planes (the ``malvar`` method of
    lfcl.demosaic.methods), through :meth:`lfcl.device.Runtime.through_device` (no copies on a CPU device)."""
    array = np.ascontiguousarray(mosaic, dtype=np.float32)
    op = Malvar(runtime, array.shape, pattern, origin)
    return runtime.through_device(array, op.planes_shape, lambda queue, source, target: runtime.kernel(
        "malvar", "malvar")(queue, (op.width, op.height), None, *op._args(source, target)))


def _image_streamed(op: Malvar, array: np.ndarray, rows: int = STREAM_ROWS) -> np.ndarray:
    """A device with its own memory: bands of rows go up on one queue, through the filters on a second and
    down on a third, so the transfers of one band overlap the others' (each band's filters wait for its own
    and its neighbours' uploads: the 2-row halo)."""
    import pyopencl as cl

    runtime = op.runtime
    upload, compute, download = runtime.side_queues(3)
    image = np.empty(op.image_shape, np.float32)
    source = cl.Buffer(runtime.context, cl.mem_flags.READ_ONLY, array.nbytes)
    target = cl.Buffer(runtime.context, cl.mem_flags.WRITE_ONLY, image.nbytes)
    bands = row_bands(op.height, rows)
    row_bytes = array.strides[0]
    sent = [cl.enqueue_copy(upload, source, array[r0:r1], dst_offset=r0 * row_bytes, is_blocking=False)
            for r0, r1 in bands]
    done = []
    for k, band in enumerate(bands):
        filtered = op.image_rows(compute, source, target, band,
                                 wait_for=sent[max(k - 1, 0):k + 2])
        r0, r1 = band
        done.append(cl.enqueue_copy(download, image[r0:r1], target, src_offset=r0 * image.strides[0],
                                    is_blocking=False, wait_for=[filtered]))
    cl.wait_for_events(done)
    return image


def _validate_mosaic(mosaic) -> np.ndarray:
    """A float32 ``[H, W]`` copy of a real, finite, non-empty ``[H, W]`` or ``(H, W, 1)`` array."""
    array = np.asarray(mosaic)
    if array.dtype == np.bool_ or not (
        np.issubdtype(array.dtype, np.integer) or np.issubdtype(array.dtype, np.floating)
    ):
        raise ValueError(f"mosaic must have a real numeric dtype, got {array.dtype}")
    if array.ndim == 3 and array.shape[2] == 1:
        array = array[:, :, 0]
    if array.ndim != 2:
        raise ValueError(f"mosaic must have shape (H, W) or (H, W, 1), got {array.shape}")
    if array.size == 0:
        raise ValueError(f"mosaic must not be empty, got shape {array.shape}")
    with np.errstate(over="ignore"):  # out-of-range values become inf, rejected below
        array = np.ascontiguousarray(array, dtype=np.float32)
    if not np.all(np.isfinite(array)):
        raise ValueError("mosaic must be finite (it holds NaN or infinity, possibly after conversion to float32)")
    return array


def malvar(mosaic, pattern: str, origin=(0, 0), device=None) -> np.ndarray:
    """Demosaic a Bayer ``mosaic`` on an OpenCL device: ``(H, W)`` -> ``(H, W, 3)`` float32 RGB.

    ``mosaic`` is a 2D (or ``(H, W, 1)``) real array, converted to float32 without
    scaling. ``pattern`` is one of RGGB, GRBG, GBRG, BGGR (colours of pixels (0, 0),
    (0, 1), (1, 0), (1, 1)); ``origin`` is the sensor (row, col) of the first pixel.
    ``device`` selects the device as in :func:`lfcl.device.get_runtime`.
    """
    import pyopencl as cl

    from ..device import get_runtime

    pattern = parse_pattern(pattern)
    array = _validate_mosaic(mosaic)
    runtime = get_runtime(device)
    op = Malvar(runtime, array.shape, pattern, origin)
    # The kernel writes the (H, W, 3) image itself: no transpose on the host.
    if runtime.device.type & cl.device_type.CPU:
        return runtime.through_device(array, op.image_shape,
                                      lambda queue, source, target: op.image_rows(queue, source, target, (0, op.height)))
    return _image_streamed(op, array)
