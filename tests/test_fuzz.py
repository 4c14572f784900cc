"""Fuzzing the readers (repository issue "Robustness", item 2), with hypothesis.

Byte strings (mutations of a small valid DNG written with
:func:`lfcl.sim.dng.write_dng`, of small PNG / EXR / TIFF mosaics, and pure random
bytes) are written to a file with each extension and fed to

* :func:`lfcl.io.raw.read_mosaic`: it returns a valid Mosaic (finite float32 data of
  the shape the header declares, finite metadata) or raises ``ValueError`` /
  ``FileNotFoundError`` with a one-line message; nothing else;
* ``lfcl demosaic FILE --pattern GRBG -o OUT.exr``: no traceback; either it writes
  OUT and nothing else, or it prints exactly one ``lfcl: error:`` line, exits
  non-zero and creates nothing;
* :func:`lfcl.grid.load_calibration` with mutated ``cal.json`` documents.

``LFCL_FUZZ_EXAMPLES`` scales the number of examples (default: a quick run).
Hostile files found by hand, and the reasons behind each fix, are in
``test_hostile_files.py``.
"""

from __future__ import annotations

import json
import math
import os
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lfcl.io.raw import IMAGE_EXTENSIONS, Mosaic, read_mosaic
from lfcl.layout import PATTERNS

SCALE = float(os.environ.get("LFCL_FUZZ_EXAMPLES", "1"))
SETTINGS = {"deadline": None, "database": None, "derandomize": False,
            "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]}
EXTENSIONS = (".dng", ".exr", ".tif", ".tiff", ".png", ".pgm", ".pfm", ".hdr", ".CR2", ".nef", ".crw")
SENSOR = (32, 48)


def _write_seeds(folder: Path) -> dict[str, bytes]:
    from lfcl.io.images import write_image
    from lfcl.sim.dng import write_dng

    values = np.random.default_rng(3).integers(64, 4000, SENSOR).astype(np.uint16)
    seeds = {}
    write_dng(folder / "s.dng", values, "GRBG", 64, 4095, noise_profile=(2e-4, 1e-6))
    seeds["dng"] = (folder / "s.dng").read_bytes()
    for ext in ("png", "exr", "tif"):
        write_image(folder / f"s.{ext}", values / 4095.0)
        seeds[ext] = (folder / f"s.{ext}").read_bytes()
    # uncompressed ones too, where a damaged sample still decodes (to a wrong, huge or NaN value)
    import OpenImageIO as oiio
    import tifffile

    tifffile.imwrite(folder / "u.tif", values)
    seeds["tif-uncompressed"] = (folder / "u.tif").read_bytes()
    spec = oiio.ImageSpec(SENSOR[1], SENSOR[0], 1, oiio.FLOAT)
    spec.attribute("compression", "none")
    out = oiio.ImageOutput.create(str(folder / "u.exr"))
    assert out.open(str(folder / "u.exr"), spec)
    assert out.write_image((values / 4095.0).astype(np.float32)[:, :, None].copy())
    out.close()
    seeds["exr-uncompressed"] = (folder / "u.exr").read_bytes()
    return seeds


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fuzz")
    return folder, _write_seeds(folder)


# --------------------------------------------------------------------------- strategies

_WORDS = (0, 1, 2, 0xFF, 0x7FFF, 0x8000, 0xFFFF, 0x10000, 0x7FFFFFFF, 0xFFFFFFFF)

_mutation = st.one_of(
    st.tuples(st.just("flip"), st.floats(0, 1), st.integers(1, 255)),  # xor one byte anywhere
    st.tuples(st.just("head"), st.integers(0, 511), st.integers(0, 255)),  # set one header byte
    st.tuples(st.just("word"), st.floats(0, 1), st.sampled_from(_WORDS), st.booleans()),  # a 32-bit size field
    st.tuples(st.just("cut"), st.floats(0, 1)),  # truncate
    st.tuples(st.just("insert"), st.floats(0, 1), st.binary(min_size=1, max_size=64)),
    st.tuples(st.just("delete"), st.floats(0, 1), st.integers(1, 256)),
)


def _mutate(data: bytes, mutations) -> bytes:
    out = bytearray(data)
    for m in mutations:
        if not out:
            break
        at = min(int(m[1] * len(out)), len(out) - 1) if isinstance(m[1], float) else min(m[1], len(out) - 1)
        if m[0] == "flip":
            out[at] ^= m[2]
        elif m[0] == "head":
            out[at] = m[2]
        elif m[0] == "word":
            out[at:at + 4] = struct.pack("<I" if m[3] else ">I", m[2])
        elif m[0] == "cut":
            del out[at:]
        elif m[0] == "insert":
            out[at:at] = m[2]
        else:
            del out[at:at + m[2]]
    return bytes(out)


@st.composite
def hostile_file(draw, seeds):
    kind = draw(st.sampled_from(("dng", "png", "exr", "tif", "exr-uncompressed", "tif-uncompressed", "random")))
    if kind == "random":
        data = draw(st.binary(max_size=4096))
        return kind, data, draw(st.sampled_from(EXTENSIONS))
    data = _mutate(seeds[kind], draw(st.lists(_mutation, min_size=1, max_size=6)))
    own = "." + kind.split("-")[0]
    return kind, data, draw(st.sampled_from(EXTENSIONS + (own,) * len(EXTENSIONS)))  # half: its own extension


# --------------------------------------------------------------------------- contracts


def _declared_shape(path: Path):
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        import OpenImageIO as oiio

        inp = oiio.ImageInput.open(str(path))
        spec = inp.spec()
        inp.close()
        return spec.height, spec.width
    import rawpy

    with rawpy.imread(str(path)) as raw:
        return raw.sizes.height, raw.sizes.width


def _check_read(path: Path, pattern) -> str:
    try:
        mosaic = read_mosaic(path, pattern)
    except (ValueError, FileNotFoundError) as exc:
        assert str(exc) and "\n" not in str(exc), repr(str(exc))
        return "refused"
    assert isinstance(mosaic, Mosaic)
    data = mosaic.data
    assert data.dtype == np.float32 and data.ndim == 2 and data.size > 0 and data.flags.c_contiguous
    assert np.all(np.isfinite(data))
    assert mosaic.shape == _declared_shape(path)
    assert mosaic.pattern in PATTERNS and (pattern is None or mosaic.pattern == pattern)
    assert all(math.isfinite(b) for b in mosaic.black) and math.isfinite(mosaic.white)
    for array in (mosaic.as_shot_wb, mosaic.xyz_to_camera, mosaic.color_matrix, mosaic.noise_profile):
        assert array is None or np.all(np.isfinite(np.asarray(array, dtype=np.float64)))
    json.dumps(mosaic.metadata(), allow_nan=False)
    return "ok"


COUNTS: dict[str, int] = {}


def _count(key: str) -> None:
    COUNTS[key] = COUNTS.get(key, 0) + 1


# --------------------------------------------------------------------------- read_mosaic


def test_fuzz_read_mosaic(workdir):
    folder, seeds = workdir

    @settings(max_examples=int(800 * SCALE), **SETTINGS)
    @given(case=hostile_file(seeds), pattern=st.sampled_from(["GRBG", None]))
    def run(case, pattern):
        kind, data, ext = case
        path = folder / f"case{ext}"
        path.write_bytes(data)
        _count(f"read {kind} {_check_read(path, pattern)}")

    run()
    print("read_mosaic fuzz:", dict(sorted(COUNTS.items())))


# --------------------------------------------------------------------------- lfcl demosaic


def test_fuzz_demosaic_cli(workdir):
    from lfcl.cli import cli

    folder, seeds = workdir
    runner = CliRunner()
    counter = [0]

    @settings(max_examples=int(150 * SCALE), **SETTINGS)
    @given(case=hostile_file(seeds))
    def run(case):
        kind, data, ext = case
        counter[0] += 1
        path = folder / f"cli{ext}"
        path.write_bytes(data)
        out = folder / f"out{counter[0]}"
        out.mkdir()
        target = out / "o.exr"
        result = runner.invoke(cli, ["demosaic", str(path), "--pattern", "GRBG", "-o", str(target)])
        assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
        left = sorted(p.name for p in out.iterdir())
        if result.exit_code == 0:
            assert left == ["o.exr"], left  # the output and nothing else (no temporary file)
            _count(f"cli {kind} ok")
        else:
            lines = result.output.strip().splitlines()
            assert len(lines) == 1 and lines[0].startswith("lfcl: error:"), result.output
            assert left == [], left
            _count(f"cli {kind} refused")

    run()
    print("demosaic CLI fuzz:", dict(sorted(k for k in COUNTS.items() if k[0].startswith("cli"))))


# --------------------------------------------------------------------------- cal.json


_json_leaf = st.one_of(
    st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=8), st.sampled_from(["GRBG", "square", "hex", "lfcl-calibration"]),
)
_json_value = st.recursive(_json_leaf, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                               st.dictionaries(st.text(max_size=6), inner,
                                                                               max_size=4)),
                           max_leaves=12)


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for key, value in doc.items():
            yield from _paths(value, prefix + (key,))
    elif isinstance(doc, list):
        for i, value in enumerate(doc[:3]):
            yield from _paths(value, prefix + (i,))


def _base_documents():
    from lfcl.grid import calibration_from_pitch, calibration_to_dict

    plain = json.loads(json.dumps(calibration_to_dict(calibration_from_pitch(9, (96, 120), pattern="GRBG"))))
    weighted = json.loads(json.dumps(plain))
    weighted["weight"] = {
        "colours": ["R", "G", "B"], "peak": [0.8, 0.9, 0.7], "valid_threshold": 0.2,
        "local": {"step_px": 2.0, "size": 3, "table": [[[1.0] * 3] * 3] * 3},
        "global": {"shape": [2, 2], "table": [[1.0, 0.9], [0.9, 0.8]]},
    }
    return [plain, weighted]


def test_fuzz_calibration_json(tmp_path_factory):
    from lfcl.grid import load_calibration

    folder = tmp_path_factory.mktemp("cal")
    bases = _base_documents()
    path = folder / "cal.json"

    @settings(max_examples=int(500 * SCALE), **SETTINGS)
    @given(base=st.sampled_from([0, 1]), edits=st.lists(st.tuples(st.integers(0, 10**6), st.booleans(), _json_value),
                                                          min_size=1, max_size=4),
           shape=st.sampled_from([None, (96, 120)]))
    def run(base, edits, shape):
        doc = json.loads(json.dumps(bases[base]))
        for pick, delete, value in edits:
            paths = list(_paths(doc))[1:]
            if not paths:
                break
            where = paths[pick % len(paths)]
            parent = doc
            for key in where[:-1]:
                parent = parent[key]
            if delete and isinstance(parent, dict):
                del parent[where[-1]]
            else:
                parent[where[-1]] = value
        path.write_text(json.dumps(doc, allow_nan=True))
        try:
            cal = load_calibration(path, shape, "GRBG" if shape else None)
        except ValueError as exc:
            assert "\n" not in str(exc) and str(path) in str(exc), str(exc)
            _count("cal refused")
            return
        # what process does with an accepted calibration must work on it (small sensors: time)
        if cal.sensor_shape[0] * cal.sensor_shape[1] <= 10**6:
            _, _, rows, cols = cal.centres()
            assert np.all(np.isfinite(rows)) and np.all(np.isfinite(cols))
            assert np.all(np.isfinite(cal.weight_map()))
        _count("cal ok")

    run()
