"""Simulate one lenslet capture end to end, and write it to a folder.

:func:`simulate` renders (or loads) the light field, scales it so that the mean
illuminance (luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` of the linear
camera RGB, averaged over every sample) equals ``lux``, converts to expected
electrons with :class:`lfcl.sim.sensor.SensorModel`, CFA-samples it through
:class:`lfcl.sim.geometry.LensletGeometry`, applies the optional microlens
vignetting and exposes it with noise. A flat white field at 80 % of full well
goes through the same camera for the white image.

Ground truth (``Capture.truth``): ``[S, T, U, V, 3]`` float32, noise-free, no
vignetting, in the pipeline's normalised raw scale ``(raw - black) / (white -
black)``, i.e. expected electrons / full-well electrons, clipped at 1.0.

:func:`write_capture` writes ``raw.dng``, ``white.dng``, ``meta.json``,
``truth.npy`` and ``truth_views.exr`` (and, for a scene of planes on the aligned
grid, ``disparity.npy``: the true centre-view disparity ``[S, T]``,
:func:`lfcl.sim.scenes.planes_disparity`) into a temporary sibling folder and
moves them into place only once all were written.

:func:`simulate_white` / :func:`write_white_capture`: only ``white.dng`` and
``meta.json`` of a square or hexagonal grid of any pitch, rotation and offset
(:class:`lfcl.sim.geometry.GridGeometry`; docs/calibration.md).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import tempfile
from fractions import Fraction
from pathlib import Path

import numpy as np

from .. import __version__
from ..io.images import write_image, write_json, write_npy
from ..layout import channel_map, parse_pattern, tiled_views
from .dng import write_dng
from .geometry import GridGeometry, LensletGeometry
from .lightfield import load_lightfield
from .planes import Plane, render_planes
from .scenes import check_scene, planes_disparity, scene_planes
from .sensor import SensorModel

LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float64)  # Rec. 709 / sRGB Y weights
WHITE_FRACTION = 0.8
FILES = ("raw.dng", "white.dng", "meta.json", "truth.npy", "truth_views.exr")
DISPARITY_FILE = "disparity.npy"
WHITE_FILES = ("white.dng", "meta.json")


class _SensorLevels:
    """Black and white levels (DN) of the simulated sensor, for writing DNGs."""

    @property
    def black_level(self) -> int:
        return int(self.sensor.black_level_dn)

    @property
    def white_level(self) -> int:
        return int(self.sensor.white_level_dn)


@dataclasses.dataclass
class Capture(_SensorLevels):
    """A simulated lenslet capture: raws, ground truth and metadata."""

    raw: np.ndarray  # uint16 [H, W] CFA mosaic
    white: np.ndarray  # uint16 [H, W] white image
    truth: np.ndarray  # float32 [S, T, U, V, 3], normalised (see module docstring)
    meta: dict
    geometry: LensletGeometry
    sensor: SensorModel
    pattern: str
    disparity: np.ndarray | None = None  # float32 [S, T] true centre-view disparity (planes only), lenses/view step

    def normalised_raw(self) -> np.ndarray:
        """``(raw - black) / (white - black)`` as float32."""
        return ((self.raw.astype(np.float32) - self.black_level) / (self.white_level - self.black_level))


def parse_lenses(value) -> tuple[int, int]:
    """``"64x64"``, ``"64"``, ``64`` or ``(S, T)`` -> ``(S, T)``; ``ValueError`` for anything else."""
    if isinstance(value, str):
        parts = value.lower().replace("×", "x").split("x")
        try:
            numbers = [int(p.strip()) for p in parts]
        except ValueError:
            raise ValueError(f"malformed --lenses {value!r}: expected SxT, e.g. 64x64") from None
    elif isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        numbers = [int(value)]
    else:
        try:
            numbers = [int(n) for n in value]
        except (TypeError, ValueError):
            raise ValueError(f"malformed lenses {value!r}: expected (S, T)") from None
    if len(numbers) == 1:
        numbers = numbers * 2
    if len(numbers) != 2:
        raise ValueError(f"malformed lenses {value!r}: expected SxT, e.g. 64x64")
    if min(numbers) < 1:
        raise ValueError(f"lenses must be at least 1x1, got {numbers[0]}x{numbers[1]}")
    return numbers[0], numbers[1]


def parse_exposure(value) -> float:
    """``"1/90"``, ``"0.011"`` or a number -> seconds (> 0)."""
    try:
        seconds = float(Fraction(value.strip())) if isinstance(value, str) else float(value)
    except (ValueError, ZeroDivisionError, TypeError):
        raise ValueError(f"malformed exposure {value!r}: expected seconds, e.g. 1/90 or 0.011") from None
    if not np.isfinite(seconds) or seconds <= 0:
        raise ValueError(f"exposure must be positive, got {value!r}")
    return seconds


def _check_lux(lux) -> float:
    try:
        lux = float(lux)
    except (TypeError, ValueError):
        raise ValueError(f"lux must be a number, got {lux!r}") from None
    if not np.isfinite(lux) or lux <= 0:
        raise ValueError(f"lux must be positive, got {lux:g}")
    return lux


def _check_pitch(pitch) -> int:
    if isinstance(pitch, bool) or not isinstance(pitch, (int, np.integer)):
        raise ValueError(f"pitch must be an integer number of pixels, got {pitch!r}")
    if pitch < 2:
        raise ValueError(f"pitch must be at least 2 pixels per microlens, got {pitch}")
    return int(pitch)


def simulate(scene: str = "charts", lenses=None, pitch: int | None = None, pattern: str = "GRBG",
             lux: float = 12.0, seed: int = 0, *, exposure=None, vignetting: bool = False,
             texture=None, lightfield=None, planes: list[Plane] | None = None,
             sensor: SensorModel | None = None, supersample: int = 3, f_number: float = 2.8,
             progress: bool | None = False) -> Capture:
    """Simulate a lenslet capture; every bad argument is a one-line ``ValueError``.

    ``lenses`` (``(S, T)`` or ``"SxT"``) defaults to 64x64 and ``pitch`` to 9.
    ``lightfield`` (an HCI-layout folder or a ``.npy``, or an ``[S, T, U, V, 3]``
    array) replaces the scene and sets S, T, U, V (``lenses`` crops its centre,
    ``None`` keeps all; ``pitch``, if given, must match). ``planes`` renders custom planes instead of a
    named scene. ``exposure`` (seconds, or "1/90") overrides the sensor's.
    """
    lux = _check_lux(lux)
    pattern = parse_pattern(pattern)
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    sensor = sensor if sensor is not None else SensorModel()
    if exposure is not None:
        sensor = dataclasses.replace(sensor, exposure_s=parse_exposure(exposure))
    if texture is not None and lightfield is not None:
        raise ValueError("--texture and --lightfield exclude each other")
    lenses = parse_lenses(lenses) if lenses is not None else None

    if lightfield is not None:
        if isinstance(lightfield, np.ndarray):
            radiance = np.asarray(lightfield, dtype=np.float32)
            if radiance.ndim != 5 or radiance.shape[4] != 3:
                raise ValueError(f"a light field must have shape [S, T, U, V, 3], got {list(radiance.shape)}")
            if lenses is not None:
                S0, T0 = radiance.shape[:2]
                if lenses[0] > S0 or lenses[1] > T0:
                    raise ValueError(f"lenses {lenses[0]}x{lenses[1]} exceed the light field's {S0}x{T0}")
                s0, t0 = (S0 - lenses[0]) // 2, (T0 - lenses[1]) // 2
                radiance = radiance[s0:s0 + lenses[0], t0:t0 + lenses[1]]
            radiance = np.array(np.clip(radiance, 0, None), dtype=np.float32)
            source = {"kind": "lightfield", "path": None}
        else:
            radiance = load_lightfield(lightfield, lenses)
            source = {"kind": "lightfield", "path": str(lightfield)}
        U, V = radiance.shape[2:4]
        if pitch is not None and (int(pitch) != U or int(pitch) != V):
            raise ValueError(f"--pitch {pitch} does not match the light field's {U}x{V} views")
        geometry = LensletGeometry(radiance.shape[:2], (U, V))
        plane_meta = disparity = None
    else:
        pitch = _check_pitch(9 if pitch is None else pitch)
        lenses = lenses if lenses is not None else (64, 64)
        geometry = LensletGeometry(lenses, (pitch, pitch))
        if planes is None:
            scene = check_scene(scene)
            planes = scene_planes(scene, lenses, seed, (pitch, pitch), texture)
            source = {"kind": "scene", "name": scene, "texture": None if texture is None else str(texture)}
        else:
            source = {"kind": "planes", "name": "custom"}
        radiance = render_planes(planes, lenses, (pitch, pitch), supersample=supersample, progress=progress)
        plane_meta = [p.as_meta() for p in planes]
        disparity = planes_disparity(planes, lenses)

    luminance = radiance.reshape(-1, 3) @ LUMINANCE.astype(np.float32)
    mean_y, peak_y = float(luminance.mean(dtype=np.float64)), float(luminance.max())
    del luminance
    if not np.isfinite(mean_y) or mean_y <= 0:
        raise ValueError("the scene is black (mean luminance 0): nothing to scale to the requested lux")
    lux_per_unit = lux / mean_y
    # In place: radiance -> expected electrons / full well (unclipped).
    radiance *= np.float32(lux_per_unit * sensor.electrons_per_lux / sensor.full_well_e)
    expected = geometry.mosaic(radiance, pattern).astype(np.float64)
    truth = np.minimum(radiance, np.float32(1.0), out=radiance)
    del radiance

    vignette = geometry.vignetting_sensor(f_number) if vignetting else None
    raw_rng, white_rng = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 0x5E2502]).spawn(2))
    if vignette is not None:
        expected *= vignette
    raw = sensor.expose(expected, raw_rng)
    del expected
    flat = np.full(geometry.sensor_shape, WHITE_FRACTION, dtype=np.float64)
    if vignette is not None:
        flat *= vignette
    white = sensor.expose(flat, white_rng)
    del flat

    s_coef, o_coef = sensor.noise_profile()
    mean_normalised = float(sensor.lux_to_normalised(lux))
    meta = {
        "generator": f"lfcl {__version__} simulate",
        "scene": source,
        "planes": plane_meta,
        "lux": lux,
        "seed": seed,
        "pattern": pattern,
        "lenslet": geometry.as_meta(),
        "pitch": list(geometry.pitch),
        "lenses": list(geometry.lenses),
        "grid": geometry.grid,
        "offset": list(geometry.offset),
        **_exposure_meta(sensor, lux, lux_per_unit, mean_y, peak_y, mean_normalised, (s_coef, o_coef)),
        "vignetting": {"enabled": bool(vignetting), "model": "cos^4, microlens f-number", "f_number": f_number,
                       "uv_factors": geometry.vignetting(f_number).tolist() if vignetting else None},
        "white": {"file": "white.dng", "level_normalised": WHITE_FRACTION},
        "truth": {
            "file": "truth.npy", "shape": list(truth.shape), "dtype": "float32",
            "layout": "[S, T, U, V, 3] linear camera RGB",
            "scale": "expected electrons / full-well electrons = (raw - black) / (white - black), clipped at 1.0",
            "noise_free": True, "vignetting": False,
        },
        "truth_views": {"file": "truth_views.exr",
                        "layout": "U x V grid of S x T tiles; tile (u, v) is the view (u, v)"},
        "supersample": supersample,
        "files": list(FILES),
    }
    if disparity is not None:
        meta["disparity"] = {
            "file": DISPARITY_FILE, "shape": list(disparity.shape), "dtype": "float32",
            "layout": "[S, T] disparity of the frontmost plane at each lens centre seen from the centre of the views",
            "unit": "lenses per view step; a feature at row y of the centre view is at y - d (u - u0) in view u",
        }
        meta["files"].append(DISPARITY_FILE)
    return Capture(raw, white, truth, meta, geometry, sensor, pattern, disparity)


def _exposure_meta(sensor, lux, lux_per_unit, mean_y, peak_y, mean_normalised, profile) -> dict:
    """The sensor, exposure and noise entries of a capture's meta.json (docs/simulator.md)."""
    s_coef, o_coef = profile
    return {
        "sensor": sensor.as_meta(),
        "black_level": int(sensor.black_level_dn),
        "white_level": int(sensor.white_level_dn),
        "electrons_per_lux": sensor.electrons_per_lux,
        "exposure": {
            "lux_per_scene_unit": lux_per_unit,
            "mean_luminance_scene_units": mean_y,
            "peak_lux": peak_y * lux_per_unit,
            "mean_electrons": lux * sensor.electrons_per_lux,
            "mean_normalised": mean_normalised,
            "luminance_weights": LUMINANCE.tolist(),
        },
        "noise": {
            "profile": [[s_coef, o_coef]] * 3,
            "variance": "S * x + O in normalised units x = (raw - black) / (white - black)",
            "sigma": float(sensor.noise_sigma(mean_normalised)),
            "sigma_at_mean": float(sensor.noise_sigma(mean_normalised)),
            "sigma_at_1_lux": float(sensor.noise_sigma(sensor.lux_to_normalised(1.0))),
            "sigma_floor": float(np.sqrt(o_coef)),
        },
    }


def _write_folder(directory, files, write) -> Path:
    """Write ``files`` into ``directory`` all or nothing: ``write(tmp)`` fills a temporary
    sibling folder, whose files move into ``directory`` only when every one was written."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise ValueError(f"output {directory} exists and is not a folder")
    parent = directory.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", suffix=".tmp", dir=parent))
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes the folder private
        write(tmp)
        if not directory.exists():
            with contextlib.suppress(OSError):
                os.rename(tmp, directory)
                return directory
        directory.mkdir(exist_ok=True)
        for name in files:
            os.replace(tmp / name, directory / name)
        tmp.rmdir()
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return directory


def write_capture(capture, directory) -> Path:
    """Write a :class:`Capture` or :class:`GridCapture` into ``directory`` (created if missing, files replaced)."""

    def write(tmp: Path):
        s, o = capture.sensor.noise_profile()
        for name, mosaic in (("raw.dng", capture.raw), ("white.dng", capture.white)):
            write_dng(tmp / name, mosaic, capture.pattern, capture.black_level, capture.white_level,
                      [(s, o)] * 3)
        write_npy(tmp / "truth.npy", capture.truth)
        S, T, U, V = (int(n) for n in capture.truth.shape[:4])
        write_image(tmp / "truth_views.exr", tiled_views(capture.truth),
                    {"layout": "U x V grid of S x T views", "lenses": [S, T], "pitch": [U, V]})
        disparity = getattr(capture, "disparity", None)
        if disparity is not None:
            write_npy(tmp / DISPARITY_FILE, np.asarray(disparity, np.float32))
        write_json(tmp / "meta.json", capture.meta)

    files = FILES + ((DISPARITY_FILE,) if getattr(capture, "disparity", None) is not None else ())
    return _write_folder(directory, files, write)


# --------------------------------------------------------------------------- white images of any grid

@dataclasses.dataclass
class WhiteCapture(_SensorLevels):
    """A simulated white image of a square or hexagonal grid of any pitch, rotation and offset."""

    white: np.ndarray  # uint16 [H, W]
    meta: dict
    geometry: GridGeometry
    sensor: SensorModel
    pattern: str


def parse_offset(value) -> tuple[float, float]:
    """``"0.3,0.7"`` or ``(0.3, 0.7)`` -> ``(rows, cols)`` in pixels; ``ValueError`` for anything else."""
    if isinstance(value, str):
        parts = value.replace(";", ",").split(",")
        try:
            numbers = tuple(float(p.strip()) for p in parts)
        except ValueError:
            raise ValueError(f"malformed --offset {value!r}: expected ROW,COL in pixels, e.g. 0.3,0.7") from None
    else:
        try:
            numbers = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise ValueError(f"malformed offset {value!r}: expected (rows, cols)") from None
    if len(numbers) != 2 or not all(np.isfinite(numbers)):
        raise ValueError(f"malformed offset {value!r}: expected two finite numbers ROW,COL")
    return numbers


def simulate_white(grid: str = "square", pitch: float = 9.0, rotation_deg: float = 0.0, offset=(0.0, 0.0), *,
                   lenses=None, sensor_shape=None, pattern: str = "GRBG", seed: int = 0, level: float = WHITE_FRACTION,
                   vignetting: bool = False, f_number: float = 2.8, main_vignetting: float = 0.0,
                   colour_gains=None, fill: float = 0.9, edge_px: float = 0.45,
                   sensor: SensorModel | None = None) -> WhiteCapture:
    """A noisy white image (flat field through the camera) of a :class:`GridGeometry`.

    The sensor is ``sensor_shape`` (rows, cols) or just large enough for ``lenses``
    ``(S, T)`` lens rows and columns (default 64x64). ``level``: the response at
    a micro-image centre (normalised). See :meth:`GridGeometry.white_expected`.
    """
    pattern = parse_pattern(pattern)
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    try:
        pitch = float(pitch)
        rotation_deg = float(rotation_deg)
        level = float(level)
    except (TypeError, ValueError):
        raise ValueError("pitch, rotation and level must be numbers") from None
    if not np.isfinite(level) or not 0 < level <= 1.5:
        raise ValueError(f"the white level must be in (0, 1.5], got {level!r}")
    offset = parse_offset(offset)
    shape_kwargs = {"rotation_deg": rotation_deg, "offset": offset, "fill": fill, "edge_px": edge_px}
    if sensor_shape is not None:
        geometry = GridGeometry(tuple(sensor_shape), grid, pitch, **shape_kwargs)
    else:
        lenses = parse_lenses(lenses) if lenses is not None else (64, 64)
        geometry = GridGeometry.from_lenses(lenses, grid, pitch, **shape_kwargs)
    if geometry.sensor_shape[0] * geometry.sensor_shape[1] > 2**28:
        raise ValueError(f"a {geometry.sensor_shape[0]}x{geometry.sensor_shape[1]} sensor is too large to simulate")
    sensor = sensor if sensor is not None else SensorModel()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x3D1E]))
    expected = geometry.white_expected(pattern, level, vignetting=vignetting, f_number=f_number,
                                       main_vignetting=main_vignetting, colour_gains=colour_gains)
    white = sensor.expose(expected, rng)
    del expected
    s_coef, o_coef = sensor.noise_profile()
    meta = {
        "generator": f"lfcl {__version__} simulate",
        "mode": "white-only",
        "note": "white image only (`lfcl simulate --grid ... --white-only`); simulate_grid makes raws of any grid",
        "seed": seed,
        "pattern": pattern,
        "lenslet": geometry.as_meta(),
        "grid": geometry.grid,
        "pitch": geometry.pitch,
        "rotation_deg": geometry.rotation_deg,
        "offset": list(geometry.offset),
        "sensor_shape": list(geometry.sensor_shape),
        "sensor": sensor.as_meta(),
        "black_level": int(sensor.black_level_dn),
        "white_level": int(sensor.white_level_dn),
        "noise": {"profile": [[s_coef, o_coef]] * 3,
                  "variance": "S * x + O in normalised units x = (raw - black) / (white - black)"},
        "vignetting": {"enabled": bool(vignetting), "model": "cos^4, microlens f-number", "f_number": f_number,
                       "main_lens_corner_loss": float(main_vignetting)},
        "white": {"file": "white.dng", "level_normalised": level,
                  "colour_gains": None if colour_gains is None else [float(g) for g in colour_gains]},
        "files": list(WHITE_FILES),
    }
    return WhiteCapture(white, meta, geometry, sensor, pattern)


def write_white_capture(capture: WhiteCapture, directory) -> Path:
    """Write ``white.dng`` and ``meta.json`` into ``directory`` (created if missing, files replaced), atomically."""

    def write(tmp: Path):
        s, o = capture.sensor.noise_profile()
        write_dng(tmp / "white.dng", capture.white, capture.pattern, capture.black_level, capture.white_level,
                  [(s, o)] * 3)
        write_json(tmp / "meta.json", capture.meta)

    return _write_folder(directory, WHITE_FILES, write)


# --------------------------------------------------------------------------- raws of any grid

@dataclasses.dataclass
class GridCapture(_SensorLevels):
    """A simulated capture through a square or hexagonal grid of any pitch, rotation and offset.

    ``truth`` is on the solver's regular grid (``sampling``, lfcl/grid/resampling.py).
    """

    raw: np.ndarray  # uint16 [H, W] CFA mosaic
    white: np.ndarray  # uint16 [H, W] white image of the same camera
    truth: np.ndarray  # float32 [S, T, U, V, 3], normalised, noise-free, no vignetting
    meta: dict
    geometry: GridGeometry
    sensor: SensorModel
    pattern: str
    sampling: object  # lfcl.grid.resampling.SamplingModel of the true geometry

    def normalised_raw(self) -> np.ndarray:
        """``(raw - black) / (white - black)`` as float32."""
        return ((self.raw.astype(np.float32) - self.black_level) / (self.white_level - self.black_level))


def _grid_geometry(grid, pitch, rotation_deg, offset, lenses, sensor_shape, fill, edge_px) -> GridGeometry:
    try:
        pitch, rotation_deg = float(pitch), float(rotation_deg)
    except (TypeError, ValueError):
        raise ValueError("pitch and rotation must be numbers") from None
    kwargs = {"rotation_deg": rotation_deg, "offset": parse_offset(offset), "fill": fill, "edge_px": edge_px}
    if sensor_shape is not None:
        geometry = GridGeometry(tuple(sensor_shape), grid, pitch, **kwargs)
    else:
        lenses = parse_lenses(lenses) if lenses is not None else (64, 64)
        geometry = GridGeometry.from_lenses(lenses, grid, pitch, **kwargs)
    if geometry.sensor_shape[0] * geometry.sensor_shape[1] > 2**28:
        raise ValueError(f"a {geometry.sensor_shape[0]}x{geometry.sensor_shape[1]} sensor is too large to simulate")
    return geometry


def render_grid(planes, sampling, supersample: int = 3):
    """The scene through a lens grid: ``(truth [S, T, U, V, 3], radiance [H*W, 3])``, relative units.

    ``truth``: the planes at the regular samples of ``sampling`` (an
    :class:`lfcl.grid.resampling.SamplingModel`); ``radiance``: every sensor pixel's
    colour at its own continuous light-field position (nearest lens, offset from
    its centre in view steps, :meth:`~lfcl.grid.resampling.SamplingModel.pixel_coordinates`),
    all three colours. Lens (s, t) sits at :func:`lfcl.sim.geometry.scene_position`
    and integrates over a box of its pitch (rows of a hex grid: sqrt(3)/2 of it).
    """
    from .geometry import scene_position
    from .planes import render_points

    packing = sampling.grid.packing
    S, T = sampling.lenses
    U, V = sampling.views
    footprint = (np.sqrt(3.0) / 2, 1.0) if packing == "hex" else (1.0, 1.0)
    ss, tt, uu, vv = np.meshgrid(np.arange(S), np.arange(T), np.arange(U), np.arange(V), indexing="ij")
    y, x = scene_position(packing, ss, tt)
    truth = render_points(planes, y, x, uu - (U - 1) / 2, vv - (V - 1) / 2, supersample, footprint)
    H, W = sampling.sensor_shape
    rows, cols = np.meshgrid(np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64), indexing="ij")
    s, t, u, v = sampling.pixel_coordinates(rows.ravel(), cols.ravel())
    y, x = scene_position(packing, s, t)
    radiance = render_points(planes, y, x, u - (U - 1) / 2, v - (V - 1) / 2, supersample, footprint)
    return truth.reshape(S, T, U, V, 3), radiance


def simulate_grid(scene: str = "charts", grid: str = "square", pitch: float = 9.0, rotation_deg: float = 0.0,
                  offset=(0.0, 0.0), *, lenses=None, sensor_shape=None, pattern: str = "GRBG", lux: float = 12.0,
                  seed: int = 0, exposure=None, vignetting: bool = False, f_number: float = 2.8, views=None,
                  texture=None, planes: list[Plane] | None = None, sensor: SensorModel | None = None,
                  supersample: int = 3, fill: float = 0.9, edge_px: float = 0.45) -> GridCapture:
    """Simulate a raw, white image and truth of a square or hexagonal lens grid (docs/geometry.md).

    The sensor is ``sensor_shape`` or just large enough for ``lenses`` (S, T; default
    64x64), as :func:`simulate_white`. The regular light field is the one the
    solvers estimate for the *true* grid (:func:`lfcl.grid.resampling.sampling_model`,
    ``views`` default round(pitch)): the truth holds the scene at its samples. Each
    sensor pixel sees the scene at its own continuous light-field position (its
    nearest lens, its offset from that lens's centre in view steps; no bilinear
    model involved), times the micro-image response (the white image's disc and,
    with ``vignetting``, the cos^4 falloff), through the sensor's noise model.
    """
    from ..grid.resampling import sampling_model
    from .geometry import scene_frame

    lux = _check_lux(lux)
    pattern = parse_pattern(pattern)
    seed = int(seed)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    sensor = sensor if sensor is not None else SensorModel()
    if exposure is not None:
        sensor = dataclasses.replace(sensor, exposure_s=parse_exposure(exposure))
    geometry = _grid_geometry(grid, pitch, rotation_deg, offset, lenses, sensor_shape, fill, edge_px)
    response = geometry.response(vignetting=vignetting, f_number=f_number)
    sampling = sampling_model(geometry, pattern, views=views, response=geometry.response())
    S, T = sampling.lenses
    U, V = sampling.views
    frame = scene_frame(geometry.grid, (S, T))
    if planes is None:
        scene = check_scene(scene)
        planes = scene_planes(scene, frame, seed, (U, V), texture)
        source = {"kind": "scene", "name": scene, "texture": None if texture is None else str(texture)}
    else:
        source = {"kind": "planes", "name": "custom"}
    truth, radiance = render_grid(planes, sampling, supersample)
    H, W = geometry.sensor_shape

    luminance = truth.reshape(-1, 3) @ LUMINANCE.astype(np.float32)
    mean_y, peak_y = float(luminance.mean(dtype=np.float64)), float(luminance.max())
    if not np.isfinite(mean_y) or mean_y <= 0:
        raise ValueError("the scene is black (mean luminance 0): nothing to scale to the requested lux")
    lux_per_unit = lux / mean_y
    scale = np.float32(lux_per_unit * sensor.electrons_per_lux / sensor.full_well_e)
    truth *= scale
    radiance *= scale
    channels = channel_map((H, W), pattern).ravel()
    expected = radiance[np.arange(H * W), channels].astype(np.float64).reshape(H, W) * response
    truth = np.minimum(truth, np.float32(1.0), out=truth)
    del radiance

    raw_rng, white_rng = (np.random.default_rng(q) for q in np.random.SeedSequence([seed, 0x6121D]).spawn(2))
    raw = sensor.expose(expected, raw_rng)
    white = sensor.expose(WHITE_FRACTION * response, white_rng)
    del expected
    s_coef, o_coef = sensor.noise_profile()
    mean_normalised = float(sensor.lux_to_normalised(lux))
    light_field = sampling.as_meta()
    del light_field["grid"]
    meta = {
        "generator": f"lfcl {__version__} simulate",
        "mode": "grid",
        "scene": source,
        "planes": [p.as_meta() for p in planes],
        "lux": lux,
        "seed": seed,
        "pattern": pattern,
        "lenslet": geometry.as_meta(),
        "grid": geometry.grid,
        "pitch": geometry.pitch,
        "rotation_deg": geometry.rotation_deg,
        "offset": list(geometry.offset),
        "sensor_shape": [H, W],
        "lenses": [S, T],
        "views": [U, V],
        "lightfield": {**light_field, "scene_frame": list(frame), "scene_position": (
            "(s sqrt(3)/2 + 1/2, t + 1/2 + (s mod 2)/2) lenses (hex); (s + 1/2, t + 1/2) (square)")},
        **_exposure_meta(sensor, lux, lux_per_unit, mean_y, peak_y, mean_normalised, (s_coef, o_coef)),
        "vignetting": {"enabled": bool(vignetting), "model": "cos^4, microlens f-number", "f_number": f_number,
                       "micro_image": "disc of diameter fill * pitch in raw and white (lenslet.micro_image)"},
        "white": {"file": "white.dng", "level_normalised": WHITE_FRACTION},
        "truth": {
            "file": "truth.npy", "shape": list(truth.shape), "dtype": "float32",
            "layout": "[S, T, U, V, 3] linear camera RGB on the solvers' regular grid (lightfield)",
            "scale": "expected electrons / full-well electrons = (raw - black) / (white - black), clipped at 1.0",
            "noise_free": True, "vignetting": False,
        },
        "truth_views": {"file": "truth_views.exr",
                        "layout": "U x V grid of S x T tiles; tile (u, v) is the view (u, v)"},
        "supersample": supersample,
        "files": list(FILES),
    }
    return GridCapture(raw, white, truth, meta, geometry, sensor, pattern, sampling)
