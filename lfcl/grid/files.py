"""``cal.json`` (read with validation, written atomically) and the lens-centre CSV.

Every problem with a calibration file is a one-line ``ValueError`` naming the
file and the cause; :func:`load_calibration` with ``sensor_shape`` (and
``pattern``) also refuses a calibration made for another sensor.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np

from .. import __version__
from ..io.images import atomic_path
from .calibration import FORMAT, VERSION, Calibration, WeightModel
from .lattice import LensGrid


def calibration_to_dict(cal: Calibration) -> dict:
    grid = cal.grid.as_dict()
    grid["lens_rows_spacing"] = cal.grid.pitch * cal.grid.row_factor
    grid["centre"] = ("(row, col) of lens (i, j) = origin + i*row_step + (j + (i mod 2)/2 if hex else j)*col_step; "
                      "pixel centres at integers, row 0 at the top")
    grid["lenses_on_sensor"] = int(cal.centres()[0].size)
    return {
        "format": FORMAT,
        "version": VERSION,
        "generator": f"lfcl {__version__} calibrate",
        "source": cal.source,
        "sensor_shape": list(cal.sensor_shape),
        "pattern": cal.pattern,
        "grid": grid,
        "weight": None if cal.weight is None else cal.weight.as_dict(),
        "fit": cal.fit,
    }


#: Largest ``cal.json`` read (a real one is tens of kB: the weight tables are small).
MAX_FILE_BYTES = 64 * 2**20
#: Largest magnitude of a number in ``cal.json`` (beyond it floats lose integers and
#: arithmetic on them overflows; nothing in a calibration comes near it).
MAX_NUMBER = 2.0**53


def _bad_number(data):
    """The first number in a JSON document that is not finite or is absurdly large, else None."""
    stack = [data]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, (int, float)) and not isinstance(item, bool):
            if isinstance(item, float) and not math.isfinite(item):
                return item
            if abs(item) > MAX_NUMBER:
                return item
    return None


def _all_numbers(value) -> bool:
    """``value`` is a number or a (nested, non-empty) list of numbers only: no strings, booleans or nulls."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, list):
            if not item:
                return False
            stack.extend(item)
        elif isinstance(item, bool) or not isinstance(item, (int, float)):
            return False
    return True


def calibration_from_dict(data, name: str = "calibration") -> Calibration:
    """Validate a ``cal.json`` document; ``ValueError`` naming ``name`` and the problem."""
    from ..io.raw import MAX_PIXELS

    def fail(msg):
        raise ValueError(f"{name}: {msg}")

    if not isinstance(data, dict):
        fail("not a calibration (expected a JSON object)")
    bad = _bad_number(data)
    if bad is not None:
        text = repr(bad) if isinstance(bad, float) else f"a {len(str(abs(bad)))}-digit integer"
        fail(f"holds the number {text}: every number in a calibration must be finite and below {MAX_NUMBER:.0e}")
    if data.get("format") != FORMAT:
        fail(f"not an lfcl calibration (format {data.get('format')!r}, expected {FORMAT!r})")
    version = data.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        fail(f"malformed version {version!r}")
    if version > VERSION:
        fail(f"calibration version {version} is newer than this lfcl understands ({VERSION}): upgrade lfcl")
    if version < 1:
        fail(f"unknown calibration version {version}")
    shape = data.get("sensor_shape")
    if (not isinstance(shape, list) or len(shape) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in shape)):
        fail(f"sensor_shape must be [rows, cols] of positive integers, got {shape!r}")
    if shape[0] * shape[1] > MAX_PIXELS:
        fail(f"sensor_shape {shape[0]}x{shape[1]} is more than the {MAX_PIXELS}-pixel limit of any raw lfcl reads")
    for key, kind in (("source", str), ("fit", dict)):
        if data.get(key) is not None and not isinstance(data[key], kind):
            fail(f"{key} must be {'a string' if kind is str else 'an object'} or null, got {type(data[key]).__name__}")
    grid_data = data.get("grid")
    if isinstance(grid_data, dict):
        for key in ("origin", "row_step", "col_step"):
            value = grid_data.get(key)
            if value is not None and not (isinstance(value, list) and len(value) == 2 and _all_numbers(value)):
                fail(f"bad grid ({key} must be two numbers [row, col], got {value!r})")
    weight = data.get("weight")
    if isinstance(weight, dict):
        local, glob = weight.get("local"), weight.get("global")
        for key, value in (("peak", weight.get("peak")), ("valid_threshold", weight.get("valid_threshold", 0.2)),
                           ("local step_px", local.get("step_px") if isinstance(local, dict) else None),
                           ("local table", local.get("table") if isinstance(local, dict) else None),
                           ("global table", glob.get("table") if isinstance(glob, dict) else None)):
            if value is not None and not _all_numbers(value):
                fail(f"the weight model's {key} must hold numbers only")
    try:
        grid = LensGrid.from_dict(grid_data)
    except ValueError as exc:
        fail(f"bad grid ({exc})")
    stated = data["grid"].get("pitch")
    if stated is not None and (not isinstance(stated, (int, float)) or not math.isfinite(stated)
                               or abs(stated - grid.pitch) > 1e-3 * grid.pitch):
        fail(f"the grid's pitch {stated!r} disagrees with its steps ({grid.pitch:.4f} px)")
    if grid.pitch < 2 or grid.pitch > max(shape):
        fail(f"implausible lens pitch {grid.pitch:.4g} px for a {shape[0]}x{shape[1]} sensor")
    reach = 8 * max(shape)  # lens (0, 0) farther than this from the sensor: not a grid of this sensor
    if not all(abs(v) <= reach for v in grid.origin):
        fail(f"the grid's origin {list(grid.origin)} is implausibly far from the {shape[0]}x{shape[1]} sensor")
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # out-of-range tables are refused by the model
            weight = None if weight is None else WeightModel.from_dict(weight)
        return Calibration(grid=grid, sensor_shape=tuple(shape), pattern=data.get("pattern"), weight=weight,
                           fit=data.get("fit"), source=data.get("source"), version=version)
    except ValueError as exc:
        fail(str(exc))


def load_calibration(path, sensor_shape=None, pattern: str | None = None) -> Calibration:
    """Read and validate ``cal.json``; with ``sensor_shape``/``pattern``, refuse another sensor's calibration."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"calibration {str(path)!r} does not exist")
    if not path.is_file():
        raise ValueError(f"calibration {str(path)!r} is not a file")
    size = path.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ValueError(f"{path}: {size} bytes is too large for a calibration (at most {MAX_FILE_BYTES})")
    raw = path.read_bytes()
    try:
        data = json.loads(raw, parse_constant=_refuse_constant)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    except RecursionError:
        raise ValueError(f"{path}: not a calibration (JSON nested too deeply)") from None
    except ValueError as exc:  # NaN / Infinity, or an integer too long for Python to convert
        raise ValueError(f"{path}: not valid JSON ({' '.join(str(exc).split())})") from None
    cal = calibration_from_dict(data, str(path))
    if sensor_shape is not None:
        try:
            cal.check(sensor_shape, pattern)
        except ValueError as exc:  # name the file: the user may hold calibrations of several cameras
            raise ValueError(f"{path}: {exc}") from None
    return cal


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


_NUMBER_LIST = re.compile(r"\[\s*((?:-?[0-9][0-9.eE+-]*|null)(?:,\s*(?:-?[0-9][0-9.eE+-]*|null))*)\s*\]")


def dumps(data) -> str:
    """JSON with lists of numbers on one line (the weight tables stay readable and small)."""
    text = json.dumps(data, indent=2, allow_nan=False)
    return _NUMBER_LIST.sub(lambda m: "[" + ", ".join(p.strip() for p in m.group(1).split(",")) + "]", text) + "\n"


def _write_text(path, text: str) -> Path:
    """Write ``text`` atomically, with the usual file mode (the temporary file is created 0600)."""
    umask = os.umask(0)
    os.umask(umask)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
        os.chmod(tmp, 0o666 & ~umask)
    return Path(path)


def save_calibration(cal: Calibration, path) -> Path:
    """Write ``cal.json`` atomically."""
    return _write_text(path, dumps(calibration_to_dict(cal)))


def write_centres_csv(path, rows, cols) -> Path:
    """``row,col`` per lens centre (sensor pixels, 4 decimals) with a header line, atomically."""
    rows, cols = np.asarray(rows, np.float64), np.asarray(cols, np.float64)
    body = "\n".join(f"{r:.4f},{c:.4f}" for r, c in zip(rows.tolist(), cols.tolist()))
    return _write_text(path, "row,col\n" + body + ("\n" if body else ""))


def read_centres_csv(path) -> np.ndarray:
    """``[N, 2]`` (row, col) from :func:`write_centres_csv` output."""
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
