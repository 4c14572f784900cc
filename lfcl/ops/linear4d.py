"""A learned 4D linear demosaic: Malvar-He-Cutler's idea extended to light fields.

Malvar, He and Cutler (ICASSP 2004) estimate every colour at a Bayer pixel with a
fixed 5x5 linear filter chosen by the pixel's CFA phase. Here each output colour at
each pixel of a lenslet mosaic is a linear combination of *taps*: mosaic samples at
4D offsets ``(ds, dt, du, dv)`` from the pixel ``(s, t, u, v)`` (docs/layout.md,
row = s*U + u, col = t*V + v). In-lens taps (``ds = dt = 0``) see nearby directions
of the same lens; cross-lens taps see the same or a nearby ``(u, v)`` under a
neighbouring lens. With an odd pitch (9) the neighbouring lens's pixel at the same
``(u, v)`` has the opposite Bayer parity, so it measured another colour. The
coefficients were fitted by least squares on simulated ground truth
(``python research/fit_linear4d.py``, docs/linear4d.md) and depend on

* the pixel's position ``(u, v)`` under its lens, and
* its CFA class (:data:`CLASSES`: R; G with R left and right; G with B left and
  right; B), so one coefficient set serves all four Bayer patterns and any crop
  origin, like Malvar's four filter kinds.

Borders (:func:`tap_samples`):

* **Lens border**: a tap whose ``(u + du, v + dv)`` falls outside ``[0, U) x [0, V)``
  is *dropped* (reads 0 and its coefficient is 0): no tap ever mixes a pixel of
  another lens into a lens's ``(u, v)`` neighbourhood. Because the coefficients are
  fitted per ``(u, v)``, a rim pixel gets its own filter over the taps it has.
* **Image border**: a cross-lens tap whose lens ``s + ds`` lies outside the
  image reads the lens on the other side, ``s - ds`` (the same for ``t``); a shift of
  ``2 ds`` lenses moves an even number of rows (columns), so the sample keeps its
  CFA colour. If that lens is outside too (one lens row or column), the tap reads 0.

The numpy twin :func:`linear4d_np` and the kernel ``lfcl/kernels/linear4d.cl`` follow
the same rules. Coefficients are selected by the noise level (:func:`select_coefficients`).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import math
from pathlib import Path

import numpy as np

from ..layout import packed_pattern, parse_pattern, pattern_channels
from . import check_device_array, output

CLASSES = ("R", "G in an R row", "G in a B row", "B")
LANES = 16  # pixels per work-item of the kernel (one float16)
MODEL_FILE = "linear4d.npz"


def cfa_classes(pattern: str, origin=(0, 0)) -> np.ndarray:
    """2x2 class indices (:data:`CLASSES`) for array rows/cols 0 and 1 of a crop at ``origin``."""
    cells = pattern_channels(pattern, origin)
    right = np.roll(cells, -1, axis=1)  # the colour of the pixel to the right
    return np.where(cells == 0, 0, np.where(cells == 2, 3, np.where(right == 0, 1, 2))).astype(np.int64)


def check_taps(taps, pitch) -> np.ndarray:
    """Taps as int64 ``[NT, 4]`` rows ``(ds, dt, du, dv)``; cross-lens offsets within one lens."""
    U, V = (int(p) for p in pitch)
    taps = np.asarray(taps)
    if taps.ndim != 2 or taps.shape[1] != 4 or taps.shape[0] < 1 or not np.issubdtype(taps.dtype, np.integer):
        raise ValueError(f"taps must be an integer array [NT, 4] of (ds, dt, du, dv), got {taps.dtype} {taps.shape}")
    taps = taps.astype(np.int64)
    if np.abs(taps[:, :2]).max() > 1:
        raise ValueError("cross-lens tap offsets ds, dt must lie in -1..1")
    if np.abs(taps[:, 2]).max() >= U or np.abs(taps[:, 3]).max() >= V:
        raise ValueError(f"in-lens tap offsets du, dv must be smaller than the pitch {U}x{V}")
    if len({tuple(t) for t in taps.tolist()}) != len(taps):
        raise ValueError("taps must not repeat")
    return taps


def valid_taps(pitch, taps) -> np.ndarray:
    """``[U, V, NT]`` bool: tap k of a pixel at ``(u, v)`` stays inside the lens."""
    U, V = (int(p) for p in pitch)
    taps = check_taps(taps, pitch)
    uu = np.arange(U)[:, None, None] + taps[None, None, :, 2]
    vv = np.arange(V)[None, :, None] + taps[None, None, :, 3]
    return (uu >= 0) & (uu < U) & (vv >= 0) & (vv < V)


def _lens_index(n: int, d: int):
    """Lens index ``i + d`` for ``i`` in ``[0, n)``, ``i - d`` when outside; and where it exists."""
    i = np.arange(n)
    j = i + d
    j = np.where((j < 0) | (j >= n), i - d, j)
    ok = (j >= 0) & (j < n)
    return np.where(ok, j, 0), ok


def _tap_sample(grid: np.ndarray, tap) -> np.ndarray:
    """One tap's value at every pixel of ``grid`` [S, U, T, V] (borders: module docstring)."""
    S, U, T, V = grid.shape
    ds, dt, du, dv = (int(d) for d in tap)
    s_idx, s_ok = _lens_index(S, ds)
    t_idx, t_ok = _lens_index(T, dt)
    u_idx = np.arange(U) + du
    v_idx = np.arange(V) + dv
    u_ok, v_ok = (u_idx >= 0) & (u_idx < U), (v_idx >= 0) & (v_idx < V)
    values = grid[np.ix_(s_idx, np.clip(u_idx, 0, U - 1), t_idx, np.clip(v_idx, 0, V - 1))]
    mask = s_ok[:, None, None, None] & u_ok[None, :, None, None] & t_ok[None, None, :, None] & v_ok
    return np.where(mask, values, 0.0).reshape(S * U, T * V)


def _lens_grid(mosaic: np.ndarray, pitch) -> np.ndarray:
    U, V = (int(p) for p in pitch)
    H, W = mosaic.shape
    if H % U or W % V:
        raise ValueError(f"mosaic {H}x{W} is not a whole number of {U}x{V} lenses")
    return np.asarray(mosaic, dtype=np.float64).reshape(H // U, U, W // V, V)


def tap_samples(mosaic: np.ndarray, pitch, taps) -> np.ndarray:
    """``[NT, H, W]`` float64: the value of each tap at each pixel (borders: module docstring)."""
    taps = check_taps(taps, pitch)
    grid = _lens_grid(mosaic, pitch)
    return np.stack([_tap_sample(grid, tap) for tap in taps])


def tap_colours(pitch, taps) -> np.ndarray:
    """``[4, NT]``: the CFA colour (0 R, 1 G, 2 B) tap k reads at a pixel of each class.

    Fixed by the class and the tap's sensor offset ``(du + ds*U, dv + dt*V)``, whatever
    the pattern (the image-border mirror keeps colours)."""
    U, V = (int(p) for p in pitch)
    taps = check_taps(taps, pitch)
    pattern = "RGGB"  # any pattern gives the same answer: classes are relative to it
    classes, cells = cfa_classes(pattern), pattern_channels(pattern)
    rows, cols = taps[:, 2] + taps[:, 0] * U, taps[:, 3] + taps[:, 1] * V
    out = np.empty((len(CLASSES), len(taps)), np.int64)
    for cls in range(len(CLASSES)):
        r, c = np.argwhere(classes == cls)[0]
        out[cls] = cells[(r + rows) % 2, (c + cols) % 2]
    return out


def fold_missing_lenses(coefficients, pitch, taps, lenses) -> np.ndarray:
    """Coefficients for a sensor of ``lenses = (S, T)``: with a single lens row (column) the taps
    across lens rows (columns) exist nowhere; their weight moves evenly onto the remaining
    taps of the same CFA colour at the same phase, so flat colours still come back exactly.
    Unchanged (the same array) when ``S, T >= 2``."""
    S, T = (int(n) for n in lenses)
    taps = check_taps(taps, pitch)
    missing = ((taps[:, 0] != 0) & (S < 2)) | ((taps[:, 1] != 0) & (T < 2))
    if not missing.any():
        return coefficients
    out = np.array(coefficients, dtype=np.float64) * valid_taps(pitch, taps)[:, :, None, None, :]
    remaining = valid_taps(pitch, taps) & ~missing  # [U, V, NT]
    colours = tap_colours(pitch, taps)
    for cls in range(len(CLASSES)):
        for j in range(3):
            lost = out[:, :, cls][..., missing & (colours[cls] == j)].sum(axis=-1)  # [U, V, 3]
            targets = remaining & (colours[cls] == j)  # [U, V, NT]
            count = targets.sum(axis=-1)  # [U, V]
            share = np.divide(lost, count[..., None], out=np.zeros_like(lost), where=count[..., None] > 0)
            out[:, :, cls] += share[..., None] * targets[:, :, None, :]
    out[..., missing] = 0.0
    return out.astype(np.float32)


def pixel_phases(shape, pitch, pattern: str, origin=(0, 0)):
    """Per pixel of an ``[H, W]`` mosaic: its ``u``, ``v`` and CFA class, each ``[H, W]``."""
    U, V = (int(p) for p in pitch)
    H, W = shape
    classes = cfa_classes(pattern, origin)
    rows, cols = np.arange(H)[:, None], np.arange(W)[None, :]
    u = np.broadcast_to(rows % U, (H, W))
    v = np.broadcast_to(cols % V, (H, W))
    return u, v, classes[rows % 2, cols % 2]


def check_coefficients(coefficients, pitch, n_taps: int) -> np.ndarray:
    U, V = (int(p) for p in pitch)
    coefficients = np.asarray(coefficients)
    want = (U, V, len(CLASSES), 3, n_taps)
    if coefficients.shape != want:
        raise ValueError(f"coefficients must have shape {want} [U, V, class, colour, tap], got {coefficients.shape}")
    if not np.all(np.isfinite(coefficients)):
        raise ValueError("coefficients hold NaN or Inf values")
    return coefficients


def linear4d_np(mosaic: np.ndarray, pattern: str, pitch, taps, coefficients, origin=(0, 0)) -> np.ndarray:
    """The 4D linear filter: ``[H, W]`` mosaic -> ``[3, H, W]`` float32 planes (float64 inside).

    ``coefficients[u, v, class, colour, k]`` weighs tap ``k``; a dropped tap (outside
    the lens) reads 0, so its coefficient does not matter.
    """
    mosaic = np.asarray(mosaic)
    if mosaic.ndim != 2:
        raise ValueError(f"mosaic must have shape [H, W], got {mosaic.shape}")
    pattern = parse_pattern(pattern)
    taps = check_taps(taps, pitch)
    coefficients = check_coefficients(coefficients, pitch, len(taps)).astype(np.float64)
    grid = _lens_grid(mosaic, pitch)
    coefficients = np.asarray(fold_missing_lenses(coefficients, pitch, taps, grid.shape[::2]), np.float64)
    u, v, cls = pixel_phases(mosaic.shape, pitch, pattern, origin)
    out = np.zeros((3, *mosaic.shape))
    for k, tap in enumerate(taps):  # one tap at a time: memory stays a few planes at any size
        sample = _tap_sample(grid, tap)
        for c in range(3):
            out[c] += coefficients[u, v, cls, c, k] * sample
    return out.astype(np.float32)


def row_tables(coefficients, pitch, taps, pattern: str, origin=(0, 0), lenses=(2, 2)) -> np.ndarray:
    """The kernel's coefficient layout: ``[2U, 3, NT, 2V + LANES]`` float32.

    A pixel's coefficients depend on ``row mod 2U`` and ``col mod 2V`` (u and v, and the
    lens parity that decides the Bayer parity with an odd pitch). Entry
    ``[row mod 2U, c, k, j]`` holds column phase ``j mod 2V``; the row is extended by
    ``LANES`` so that 16 neighbouring columns are one contiguous load. Dropped taps
    get coefficient 0, so the kernel may read any in-image pixel for them. ``lenses``: the
    sensor's ``(S, T)``, for :func:`fold_missing_lenses`.
    """
    U, V = (int(p) for p in pitch)
    taps = check_taps(taps, pitch)
    coefficients = fold_missing_lenses(check_coefficients(coefficients, pitch, len(taps)), pitch, taps, lenses)
    valid = valid_taps(pitch, taps)
    classes = cfa_classes(parse_pattern(pattern), origin)
    rows = np.arange(2 * U)
    cols = np.arange(2 * V + LANES) % (2 * V)
    u, v = rows[:, None] % U, cols[None, :] % V
    cls = classes[rows[:, None] % 2, cols[None, :] % 2]
    table = coefficients[u, v, cls] * valid[u, v][:, :, None, :]  # [2U, 2V+L, 3, NT]
    return np.ascontiguousarray(table.transpose(0, 2, 3, 1), dtype=np.float32)


def tap_offsets(pitch, taps) -> np.ndarray:
    """Per tap, int32 ``(row offset, mirrored row offset, col offset, mirrored col offset)``."""
    U, V = (int(p) for p in pitch)
    taps = check_taps(taps, pitch)
    ds, dt, du, dv = taps.T
    return np.ascontiguousarray(np.stack([du + ds * U, du - ds * U, dv + dt * V, dv - dt * V], axis=1), np.int32)


class Linear4d:
    """The 4D linear demosaic on the device for an ``(H, W)`` sensor of ``pitch`` lenses."""

    def __init__(self, runtime, sensor_shape, pattern: str, pitch, taps, coefficients, origin=(0, 0)):
        self.runtime = runtime
        self.height, self.width = (int(n) for n in sensor_shape)
        self.pitch = tuple(int(p) for p in pitch)
        U, V = self.pitch
        if self.height < 1 or self.width < 1 or self.height % U or self.width % V:
            raise ValueError(f"sensor {self.height}x{self.width} is not a whole number of {U}x{V} lenses")
        self.pattern = parse_pattern(pattern)
        taps = check_taps(taps, self.pitch)
        self.n_taps = len(taps)
        self.mosaic_shape = (self.height, self.width)
        self.planes_shape = (3, self.height, self.width)
        self.offsets = runtime.to_device(tap_offsets(self.pitch, taps))
        lenses = (self.height // U, self.width // V)
        self.tables = runtime.to_device(row_tables(coefficients, self.pitch, taps, self.pattern, origin, lenses))
        self.defines = (("LENS_U", U), ("LENS_V", V))  # not PITCH_*: common.cl then wants DIMS
        # On a CPU (PoCL) a work-group of one work-item keeps the kernel's float16 code one SIMD
        # register wide; PoCL's work-group vectorizer, given more, made it 2-3x slower
        # (docs/linear4d.md). Other devices choose their own work-group size.
        from pyopencl import device_type

        self.local_size = (1, 1) if runtime.device.type & device_type.CPU else None
        packed_pattern(self.pattern, origin)  # validates the origin

    def forward(self, mosaic, out=None):
        """``[H, W]`` float32 mosaic -> ``[3, H, W]`` float32 planes (into ``out`` if given)."""
        check_device_array(mosaic, self.mosaic_shape, "mosaic")
        out = output(self.runtime, out, self.planes_shape)
        groups = -(-self.width // LANES)
        self.runtime.launch(
            "linear4d", "linear4d", (groups, self.height), mosaic.data, out.data, self.tables.data,
            self.offsets.data, np.int32(self.n_taps), np.int32(self.height), np.int32(self.width),
            local_size=self.local_size, defines=self.defines,
        )
        return out


# --------------------------------------------------------------------------- shipped coefficients

@dataclasses.dataclass(frozen=True)
class Linear4dModel:
    """Fitted coefficient sets, one per training noise level (lfcl/data/linear4d.npz)."""

    pitch: tuple[int, int]
    taps: np.ndarray  # int64 [NT, 4] (ds, dt, du, dv)
    coefficients: np.ndarray  # float32 [n_sets, U, V, 4, 3, NT]
    relative_noise: np.ndarray  # float64 [n_sets], increasing: sigma / mean level of each training set
    metadata: dict

    def __post_init__(self):
        taps = check_taps(self.taps, self.pitch)
        if self.coefficients.ndim != 6 or self.coefficients.shape[0] != len(self.relative_noise):
            raise ValueError("coefficients must be [n_sets, U, V, 4, 3, NT], one set per noise level")
        for coefficients in self.coefficients:
            check_coefficients(coefficients, self.pitch, len(taps))
        noise = np.asarray(self.relative_noise, dtype=np.float64)
        if not (np.all(np.isfinite(noise)) and np.all(noise > 0) and np.all(np.diff(noise) > 0)):
            raise ValueError("the sets' relative noise levels must be positive, finite and increasing")


def save_model(path, model: Linear4dModel) -> None:
    """Write ``model`` as an .npz (metadata as JSON), atomically."""
    import json

    from ..io.images import atomic_path

    with atomic_path(path, suffix=".npz") as tmp:
        np.savez(tmp, pitch=np.asarray(model.pitch, np.int64), taps=model.taps,
                 coefficients=model.coefficients.astype(np.float32),
                 relative_noise=np.asarray(model.relative_noise, np.float64),
                 metadata=np.array(json.dumps(model.metadata, sort_keys=True)))


def load_model(path=None) -> Linear4dModel:
    """The coefficients at ``path``, by default the ones shipped in ``lfcl.data`` (read once)."""
    return _read_model(Path(path)) if path is not None else _shipped_model()


@functools.cache
def _shipped_model() -> Linear4dModel:
    model = _read_model(importlib.resources.files("lfcl.data").joinpath(MODEL_FILE))
    for array in (model.taps, model.coefficients, model.relative_noise):
        array.flags.writeable = False  # shared by every caller
    return model


def _read_model(source) -> Linear4dModel:
    import json

    with source.open("rb") as handle, np.load(handle, allow_pickle=False) as data:
        return Linear4dModel(
            pitch=tuple(int(p) for p in data["pitch"]), taps=data["taps"].astype(np.int64),
            coefficients=data["coefficients"].astype(np.float32),
            relative_noise=data["relative_noise"].astype(np.float64),
            metadata=json.loads(str(data["metadata"])),
        )


def relative_noise(sigma: float, mosaic: np.ndarray) -> float:
    """Noise relative to the signal: ``sigma`` / the mosaic's mean level (the set selector).

    A mosaic without signal (mean level <= 0) counts as infinitely noisy: the noisiest set.
    """
    level = float(np.mean(mosaic, dtype=np.float64))
    if not math.isfinite(level):
        raise ValueError("the mosaic's mean level is not finite")
    return float(sigma) / level if level > 0 else math.inf


def select_coefficients(model: Linear4dModel, noise: float) -> np.ndarray:
    """Coefficients ``[U, V, 4, 3, NT]`` for relative noise ``noise``: linear in log(noise)
    between the two nearest training levels, the end sets beyond them."""
    if math.isnan(noise) or noise < 0:
        raise ValueError(f"relative noise must be >= 0, got {noise!r}")
    levels = np.log(model.relative_noise)
    x = math.log(max(noise, 1e-12)) if math.isfinite(noise) else math.inf
    if x <= levels[0]:
        return model.coefficients[0]
    if x >= levels[-1]:
        return model.coefficients[-1]
    i = int(np.searchsorted(levels, x)) - 1
    w = (x - levels[i]) / (levels[i + 1] - levels[i])
    mixed = (1 - w) * model.coefficients[i].astype(np.float64) + w * model.coefficients[i + 1]
    return mixed.astype(np.float32)


def linear4d(runtime_or_device, mosaic, pattern: str, pitch, origin=(0, 0), noise=None, model=None) -> np.ndarray:
    """Demosaic a normalised lenslet mosaic ``[H, W]`` into ``[3, H, W]`` float32 planes.

    ``runtime_or_device``: a :class:`lfcl.device.Runtime` or a device spec for
    :func:`lfcl.device.get_runtime`. ``noise``: a :class:`lfcl.noise.model.NoiseEstimate`
    (default: estimated from the mosaic) whose ``sigma`` relative to the mosaic's
    mean level picks the coefficients. ``model`` defaults to the shipped coefficients.
    """
    from ..device import Runtime, get_runtime

    runtime = runtime_or_device if isinstance(runtime_or_device, Runtime) else get_runtime(runtime_or_device)
    mosaic = np.ascontiguousarray(mosaic, dtype=np.float32)
    op = linear4d_operator(runtime, mosaic, pattern, pitch, origin, noise, model)
    return op.forward(runtime.to_device(mosaic)).get()


def linear4d_operator(runtime, mosaic, pattern: str, pitch, origin=(0, 0), noise=None, model=None) -> Linear4d:
    """The :class:`Linear4d` for ``mosaic`` (host array): the coefficient set its noise level picks,
    after the checks of :func:`linear4d`; its ``forward`` takes and gives device arrays."""
    from ..noise.model import estimate_noise

    model = model if model is not None else load_model()
    pitch = (int(pitch), int(pitch)) if np.isscalar(pitch) else tuple(int(p) for p in pitch)  # 9 means 9x9
    if pitch != tuple(model.pitch):
        raise ValueError(f"the linear4d coefficients were fitted for {model.pitch[0]}x{model.pitch[1]} lenses, "
                         f"not {pitch[0]}x{pitch[1]}: refit with python research/fit_linear4d.py --pitch")
    mosaic = np.ascontiguousarray(mosaic, dtype=np.float32)
    if mosaic.ndim != 2:
        raise ValueError(f"mosaic must be 2D [H, W], got shape {mosaic.shape}")
    if not np.all(np.isfinite(mosaic)):
        raise ValueError("mosaic holds NaN or Inf values")
    if noise is None:
        noise = estimate_noise(mosaic, pattern, pitch, origin)
    coefficients = select_coefficients(model, relative_noise(noise.sigma, mosaic))
    return Linear4d(runtime, mosaic.shape, pattern, pitch, model.taps, coefficients, origin)
