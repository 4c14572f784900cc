"""Hostile input files (repository issue "Robustness", item 2).

Truncated, corrupted, random, empty, misnamed, huge-declaring, unreadable and
not-a-file inputs, and malformed ``cal.json``, through :func:`lfcl.io.raw.read_mosaic`,
:func:`lfcl.grid.load_calibration` and the command line (``lfcl demosaic``,
``lfcl process``, ``lfcl calibrate``, ``lfcl process --calibration``).

The contract:

* ``read_mosaic`` returns a valid :class:`~lfcl.io.raw.Mosaic` (finite float32 data of
  the declared shape, finite metadata) or raises ``ValueError`` /
  ``FileNotFoundError`` with a one-line message; nothing else.
* The CLI shows no traceback, prints exactly one line, starting ``lfcl: error:``,
  exits non-zero and creates nothing: no output file or folder, no temporary
  file beside it.

The seeds are small files written here (a DNG with :func:`lfcl.sim.dng.write_dng`,
PNG / EXR / TIFF mosaics) and, where the workplace's ``../shared`` folder is
present, real camera raws (see ../shared/realdata/SOURCES.md).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import subprocess
import sys
import tempfile
import textwrap
import zlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.grid import calibration_from_pitch, calibration_to_dict, load_calibration
from lfcl.io.raw import IMAGE_EXTENSIONS, Mosaic, read_mosaic
from lfcl.layout import PATTERNS

SHARED = Path(os.environ.get("LFCL_SHARED", Path(__file__).resolve().parents[2] / "shared"))
REALDATA = SHARED / "realdata"

#: real files to damage (small ones, and one of each LibRaw family)
REAL = [
    "tinydng/colorchart.dng",
    "digicam_corpus/Canon_PowerShot_S40_CRW_0101.CRW",
    "digicam_corpus/Kodak_DC50_DC0008L.KDC",
    "digicam_corpus/Kodak_DC120_P003911_better.KDC",
    "a2tools_quicktake/QT100_IMAGE01.QTK",
    "a2tools_quicktake/QT150_TEST150.QTK",
    "imageio_test_images/Nikon_uncompressed.nef",
    "digicam_corpus/GoPro_Hero7Black_GOPR8508.GPR",
    "halide/bayer_small.png",
]
FRACTIONS = (0.0, 0.01, 0.1, 0.25, 0.5, 0.75, 0.9, 0.99)
SEEDS = ("dng", "png", "exr", "tif")
SENSOR = (32, 48)  # LibRaw refuses DNGs narrower than 22 pixels


# --------------------------------------------------------------------------- seeds and crafting


def _sensor_values() -> np.ndarray:
    rng = np.random.default_rng(7)
    return rng.integers(64, 4000, SENSOR).astype(np.uint16)


def write_seed(kind: str, path: Path) -> Path:
    """A small valid mosaic of ``kind`` (dng, png, exr, tif) at ``path``."""
    from lfcl.io.images import write_image
    from lfcl.sim.dng import write_dng

    values = _sensor_values()
    if kind == "dng":
        write_dng(path, values, "GRBG", 64, 4095, noise_profile=(2e-4, 1e-6))
    else:
        write_image(path, values / 4095.0)
    return path


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("seeds")
    out = {}
    for kind in SEEDS:
        path = write_seed(kind, folder / f"seed.{kind}")
        out[kind] = path.read_bytes()
        assert read_mosaic(path, "GRBG").shape == SENSOR  # the seeds themselves are valid
    return out


def real_file(relative: str) -> Path:
    path = REALDATA / relative
    if not path.is_file():
        pytest.skip(f"real test file {path} is absent (the workplace's shared/ folder beside the repo)")
    return path


def tiff_set_size(data: bytes, width: int, height: int) -> bytes:
    """A little-endian TIFF/DNG whose first IFD declares ``width`` x ``height`` (the pixel data unchanged)."""
    out = bytearray(data)
    assert out[:4] == b"II*\x00"
    ifd = struct.unpack_from("<I", out, 4)[0]
    for k in range(struct.unpack_from("<H", out, ifd)[0]):
        entry = ifd + 2 + 12 * k
        tag = struct.unpack_from("<H", out, entry)[0]
        if tag in (256, 257):
            struct.pack_into("<HHII", out, entry, tag, 4, 1, width if tag == 256 else height)
    return bytes(out)


def tiff_set_tag(data: bytes, code: int, value: int) -> bytes:
    """Set a SHORT/LONG tag with count 1 in the first IFD."""
    out = bytearray(data)
    ifd = struct.unpack_from("<I", out, 4)[0]
    for k in range(struct.unpack_from("<H", out, ifd)[0]):
        entry = ifd + 2 + 12 * k
        if struct.unpack_from("<H", out, entry)[0] == code:
            struct.pack_into("<HHII", out, entry, code, 4, 1, value)
            return bytes(out)
    raise AssertionError(f"tag {code} not in the first IFD")


def png_set_size(data: bytes, width: int, height: int) -> bytes:
    out = bytearray(data)
    assert out[12:16] == b"IHDR"
    struct.pack_into(">II", out, 16, width, height)
    struct.pack_into(">I", out, 29, zlib.crc32(bytes(out[12:29])))
    return bytes(out)


def exr_set_size(data: bytes, width: int, height: int) -> bytes:
    out = bytearray(data)
    for name in (b"dataWindow\x00box2i\x00", b"displayWindow\x00box2i\x00"):
        at = out.index(name) + len(name) + 4
        struct.pack_into("<iiii", out, at, 0, 0, width - 1, height - 1)
    return bytes(out)


SET_SIZE = {"dng": tiff_set_size, "tif": tiff_set_size, "png": png_set_size, "exr": exr_set_size}


def flip_bytes(data: bytes, seed: int, start: int, stop: int, count: int) -> bytes:
    out = bytearray(data)
    rng = np.random.default_rng(seed)
    stop = min(stop, len(out))
    for at in rng.integers(start, stop, count):
        out[at] ^= int(rng.integers(1, 256))
    return bytes(out)


# --------------------------------------------------------------------------- the contracts


def declared_shape(path: Path) -> tuple[int, int] | None:
    """What the file's header says the mosaic is (OpenImageIO's spec, LibRaw's visible size)."""
    if path.suffix.lower() in IMAGE_EXTENSIONS:
        import OpenImageIO as oiio

        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            return None
        spec = inp.spec()
        inp.close()
        return spec.height, spec.width
    import rawpy

    with rawpy.imread(str(path)) as raw:
        return raw.sizes.height, raw.sizes.width


def assert_valid_mosaic(mosaic, path: Path) -> None:
    assert isinstance(mosaic, Mosaic)
    data = mosaic.data
    assert isinstance(data, np.ndarray) and data.dtype == np.float32 and data.ndim == 2
    assert data.size > 0 and data.flags.c_contiguous
    assert np.all(np.isfinite(data)), f"{path.name}: non-finite mosaic"
    assert mosaic.shape == declared_shape(path)
    assert mosaic.pattern in PATTERNS
    assert len(mosaic.black) == 4 and all(math.isfinite(b) for b in mosaic.black)
    assert math.isfinite(mosaic.white) and mosaic.white > max(mosaic.black)
    for array in (mosaic.as_shot_wb, mosaic.xyz_to_camera, mosaic.color_matrix, mosaic.noise_profile):
        assert array is None or np.all(np.isfinite(np.asarray(array, dtype=np.float64)))
    json.dumps(mosaic.metadata(), allow_nan=False)  # what outputs record: finite, JSON-clean


def read_outcome(path: Path, pattern: str | None = "GRBG") -> str:
    """``read_mosaic`` obeys the contract; returns "ok" or "refused"."""
    try:
        mosaic = read_mosaic(path, pattern)
    except (ValueError, FileNotFoundError) as exc:
        message = str(exc)
        if "disagrees" in message and pattern is not None:  # a raw of another pattern: read it as it is
            return read_outcome(path, None)
        assert message and "\n" not in message, repr(message)
        return "refused"
    assert_valid_mosaic(mosaic, path)
    return "ok"


def assert_refused(path: Path, pattern: str | None = "GRBG", match: str | None = None) -> str:
    with pytest.raises((ValueError, FileNotFoundError)) as info:
        read_mosaic(path, pattern)
    message = str(info.value)
    assert message and "\n" not in message, repr(message)
    if match is not None:
        assert match in message, message
    return message


def invoke(args):
    from lfcl.cli import cli

    result = CliRunner().invoke(cli, [str(a) for a in args])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        import traceback

        raise AssertionError("traceback:\n" + "".join(traceback.format_exception(result.exception)))
    return result


def assert_cli_error(args, out_dir: Path, match: str | None = None):
    """One ``lfcl: error:`` line, exit != 0, nothing in ``out_dir`` (which must be empty before)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    assert list(out_dir.iterdir()) == []
    result = invoke(args)
    lines = result.output.strip().splitlines()
    assert result.exit_code != 0, result.output
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:"), result.output
    if match is not None:
        assert match in lines[0], lines[0]
    assert list(out_dir.iterdir()) == [], f"left behind: {sorted(p.name for p in out_dir.iterdir())}"
    return lines[0]


def assert_cli_outcome(args, out_dir: Path, output: Path) -> str:
    """Either the error contract or a success that wrote ``output`` and no temporary file."""
    out_dir.mkdir(parents=True, exist_ok=True)
    assert list(out_dir.iterdir()) == []
    result = invoke(args)
    if result.exit_code == 0:
        assert output.exists(), result.output
        hidden = [p.name for p in out_dir.rglob(".*")]
        assert not hidden, f"temporary files left: {hidden}"
        return "ok"
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:"), result.output
    assert list(out_dir.iterdir()) == [], f"left behind: {sorted(p.name for p in out_dir.iterdir())}"
    return "refused"


def cli_commands(path: Path, out: Path):
    """The three commands that read a raw, each with its own output path in the folder ``out``."""
    return [
        (["demosaic", path, "--pattern", "GRBG", "-o", out / "o.exr"], out / "o.exr"),
        (["process", path, "-o", out / "result", "--method", "malvar", "--pattern", "GRBG"], out / "result"),
        (["calibrate", path, "-o", out / "cal.json", "--pattern", "GRBG"], out / "cal.json"),
    ]


def process_has_calibration() -> bool:
    from lfcl.cli.commands.process import command

    return any(p.name == "calibration" for p in command.params)


# --------------------------------------------------------------------------- truncated


@pytest.mark.parametrize("kind", SEEDS)
def test_truncated_seed(tmp_path, seeds, kind):
    data = seeds[kind]
    for fraction in FRACTIONS:
        path = tmp_path / f"cut{int(fraction * 100)}.{kind}"
        path.write_bytes(data[:int(len(data) * fraction)])
        assert_refused(path, match=path.name)
        for n, (args, _) in enumerate(cli_commands(path, tmp_path / f"out{fraction}")):
            if n == 0 or fraction in (0.0, 0.5):  # every fraction through demosaic; two through the others
                assert_cli_error(args, tmp_path / f"out{fraction}", match=path.name)


@pytest.mark.parametrize("name", REAL)
def test_truncated_real_file(tmp_path, name):
    source = real_file(name)
    data = source.read_bytes()
    outcomes = []
    for fraction in FRACTIONS:
        path = tmp_path / f"cut{int(fraction * 100)}{source.suffix}"
        path.write_bytes(data[:int(len(data) * fraction)])
        outcomes.append(read_outcome(path))
    # some LibRaw decoders fill a short file's missing rows; but an empty or cut-header file never reads
    assert outcomes[0] == outcomes[1] == "refused"
    path = tmp_path / f"cut10{source.suffix}"
    assert_cli_outcome(["demosaic", path, "--pattern", "GRBG", "-o", tmp_path / "out" / "o.exr"],
                       tmp_path / "out", tmp_path / "out" / "o.exr")


# --------------------------------------------------------------------------- corrupted


@pytest.mark.parametrize("kind", SEEDS)
@pytest.mark.parametrize("region", ["header", "data"])
def test_corrupted_seed(tmp_path, seeds, kind, region):
    data = seeds[kind]
    start, stop = (0, 256) if region == "header" else (256, len(data))
    for seed in range(6):
        path = tmp_path / f"flip{seed}.{kind}"
        path.write_bytes(flip_bytes(data, seed, start, stop, count=1 + 3 * seed))
        read_outcome(path)
        for n, (args, output) in enumerate(cli_commands(path, tmp_path / f"out{seed}")):
            if n == 0 or seed < 2:  # every variant through demosaic; two through process and calibrate
                out = tmp_path / f"out{seed}_{n}"
                args = [out / output.name if a == output else a for a in args]
                assert_cli_outcome(args, out, out / output.name)


@pytest.mark.parametrize("name", REAL)
def test_corrupted_real_file(tmp_path, name):
    source = real_file(name)
    data = source.read_bytes()
    for seed in range(4):
        header = tmp_path / f"h{seed}{source.suffix}"
        header.write_bytes(flip_bytes(data, seed, 0, 1024, count=2 + seed))
        body = tmp_path / f"d{seed}{source.suffix}"
        body.write_bytes(flip_bytes(data, seed, 1024, len(data), count=50))
        read_outcome(header)
        read_outcome(body)


def test_nan_in_a_float_exr_is_refused(tmp_path, seeds):
    """Flipping the exponent bits of an uncompressed float EXR's samples makes NaN/Inf: refused."""
    import OpenImageIO as oiio

    path = tmp_path / "m.exr"
    spec = oiio.ImageSpec(8, 6, 1, oiio.FLOAT)
    spec.attribute("compression", "none")
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec)
    assert out.write_image(np.full((6, 8, 1), 0.5, np.float32))
    out.close()
    data = bytearray(path.read_bytes())
    at = data.rindex(struct.pack("<f", 0.5))
    data[at:at + 4] = struct.pack("<f", float("nan"))
    path.write_bytes(bytes(data))
    assert_refused(path, match="NaN or infinite")
    assert_cli_error(["demosaic", path, "--pattern", "GRBG", "-o", tmp_path / "out" / "o.exr"], tmp_path / "out")


# --------------------------------------------------------------------------- random, empty, misnamed

EXTENSIONS = (".dng", ".exr", ".tif", ".png", ".pgm", ".CR2", ".nef", ".raw", "")


@pytest.mark.parametrize("ext", EXTENSIONS)
def test_random_and_empty_files(tmp_path, ext):
    rng = np.random.default_rng(len(ext))
    for name, data in (("empty", b""), ("one", b"\x00"), ("random", rng.bytes(20_000)),
                       ("text", b"hello, this is not an image\n" * 40)):
        path = tmp_path / f"{name}{ext}"
        path.write_bytes(data)
        assert_refused(path, match=path.name)
        out = tmp_path / f"out_{name}"
        for args, _ in cli_commands(path, out):
            assert_cli_error(args, out, match=path.name)


def test_a_text_file_named_like_a_raw_is_not_called_an_io_error(tmp_path):
    """LibRaw answers data it cannot parse with LIBRAW_IO_ERROR ("Input/output error"); the file reads fine."""
    path = tmp_path / "notes.nef"
    path.write_bytes(b"hello\n")
    assert_refused(path, match="the file itself reads fine: not a camera raw LibRaw can decode")


@pytest.mark.parametrize("source, name, match", [
    ("png", "png_named.dng", "Unsupported file format"),
    ("dng", "dng_named.exr", "holds a tiff image, not the openexr"),
    ("exr", "exr_named.png", "holds a openexr image, not the png"),
    ("tif", "tif_named.pgm", "holds a tiff image, not the pnm"),
    ("text", "text_named.tif", "text_named.tif"),
])
def test_wrong_extension(tmp_path, seeds, source, name, match):
    path = tmp_path / name
    path.write_bytes(seeds.get(source, b"just some text\n"))
    assert_refused(path, match=match)
    out = tmp_path / "out"
    for args, _ in cli_commands(path, out):
        assert_cli_error(args, out, match=name)


# --------------------------------------------------------------------------- huge declared sizes

_MEMORY_SCRIPT = textwrap.dedent("""
    import json, resource, sys, tracemalloc
    from pathlib import Path
    tracemalloc.start()
    import numpy, OpenImageIO, rawpy, tifffile
    from lfcl.io.raw import read_mosaic
    cases = json.loads(sys.argv[1])
    read_mosaic(cases[0]["seed"], "GRBG")  # warm the readers up
    tracemalloc.reset_peak()
    start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for case in cases:
        try:
            read_mosaic(case["path"], "GRBG", **case["kwargs"])
            case["error"] = None
        except (ValueError, FileNotFoundError) as exc:
            case["error"] = str(exc)
    grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - start) / 1024  # kB -> MB (Linux)
    print(json.dumps({"cases": cases, "rss_mb": grown, "traced_mb": tracemalloc.get_traced_memory()[1] / 2**20}))
""")


def test_huge_declared_sizes_are_refused_with_bounded_memory(tmp_path, seeds):
    """Headers declaring 100000x100000 (and more than ``max_pixels``) are refused from the header.

    Run in a fresh interpreter so that its peak RSS (``ru_maxrss``) and tracemalloc's
    peak measure only these reads: both must stay under 500 MB (the data of one
    100000x100000 float32 plane would be 37 GiB).
    """
    cases = []
    for kind in SEEDS:
        seed = tmp_path / f"seed.{kind}"
        seed.write_bytes(seeds[kind])
        for width, height, kwargs in ((100_000, 100_000, {}), (20_000, 20_000, {}), (60_000, 5_000, {}),
                                      (4_000, 4_000, {"max_pixels": 1_000_000})):
            path = tmp_path / f"huge{width}x{height}.{kind}"
            path.write_bytes(SET_SIZE[kind](seeds[kind], width, height))
            cases.append({"path": str(path), "seed": str(seed), "kwargs": kwargs, "declared": width * height})
    # a TIFF that declares 64 channels (a per-plane limit alone would let it allocate 64 planes)
    many = tmp_path / "channels.tif"
    many.write_bytes(tiff_set_tag(tiff_set_size(seeds["tif"], 2_000, 2_000), 277, 64))
    cases.append({"path": str(many), "seed": str(tmp_path / "seed.tif"), "kwargs": {}, "declared": 4_000_000})

    proc = subprocess.run([sys.executable, "-c", _MEMORY_SCRIPT, json.dumps(cases)],
                          check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    for case in report["cases"]:
        name = Path(case["path"]).name
        assert case["error"] is not None, f"{name} was read"
        assert "\n" not in case["error"] and name in case["error"], case["error"]
        if case["kwargs"]:  # under a limit OpenImageIO and LibRaw do not police: it is ours that refuses
            assert "more than the limit of 1000000" in case["error"], case["error"]
        if name == "channels.tif":  # refused from the header, before 64 planes are read
            assert "2000x2000x64" in case["error"], case["error"]
    assert report["rss_mb"] < 500, report
    assert report["traced_mb"] < 500, report


def test_huge_declared_size_through_the_cli(tmp_path, seeds):
    for kind in SEEDS:
        path = tmp_path / f"huge.{kind}"
        path.write_bytes(SET_SIZE[kind](seeds[kind], 20_000, 20_000))
        out = tmp_path / f"out_{kind}"
        for args, _ in cli_commands(path, out):
            assert_cli_error(args, out, match=path.name)


# --------------------------------------------------------------------------- not a readable file


def test_directory_is_refused(tmp_path):
    folder = tmp_path / "folder.dng"
    folder.mkdir()
    assert_refused(folder, match="not a file")
    with pytest.raises(ValueError, match="not a file"):
        load_calibration(folder)


@pytest.mark.parametrize("command", ["demosaic", "process", "calibrate", "process --calibration"])
def test_directory_through_the_cli(tmp_path, seeds, command):
    folder = tmp_path / "folder.dng"
    folder.mkdir()
    out = tmp_path / "out"
    if command == "process --calibration":
        assert process_has_calibration()
        raw = tmp_path / "raw.dng"
        raw.write_bytes(seeds["dng"])
        args = ["process", raw, "-o", out / "result", "--method", "malvar", "--calibration", folder]
    else:
        args = {c[0][0]: c[0] for c in cli_commands(folder, out)}[command]
    assert_cli_error(args, out)


def test_special_files_are_refused_without_blocking(tmp_path):
    """A FIFO would block any reader that opened it; a dangling link is a missing file."""
    fifo = tmp_path / "pipe.dng"
    os.mkfifo(fifo)
    assert_refused(fifo, match="not a file")
    assert_cli_error(["demosaic", fifo, "-o", tmp_path / "out" / "o.exr"], tmp_path / "out", match="not a file")
    dangling = tmp_path / "link.exr"
    dangling.symlink_to(tmp_path / "nowhere.exr")
    assert_refused(dangling, match="does not exist")
    assert_cli_error(["demosaic", dangling, "--pattern", "RGGB", "-o", tmp_path / "out" / "o.exr"],
                     tmp_path / "out", match="does not exist")


def test_awkward_file_names(tmp_path, seeds):
    """A Linux file name can be any bytes: not UTF-8 (OpenImageIO's binding raised TypeError), or with
    a line break (which split the "one-line" error in two)."""
    for name in (b"bad\xffname.dng", b"bad\xffname.png", b"line\nbreak.dng", b"line\nbreak.png"):
        path = Path(os.fsdecode(bytes(tmp_path) + b"/" + name))
        seed = seeds["dng"] if name.endswith(b".dng") else seeds["png"]
        path.write_bytes(seed if name.startswith(b"bad") else seed[: len(seed) // 2])  # truncated: an error
        assert_refused(path, match="not valid UTF-8" if name.startswith(b"bad") else "line break")
        out = tmp_path / "out"
        assert_cli_error(["demosaic", path, "--pattern", "GRBG", "-o", out / "o.exr"], out)
    good = tmp_path / "good.dng"
    good.write_bytes(seeds["dng"])
    target = Path(os.fsdecode(bytes(tmp_path) + b"/out/o\xff.exr"))
    assert_cli_error(["demosaic", good, "-o", target], tmp_path / "out", match="not valid UTF-8")


def _as_unprivileged(check, warm_up):
    """Run ``check()`` where file permissions bind: in a forked child that drops to
    uid/gid 65534 ("nobody") when the tests run as root; returns its error text or None.

    ``warm_up()`` runs first in this process, so that every module the code path imports
    lazily is loaded before the child loses access to the root-owned installation."""
    if os.geteuid() != 0:
        try:
            check()
        except AssertionError as exc:
            return str(exc) or "assertion failed"
        return None
    warm_up()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: no pytest machinery from here on, only os._exit
        os.close(read)
        message = b""
        try:
            os.setgid(65534)
            os.setuid(65534)
            check()
        except BaseException as exc:
            import traceback

            message = "".join(traceback.format_exception(exc)).encode() or b"failed"
        os.write(write, message)
        os._exit(0)
    os.close(write)
    with os.fdopen(read, "rb") as pipe:
        message = pipe.read().decode()
    os.waitpid(pid, 0)
    return message or None


@pytest.fixture
def open_folder():
    """A folder anyone may enter (pytest's own tmp_path sits under a private 0700 folder)."""
    with tempfile.TemporaryDirectory(prefix="lfcl-perm-") as folder:
        os.chmod(folder, 0o777)  # writable too: the commands may create their output folder
        yield Path(folder)


@pytest.mark.parametrize("kind", SEEDS)
def test_unreadable_file(open_folder, seeds, kind):
    tmp_path = open_folder  # the unprivileged reader may enter the folder but not read the file
    path = tmp_path / f"locked.{kind}"
    path.write_bytes(seeds[kind])
    path.chmod(0)
    out = tmp_path / "out"

    def check():
        assert_refused(path, match=path.name)
        for args, _ in cli_commands(path, out):
            assert_cli_error(args, out)

    readable = tmp_path / f"open.{kind}"
    readable.write_bytes(seeds[kind])

    def warm_up():  # the same commands on a readable copy (they may succeed or fail)
        import click._textwrap  # noqa: F401 (click formats its messages with it, lazily)

        with contextlib.suppress(Exception):
            read_mosaic(readable, "GRBG")
        for args, _ in cli_commands(readable, tmp_path / "warm"):
            invoke(args)

    try:
        assert _as_unprivileged(check, warm_up) is None
    finally:
        path.chmod(0o644)


# --------------------------------------------------------------------------- stderr of the C libraries


def test_image_library_messages_stay_off_the_terminal(tmp_path, seeds):
    """libpng prints "libpng error: ..." on fd 2 (which CliRunner does not see) before OpenImageIO
    reports the error: in a real process the user still sees exactly one line."""
    broken = tmp_path / "broken.png"
    broken.write_bytes(seeds["png"][: len(seeds["png"]) // 2])
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(flip_bytes(seeds["png"], 3, 100, len(seeds["png"]) - 20, 8))
    code = "import sys; from lfcl.cli import cli; cli(sys.argv[1:], prog_name='lfcl')"
    for path in (broken, corrupt):
        out = tmp_path / f"out_{path.stem}"
        out.mkdir()
        proc = subprocess.run([sys.executable, "-c", code, "demosaic", str(path), "--pattern", "GRBG",
                               "-o", str(out / "o.exr")], check=False, capture_output=True, text=True,
                              timeout=120)
        assert proc.returncode == 1, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("lfcl: error: ") and path.name in lines[0], proc.stderr
        assert proc.stdout == "" and list(out.iterdir()) == []


# --------------------------------------------------------------------------- damaged metadata in a DNG


def _dng_with(path: Path, edit) -> Path:
    import tifffile

    from lfcl.sim.dng import dng_tags

    tags = [edit(tag) for tag in dng_tags("GRBG", 64, 4095, noise_profile=[(2e-4, 1e-6)] * 3)]
    tifffile.imwrite(str(path), _sensor_values(), photometric=32803, metadata=None, subfiletype=0, extratags=tags)
    return path


def _set(code, count, value):
    return lambda tag: (tag[0], tag[1], count, value, tag[4]) if tag[0] == code else tag


@pytest.mark.parametrize("name, edit", [
    ("noise_nan", _set(51041, 6, (float("nan"),) * 6)),
    ("noise_inf", _set(51041, 2, (float("inf"), 1e-6))),
    ("noise_odd", _set(51041, 3, (1e-4, 1e-6, 1e-4))),
    ("matrix_zero_denominators", _set(50721, 9, (1, 0) * 9)),
    ("neutral_zero", _set(50728, 3, (0, 1) * 3)),
    ("neutral_zero_denominators", _set(50728, 3, (1, 0) * 3)),
    ("black_above_white", _set(50714, 1, 4_000_000_000)),
    ("white_zero", _set(50717, 1, 0)),
    ("cfa_all_red", _set(33422, 4, (0, 0, 0, 0))),
    ("cfa_unknown_colour", _set(33422, 4, (5, 1, 1, 2))),
    ("cfa_repeat_64", _set(33421, 2, (64, 64))),
])
def test_damaged_dng_metadata(tmp_path, name, edit):
    """Metadata a damaged DNG can hold (NaN noise profile, zero denominators, ...) never reaches a Mosaic."""
    path = _dng_with(tmp_path / f"{name}.dng", edit)
    if read_outcome(path, None) == "ok":
        out = tmp_path / "out"
        assert_cli_outcome(["process", path, "-o", out / "result", "--method", "admm-uv", "--iterations", "2"],
                           out, out / "result")


# --------------------------------------------------------------------------- malformed cal.json


def _valid_cal() -> dict:
    return json.loads(json.dumps(calibration_to_dict(calibration_from_pitch(9, SENSOR, pattern="GRBG"))))


def _edit(**changes):
    def apply(doc):
        for dotted, value in changes.items():
            keys = dotted.split("__")
            target = doc
            for key in keys[:-1]:
                target = target[key]
            if value is KeyError:
                del target[keys[-1]]
            else:
                target[keys[-1]] = value
        return json.dumps(doc, allow_nan=True)
    return apply


MALFORMED = {
    "empty": lambda doc: "",
    "not_json": lambda doc: "{not json",
    "truncated": lambda doc: json.dumps(doc)[:40],
    "binary": lambda doc: b"\x00\x01\x02\xff\xfe",
    "a_list": lambda doc: "[1, 2, 3]",
    "a_string": lambda doc: '"cal"',
    "null": lambda doc: "null",
    "nested_deep": lambda doc: "[" * 100_000 + "]" * 100_000,
    "nan_literal": lambda doc: json.dumps(doc).replace('"version": 1', '"version": NaN'),
    "infinity_literal": lambda doc: json.dumps(doc).replace('"version": 1', '"version": Infinity'),
    "overflowing_float": lambda doc: json.dumps(doc).replace('"version": 1', '"version": 1e400'),
    "huge_integer": lambda doc: json.dumps(doc).replace('"version": 1', '"version": ' + "9" * 5000),
    "missing_format": _edit(format=KeyError),
    "missing_version": _edit(version=KeyError),
    "missing_grid": _edit(grid=KeyError),
    "missing_sensor_shape": _edit(sensor_shape=KeyError),
    "missing_grid_origin": _edit(grid__origin=KeyError),
    "version_string": _edit(version="1"),
    "version_bool": _edit(version=True),
    "version_future": _edit(version=99),
    "sensor_shape_string": _edit(sensor_shape="32x48"),
    "sensor_shape_floats": _edit(sensor_shape=[32.0, 48.5]),
    "sensor_shape_negative": _edit(sensor_shape=[-32, 48]),
    "sensor_shape_huge": _edit(sensor_shape=[10**9, 10**9]),
    "sensor_shape_2_63": _edit(sensor_shape=[2**63, 2**63]),
    "grid_a_list": _edit(grid=[1, 2]),
    "grid_packing_number": _edit(grid__packing=4),
    "grid_origin_nan": _edit(grid__origin=[float("nan"), 0.0]),
    "grid_origin_far": _edit(grid__origin=[1e15, 1e15]),
    "grid_origin_huge_int": _edit(grid__origin=[10**30, 0]),
    "grid_row_step_strings": _edit(grid__row_step=["9", "0"]),
    "grid_row_step_short": _edit(grid__row_step=[9.0]),
    "grid_col_step_inf": _edit(grid__col_step=[0.0, float("inf")]),
    "grid_degenerate": _edit(grid__col_step=[9.0, 0.0]),
    "grid_pitch_string": _edit(grid__pitch="9"),
    "grid_pitch_huge": _edit(grid__pitch=10**400),
    "pattern_number": _edit(pattern=7),
    "pattern_unknown": _edit(pattern="RGBW"),
    "source_number": _edit(source=12),
    "fit_a_list": _edit(fit=[1]),
    "weight_a_number": _edit(weight=3),
    "weight_empty": _edit(weight={}),
}


def _weighted_cal() -> dict:
    doc = _valid_cal()
    n = 5
    doc["weight"] = {
        "colours": ["R", "G", "B"], "peak": [0.8, 0.9, 0.7], "valid_threshold": 0.2,
        "local": {"step_px": 2.0, "size": n, "table": [[[1.0] * n for _ in range(n)] for _ in range(3)]},
        "global": {"shape": [2, 2], "table": [[1.0, 1.0], [1.0, 1.0]]},
    }
    return doc


WEIGHT_MALFORMED = {
    "weight_peak_nan": _edit(weight__peak=[float("nan"), 1.0, 1.0]),
    "weight_peak_huge_int": _edit(weight__peak=[10**400, 1.0, 1.0]),
    "weight_table_ragged": _edit(weight__local__table=[[[1.0, 1.0], [1.0]]] * 3),
    "weight_table_strings": _edit(weight__local__table=[[["a"]]] * 3),
    "weight_table_overflowing": _edit(weight__global__table=[[1e300, 1.0], [1.0, 1.0]]),
    "weight_table_negative": _edit(weight__global__table=[[-1.0, 1.0], [1.0, 1.0]]),
    "weight_step_zero": _edit(weight__local__step_px=0),
    "weight_step_huge_int": _edit(weight__local__step_px=10**400),
    "weight_threshold_nan": _edit(weight__valid_threshold=float("nan")),
    "weight_colours_number": _edit(weight__colours=3),
    "weight_missing_local": _edit(weight__local=KeyError),
}


def _write_cal(path: Path, text: str) -> Path:
    path.write_bytes(text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text)
    return path


def test_the_valid_calibrations_load(tmp_path):
    for doc in (_valid_cal(), _weighted_cal()):
        path = _write_cal(tmp_path / "cal.json", json.dumps(doc))
        cal = load_calibration(path, SENSOR, "GRBG")
        assert cal.sensor_shape == SENSOR
        assert np.all(np.isfinite(cal.weight_map()))


@pytest.mark.parametrize("name", sorted(MALFORMED) + sorted(WEIGHT_MALFORMED))
def test_malformed_calibration(tmp_path, name):
    make = MALFORMED.get(name) or WEIGHT_MALFORMED[name]
    doc = _weighted_cal() if name in WEIGHT_MALFORMED else _valid_cal()
    path = _write_cal(tmp_path / "cal.json", make(doc))
    with pytest.raises(ValueError) as info:
        load_calibration(path, SENSOR, "GRBG")
    message = str(info.value)
    assert "\n" not in message and str(path) in message, message


@pytest.mark.parametrize("name", ["not_json", "nested_deep", "nan_literal", "huge_integer", "sensor_shape_2_63",
                                  "grid_origin_far", "grid_pitch_huge", "weight_table_overflowing", "missing"])
def test_malformed_calibration_through_process(tmp_path, seeds, name):
    assert process_has_calibration()
    raw = tmp_path / "raw.dng"
    raw.write_bytes(seeds["dng"])
    cal = tmp_path / "cal.json"
    if name != "missing":
        make = MALFORMED.get(name) or WEIGHT_MALFORMED[name]
        _write_cal(cal, make(_weighted_cal() if name in WEIGHT_MALFORMED else _valid_cal()))
    out = tmp_path / "out"
    assert_cli_error(["process", raw, "-o", out / "result", "--method", "malvar", "--calibration", cal], out,
                     match="cal.json")


def test_oversized_calibration_is_not_read(tmp_path, monkeypatch):
    import lfcl.grid.files as calib_io

    monkeypatch.setattr(calib_io, "MAX_FILE_BYTES", 1000)
    path = _write_cal(tmp_path / "cal.json", json.dumps(_valid_cal()) + " " * 2000)
    with pytest.raises(ValueError, match="too large"):
        load_calibration(path)


# --------------------------------------------------------------------------- partial outputs


def test_a_failed_write_leaves_no_file_and_no_folder(tmp_path):
    from lfcl.io.images import atomic_path, write_image

    target = tmp_path / "new" / "deeper" / "o.exr"
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half an image")
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "kept").mkdir()
    with pytest.raises(KeyboardInterrupt), atomic_path(tmp_path / "kept" / "o.exr") as tmp:
        raise KeyboardInterrupt
    assert list((tmp_path / "kept").iterdir()) == []  # an existing folder stays, empty
    with pytest.raises(ValueError, match="NaN or Inf"):
        write_image(tmp_path / "nan" / "o.exr", np.full((4, 4), np.nan))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept"]
