"""Lenslet calibration (lfcl.grid, ``lfcl calibrate``) and the white images of general grids it is tested on."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from lfcl.grid import (
    Calibration,
    CalibrationError,
    LensGrid,
    calibrate_array,
    calibration_from_dict,
    calibration_from_pitch,
    calibration_to_dict,
    load_calibration,
    read_centres_csv,
    save_calibration,
)
from lfcl.sim import LensletGeometry, SensorModel, simulate, write_capture
from lfcl.sim.capture import simulate_white, write_white_capture
from lfcl.sim.dng import write_dng
from lfcl.sim.geometry import GridGeometry, render_white

BLACK, WHITE = 64, 4095


def normalised(dn: np.ndarray) -> np.ndarray:
    return (dn.astype(np.float32) - BLACK) / (WHITE - BLACK)


def centre_errors(estimated: LensGrid, true: LensGrid, shape) -> np.ndarray:
    """Distance of every true lens centre on the sensor to the estimated grid's nearest centre."""
    _, _, rows, cols = true.centres(shape)
    _, _, dr, dc = estimated.nearest(rows, cols)
    return np.hypot(dr, dc)


@pytest.fixture(scope="module")
def cli():
    try:
        from lfcl.cli import cli as group
    except ImportError:  # another command module is broken right now: test ours alone
        import click

        from lfcl.cli.commands.calibrate import command
        from lfcl.cli.commands.simulate import command as simulate_command

        group = click.Group("lfcl", commands={"calibrate": command, "simulate": simulate_command})
    return group


# --- the grid model -----------------------------------------------------------------

def test_grid_aligned_square_matches_the_simulator():
    grid = LensGrid.from_params("square", 9)
    geometry = LensletGeometry((5, 6))
    i, j, rows, cols = grid.centres(geometry.sensor_shape)
    assert i.size == 30
    # lens (s, t) covers pixels s*9 .. s*9+8: its centre is pixel (s*9 + 4, t*9 + 4)
    np.testing.assert_allclose(rows, i * 9 + 4)
    np.testing.assert_allclose(cols, j * 9 + 4)
    assert grid.offset == (0.0, 0.0) and grid.pitch == 9 and grid.rotation_deg == 0


@pytest.mark.parametrize("packing", ["square", "hex"])
def test_grid_parameters_round_trip(packing):
    grid = LensGrid.from_params(packing, 10.3, 0.7, (0.3, -0.4))
    assert grid.pitch == pytest.approx(10.3, abs=1e-12)
    assert grid.rotation_deg == pytest.approx(0.7, abs=1e-12)
    assert grid.offset == pytest.approx((0.3, -0.4), abs=1e-12)
    assert LensGrid.from_dict(json.loads(json.dumps(grid.as_dict()))) == grid
    assert grid.canonical() == grid
    # a positive rotation moves lenses further along a lens row further down
    r0, _ = grid.centre(0, 0)
    r1, _ = grid.centre(0, 10)
    assert r1 - r0 == pytest.approx(10 * 10.3 * np.sin(np.radians(0.7)))
    # every lens has 4 (square) or 6 (hex) neighbours at one pitch
    rows, cols = grid.centre(np.array([4, 4, 4, 3, 3, 5, 5]), np.array([4, 3, 5, 3, 4, 3, 4]))
    d = np.hypot(rows[1:] - rows[0], cols[1:] - cols[0])
    assert np.sum(np.isclose(d, 10.3)) == (4 if packing == "square" else 6)


@pytest.mark.parametrize("packing", ["square", "hex"])
def test_grid_nearest_lens_is_exact(packing):
    from scipy.spatial import cKDTree

    grid = LensGrid.from_params(packing, 9.7, -0.9, (0.2, 0.45))
    rng = np.random.default_rng(3)
    rows, cols = rng.uniform(-20, 320, 20000), rng.uniform(-20, 320, 20000)
    i, j, dr, dc = grid.nearest(rows, cols)
    ii, jj = np.meshgrid(np.arange(-10, 50), np.arange(-10, 50), indexing="ij")
    cr, cc = grid.centre(ii.ravel(), jj.ravel())
    dist, k = cKDTree(np.c_[cr, cc]).query(np.c_[rows, cols])
    np.testing.assert_array_equal(i, ii.ravel()[k])
    np.testing.assert_array_equal(j, jj.ravel()[k])
    np.testing.assert_allclose(np.hypot(dr, dc), dist, atol=1e-9)
    r, c = grid.centre(i, j)
    np.testing.assert_allclose(r + dr, rows, atol=1e-9)
    np.testing.assert_allclose(c + dc, cols, atol=1e-9)


def test_hex_odd_rows_are_shifted_half_a_pitch():
    grid = LensGrid.from_params("hex", 10.0)
    r0, c0 = grid.centre(0, 0)
    r1, c1 = grid.centre(1, 0)
    assert (r1 - r0, c1 - c0) == pytest.approx((10 * np.sqrt(3) / 2, 5.0))
    assert grid.centre(2, 0) == pytest.approx((r0 + 10 * np.sqrt(3), c0))


# --- white images of general grids ------------------------------------------------------

def test_white_image_of_a_hex_grid():
    geometry = GridGeometry((200, 240), "hex", 10.3, 0.5, (0.3, 0.7))
    expected = geometry.white_expected("GRBG", 0.8)
    _, _, rows, cols = geometry.centres()
    inner = (rows > 5) & (rows < 194) & (cols > 5) & (cols < 234)
    r, c = np.rint(rows[inner]).astype(int), np.rint(cols[inner]).astype(int)
    assert expected[r, c].min() > 0.75  # bright at the lens centres
    # dark between three neighbouring lenses (a Voronoi vertex of the hex grid)
    r3, c3 = geometry.lens_grid().centre(np.array([4, 4, 5]), np.array([4, 5, 4]))
    vertex = np.rint([r3.mean(), c3.mean()]).astype(int)
    assert expected[vertex[0], vertex[1]] < 0.1
    white = simulate_white("hex", 10.3, 0.5, (0.3, 0.7), sensor_shape=(200, 240), seed=1).white
    assert white.dtype == np.uint16 and white.shape == (200, 240)
    assert normalised(white).mean() == pytest.approx(expected.mean(), abs=0.01)
    rendered = render_white(geometry, SensorModel(), np.random.default_rng(2))
    assert normalised(rendered).mean() == pytest.approx(expected.mean(), abs=0.01)


def test_aligned_simulation_is_unchanged_by_default():
    """The default (aligned-square) path still gives its files (five, and the truth disparity) and the same raw."""
    cap = simulate("charts", lenses=(6, 7), seed=3)
    assert cap.geometry.grid == "aligned-square" and cap.raw.shape == (54, 63)
    assert cap.meta["files"] == ["raw.dng", "white.dng", "meta.json", "truth.npy", "truth_views.exr", "disparity.npy"]


# --- accuracy on simulated white images of known geometry ---------------------------------

GEOMETRIES = [
    # packing, pitch, rotation, offset, sensor, white options
    ("square", 9.0, 0.0, (0.0, 0.0), (477, 522), {"vignetting": True}),
    ("square", 10.3, 0.5, (0.3, 0.7), (500, 500), {"vignetting": True, "pattern": "RGGB"}),
    ("square", 8.5, -1.0, (-0.4, 0.25), (430, 560), {"main_vignetting": 0.3}),
    ("square", 12.0, 1.0, (0.5, -0.5), (600, 600), {"colour_gains": (0.5, 1.0, 0.7), "pattern": "BGGR"}),
    ("square", 11.1, 0.25, (0.15, -0.35), (450, 450), {"level": 0.15}),
    ("hex", 9.7, 0.0, (0.1, 0.2), (500, 500), {}),
    ("hex", 10.3, 0.5, (0.3, 0.7), (520, 480), {"vignetting": True}),
    ("hex", 11.6, -0.8, (0.45, -0.2), (600, 600), {"colour_gains": (0.5, 1.0, 0.7), "main_vignetting": 0.2}),
    ("hex", 8.5, 1.0, (-0.35, 0.1), (400, 400), {"level": 0.2, "pattern": "GBRG"}),
    ("hex", 12.0, -0.35, (-0.2, -0.45), (560, 440), {"vignetting": True, "edge_px": 0.8}),
]


@pytest.mark.parametrize("packing, pitch, rotation, offset, shape, options", GEOMETRIES,
                         ids=[f"{g[0]}-p{g[1]}-r{g[2]}" for g in GEOMETRIES])
def test_calibration_accuracy(packing, pitch, rotation, offset, shape, options, record_property):
    options = dict(options)
    pattern = options.pop("pattern", "GRBG")
    cap = simulate_white(packing, pitch, rotation, offset, sensor_shape=shape, pattern=pattern,
                         seed=int(pitch * 10), **options)
    cal = calibrate_array(normalised(cap.white), pattern)
    true = cap.geometry.lens_grid()
    errors = centre_errors(cal.grid, true, shape)
    rms = float(np.sqrt(np.mean(errors**2)))
    record_property("rms_centre_error_px", rms)
    print(f"{packing} pitch {pitch} rotation {rotation} offset {offset}: RMS centre error {rms:.4f} px, "
          f"max {errors.max():.4f} px")
    assert cal.grid.packing == packing
    assert cal.grid.pitch == pytest.approx(pitch, abs=0.01)
    assert cal.grid.rotation_deg == pytest.approx(rotation, abs=0.02)
    assert rms <= 0.05
    assert cal.grid.offset == pytest.approx(offset, abs=0.05)  # small offsets come back as given
    assert cal.sensor_shape == shape and cal.pattern == pattern
    # the weight model: best lit at the lens centres, low between lenses; compact
    _, _, rows, cols = true.centres(shape)
    w_centre = cal.weight_at(np.rint(rows).astype(int), np.rint(cols).astype(int))
    assert np.median(w_centre) > 0.8
    assert len(json.dumps(calibration_to_dict(cal))) < 64_000


def test_refinement_on_tiles_of_a_larger_image():
    """Above max_pixels the refinement works on an even grid of tiles."""
    cap = simulate_white("hex", 9.3, 0.3, (0.2, 0.1), sensor_shape=(900, 1000), seed=5, vignetting=True)
    cal = calibrate_array(normalised(cap.white), "GRBG", max_pixels=250_000)
    assert cal.fit["pixels_used"] <= 250_000
    errors = centre_errors(cal.grid, cap.geometry.lens_grid(), (900, 1000))
    assert np.sqrt(np.mean(errors**2)) <= 0.05 and cal.grid.packing == "hex"


def test_aligned_camera_white_with_vignetting():
    """The aligned simulator's white (cos^4 falloff only, ~10 % contrast) calibrates to pitch 9, offset 0."""
    cap = simulate("charts", lenses=(40, 40), vignetting=True, seed=2)
    cal = calibrate_array(normalised(cap.white), cap.pattern)
    assert cal.grid.packing == "square"
    errors = centre_errors(cal.grid, LensGrid.from_params("square", 9), cap.white.shape)
    assert np.sqrt(np.mean(errors**2)) <= 0.05
    assert cal.grid.pitch == pytest.approx(9, abs=0.01) and cal.grid.rotation_deg == pytest.approx(0, abs=0.02)


def test_a_lattice_the_lens_centres_do_not_follow_is_refused():
    # A scene raw taken for a white image (scatter 1.4 px), and a wrong --pitch hint that fits a lattice 45 degrees off
    # at pitch / sqrt 2 (0.66 px): refused (MAX_LENS_SCATTER_PX), where they calibrated to a garbage grid before.
    from lfcl.grid.estimate import MAX_LENS_SCATTER_PX

    scene = simulate("charts", lenses=(32, 32), seed=1)
    with pytest.raises(CalibrationError, match="lens centres scatter by"):
        calibrate_array(normalised(scene.raw), scene.pattern)
    white = normalised(simulate_white("square", 9.3, 0.4, sensor_shape=(372, 372), seed=2).white)
    with pytest.raises(CalibrationError, match=f"more than {MAX_LENS_SCATTER_PX:.2f}; a white image, or the right"):
        calibrate_array(white, "GRBG", pitch=7)
    right = calibrate_array(white, "GRBG")
    assert right.grid.pitch == pytest.approx(9.3, abs=0.01) and right.fit["lens_rms_px"] < 0.05


def test_packing_and_pitch_options():
    cap = simulate_white("hex", 10.3, 0.5, (0.3, 0.7), sensor_shape=(300, 300), seed=4)
    data = normalised(cap.white)
    assert calibrate_array(data, "GRBG", packing="hex", pitch=10).grid.packing == "hex"
    with pytest.raises(CalibrationError, match="hex"):
        calibrate_array(data, "GRBG", packing="square")


# --- bad white images ---------------------------------------------------------------

def test_bad_white_images():
    rng = np.random.default_rng(0)
    dark = simulate_white("hex", 10.3, 0.5, (0.3, 0.7), sensor_shape=(300, 300), level=0.004).white
    with pytest.raises(CalibrationError, match="too dark"):
        calibrate_array(normalised(dark), "GRBG")
    flat = SensorModel().expose(np.full((300, 300), 0.8), rng)
    with pytest.raises(CalibrationError, match="no lenslet structure"):
        calibrate_array(normalised(flat), "GRBG")
    with pytest.raises(CalibrationError, match="no lenslet structure"):
        calibrate_array(rng.uniform(0, 1, (300, 300)).astype(np.float32), "GRBG")
    with pytest.raises(CalibrationError, match="too small"):
        calibrate_array(np.ones((20, 300), np.float32), "GRBG")


# --- cal.json -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def calibration():
    cap = simulate_white("square", 10.3, 0.5, (0.3, 0.7), sensor_shape=(300, 320), seed=6)
    return calibrate_array(normalised(cap.white), "GRBG", source="white.dng")


def test_cal_json_round_trip(tmp_path, calibration):
    path = save_calibration(calibration, tmp_path / "cal.json")
    assert path.stat().st_size < 64_000
    loaded = load_calibration(path, sensor_shape=(300, 320), pattern="GRBG")
    assert loaded.grid == calibration.grid and loaded.sensor_shape == (300, 320)
    data = json.loads(path.read_text())
    assert data["version"] == 1 and data["sensor_shape"] == [300, 320] and data["pattern"] == "GRBG"
    assert data["grid"]["packing"] == "square"
    np.testing.assert_allclose(loaded.weight.local, calibration.weight.local, atol=1e-4)
    w = loaded.weight_map()
    assert w.shape == (300, 320) and w.min() >= 0 and w.max() <= 1.0001
    assert 0.3 < loaded.valid_mask().mean() < 1.0  # dark corners between the discs are not valid


def test_cal_json_refuses_another_sensor(tmp_path, calibration):
    path = save_calibration(calibration, tmp_path / "cal.json")
    with pytest.raises(ValueError, match=r"300x320 sensor but the raw is 600x640"):
        load_calibration(path, sensor_shape=(600, 640))
    with pytest.raises(ValueError, match="RGGB"):
        load_calibration(path, sensor_shape=(300, 320), pattern="RGGB")
    with pytest.raises(ValueError, match="another.dng is 10x10"):
        calibration.check((10, 10), what="another.dng")


@pytest.mark.parametrize("edit, words", [
    (lambda d: d.update(version=2), "newer"),
    (lambda d: d.update(format="other"), "not an lfcl calibration"),
    (lambda d: d.update(sensor_shape=[300]), "sensor_shape"),
    (lambda d: d.pop("grid"), "grid"),
    (lambda d: d["grid"].update(packing="triangle"), "packing"),
    (lambda d: d["grid"].update(row_step=[0, 0]), "degenerate"),
    (lambda d: d["grid"].update(pitch=99.0), "pitch"),
    (lambda d: d["weight"]["local"].update(table=[[1.0]]), "table"),
])
def test_cal_json_validation(tmp_path, calibration, edit, words):
    data = json.loads(json.dumps(calibration_to_dict(calibration)))
    edit(data)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=words) as info:
        load_calibration(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    with pytest.raises(ValueError):
        calibration_from_dict(data)


def test_cal_json_not_json(tmp_path):
    path = tmp_path / "cal.json"
    path.write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        load_calibration(path)


def test_calibration_from_pitch():
    cal = calibration_from_pitch(9, (576, 576))
    assert isinstance(cal, Calibration) and cal.weight is None
    i, _, rows, cols = cal.centres()
    assert i.size == 64 * 64 and (rows[0], cols[0]) == (4, 4)
    assert cal.weight_at(np.array([0]), np.array([0]))[0] == 1


# --- the command line -----------------------------------------------------------------

def test_cli_simulate_and_calibrate_hex(tmp_path, cli):
    sim = tmp_path / "sim"
    result = CliRunner().invoke(cli, ["simulate", "--grid", "hex", "--pitch-px", "10.3", "--rotation", "0.5",
                                      "--offset", "0.3,0.7", "--lenses", "50x46", "--vignetting", "--seed", "1",
                                      "--white-only", "-o", str(sim)])
    assert result.exit_code == 0, result.output
    assert "white.dng and meta.json only" in result.output
    assert sorted(p.name for p in sim.iterdir()) == ["meta.json", "white.dng"]
    meta = json.loads((sim / "meta.json").read_text())
    assert meta["grid"] == "hex" and meta["pitch"] == 10.3 and meta["rotation_deg"] == 0.5
    assert meta["offset"] == [0.3, 0.7] and meta["mode"] == "white-only"
    shape = tuple(meta["sensor_shape"])

    out = tmp_path / "out" / "cal.json"
    csv = tmp_path / "out" / "centres.csv"
    result = CliRunner().invoke(cli, ["calibrate", str(sim / "white.dng"), "-o", str(out),
                                      "--export-centers", str(csv)])
    assert result.exit_code == 0, result.output
    assert "hex grid" in result.output
    cal = load_calibration(out, sensor_shape=shape, pattern="GRBG")
    assert cal.grid.packing == "hex" and cal.grid.pitch == pytest.approx(10.3, abs=0.01)
    assert csv.read_text().splitlines()[0] == "row,col"
    centres = read_centres_csv(csv)
    true = LensGrid.from_params("hex", 10.3, 0.5, (0.3, 0.7))
    _, _, rows, cols = true.centres(shape)
    assert len(centres) == rows.size == meta["lenslet"]["lenses_on_sensor"]
    from scipy.spatial import cKDTree

    dist, _ = cKDTree(np.c_[rows, cols]).query(centres)
    assert np.sqrt(np.mean(dist**2)) <= 0.05
    assert centres[:, 0].min() >= 0 and centres[:, 0].max() <= shape[0] - 1


def test_cli_pitch_without_white(tmp_path, cli):
    out = tmp_path / "cal.json"
    csv = tmp_path / "c.csv"
    result = CliRunner().invoke(cli, ["calibrate", "--pitch", "9", "--sensor-shape", "576x576", "-o", str(out),
                                      "--export-centers", str(csv)])
    assert result.exit_code == 0, result.output
    cal = load_calibration(out, sensor_shape=(576, 576))
    assert cal.grid.packing == "square" and cal.grid.pitch == 9 and cal.weight is None
    centres = read_centres_csv(csv)
    assert centres.shape == (4096, 2) and tuple(centres[0]) == (4, 4) and tuple(centres[-1]) == (571, 571)
    result = CliRunner().invoke(cli, ["calibrate", "--pitch", "10.5", "--packing", "hex", "--rotation", "0.2",
                                      "--offset=-0.3,0.4", "--sensor-shape", "300x400", "-o", str(out)])
    assert result.exit_code == 0, result.output
    cal = load_calibration(out)
    assert cal.grid.packing == "hex" and cal.grid.offset == pytest.approx((-0.3, 0.4))


def _write_white(path, dn):
    write_dng(path, dn.astype(np.uint16), "GRBG", BLACK, WHITE)
    return path


@pytest.mark.parametrize("kind, words", [
    ("dark", "too dark"),
    ("flat", "no lenslet structure"),
    ("random", "no lenslet structure"),
    ("missing", "does not exist"),
    ("no-white", "--pitch P and --sensor-shape"),
    ("bad-shape", "--sensor-shape"),
    ("packing", "packing"),
    ("rotation-with-white", "--rotation"),
    ("rotation-90", "within +-45 degrees"),
    ("few-lenses", "too few lenses"),
])
@pytest.mark.filterwarnings("error::RuntimeWarning")  # nothing but the error line: numpy's warnings would be on stderr
def test_cli_bad_input(tmp_path, cli, kind, words):
    rng = np.random.default_rng(1)
    white = tmp_path / "white.dng"
    args = [str(white)]
    if kind == "dark":
        _write_white(white, simulate_white("hex", 10.3, 0.5, (0.3, 0.7), sensor_shape=(200, 200), level=0.003).white)
    elif kind == "flat":
        write_capture(simulate("charts", lenses=(20, 20)), tmp_path / "cap")  # aligned, no vignetting: flat
        args = [str(tmp_path / "cap" / "white.dng")]
    elif kind == "random":
        _write_white(white, rng.integers(BLACK, WHITE, (200, 200)))
    elif kind == "missing":
        pass
    elif kind == "no-white":
        args = ["--pitch", "9"]
    elif kind == "bad-shape":
        args = ["--pitch", "9", "--sensor-shape", "576by576"]
    elif kind == "packing":
        args = ["--pitch", "9", "--sensor-shape", "90x90", "--packing", "triangle"]
    elif kind == "few-lenses":  # 5x5 lenses: numpy's warnings on stderr came before the error line
        _write_white(white, simulate_white("square", 8, 0.3, sensor_shape=(44, 44), vignetting=True).white)
    elif kind == "rotation-90":
        args = ["--pitch", "9", "--sensor-shape", "90x90", "--rotation", "90"]
    elif kind == "rotation-with-white":
        _write_white(white, simulate_white("square", 10, sensor_shape=(100, 100)).white)
        args = [str(white), "--rotation", "1"]
    out = tmp_path / "never" / "cal.json"
    csv = tmp_path / "never" / "c.csv"
    result = CliRunner().invoke(cli, ["calibrate", *args, "-o", str(out), "--export-centers", str(csv)])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:") and words in lines[0], result.output
    assert not out.exists() and not csv.exists()


def test_cli_never_writes_over_the_white_image_or_one_file_twice(tmp_path, cli):
    white = _write_white(tmp_path / "white.dng", simulate_white("square", 10, sensor_shape=(100, 100)).white)
    before = white.read_bytes()
    for args, words in (([str(white), "-o", str(white)], "is the white image"),
                        ([str(white), "-o", str(tmp_path / "c.json"), "--export-centers", str(white)],
                         "is the white image"),
                        ([str(white), "-o", str(tmp_path / "c.json"), "--export-centers", str(tmp_path / "c.json")],
                         "name the same file"),
                        ([str(white), "-o", str(tmp_path)], "is a folder: name the file to write")):
        result = CliRunner().invoke(cli, ["calibrate", *args])
        assert result.exit_code == 1 and words in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1
    assert white.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["white.dng"]


@pytest.mark.parametrize("args, words", [
    (["--grid", "triangle"], "grid"),
    (["--grid", "hex", "--pitch", "9", "--pitch-px", "9.5"], "pitch"),
    (["--pitch-px", "1.5"], "pitch"),
    (["--offset", "0.3"], "offset"),
    (["--rotation", "60"], "rotation"),
    (["--grid", "hex", "--texture", "x.png"], "--texture"),
])
def test_cli_simulate_white_bad_input(tmp_path, cli, args, words):
    out = tmp_path / "never" / "sim"
    result = CliRunner().invoke(cli, ["simulate", "--lenses", "8x8", *args, "-o", str(out)])
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lfcl: error:") and words in lines[0], result.output
    assert not (tmp_path / "never").exists()


def test_write_white_capture_replaces_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "white.dng").write_text("old")
    (out / "keep.txt").write_text("mine")
    write_white_capture(simulate_white("hex", 9.5, sensor_shape=(60, 60)), out)
    assert (out / "keep.txt").read_text() == "mine" and (out / "white.dng").stat().st_size > 100
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("args,message", [
    (["--pitch", "1e300", "--sensor-shape", "90x90"], "pitch must be a finite number"),
    (["--pitch", "9", "--offset=1e300,0", "--sensor-shape", "90x90"], "offset row must be a finite number"),
    (["--pitch", "9", "--sensor-shape", "100000000x100000000"], "outside 1 .."),
])
def test_absurd_grid_parameters_are_one_line_errors(tmp_path, args, message):
    from click.testing import CliRunner

    from lfcl.cli import cli

    result = CliRunner().invoke(cli, ["calibrate", *args, "-o", str(tmp_path / "cal.json")])
    assert result.exit_code == 1 and message in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "cal.json").exists()
