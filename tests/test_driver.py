"""The one demosaic entry point (lfcl/demosaic/driver.py) and the typed lens grid (lfcl/grid/model.py)."""

from __future__ import annotations

import numpy as np
import pytest

import lfcl.demosaic.auto
from lfcl.demosaic.driver import demosaic_grid, resolve_auto
from lfcl.grid import calibration_from_pitch, save_calibration
from lfcl.grid.model import AlignedGrid, ResampledGrid, lens_grid
from lfcl.io.raw import Mosaic
from lfcl.noise.model import NoiseEstimate
from lfcl.pipeline.stages import Demosaic, Grid, grid_words
from lfcl.sim.geometry import GridGeometry

#: What the stages said before the typed grid (lfcl/pipeline/stages.py grid_words, lfcl/demosaic/resampled.py
#: GRID_METHOD_NAMES), copied here as the reference the grid must keep.
OLD_RESAMPLED_METHOD_NAMES = ("auto", "malvar", "admm-uv", "admm-st", "admm-uvst")
ALL_METHODS = ("auto", "malvar", "admm-uv", "admm-st", "admm-uvst", "linear4d", "admm-uv-xc", "admm-uvst-xc",
               "admm-epi")
HEX_REFUSAL = ("method 'linear4d' does not run on the hexagonal lens grid: the resampling path (rotated, "
               "non-integer-pitch, hexagonal grids) takes auto, malvar, admm-uv, admm-st, admm-uvst")
NOISE = NoiseEstimate(gain=0.0, floor=1e-4, sigma=0.01, source="test")  # sigma 0.01 at every level


def old_grid_words(geometry: dict) -> str:
    if geometry.get("grid") != "resampled":
        return "aligned square"
    if geometry.get("packing") == "hex":
        return "hexagonal"
    return f"{', '.join(geometry.get('features') or ['non-aligned'])} square"


def gridded_of(tmp_path, packing, pitch, rotation=0.0, offset=(0.0, 0.0), shape=(60, 66)):
    """The Grid stage's result for a calibration of these grid parameters (no white image), on a flat raw."""
    path = save_calibration(calibration_from_pitch(pitch, shape, packing, rotation, offset), tmp_path / "cal.json")
    mosaic = Mosaic(data=np.full(shape, 0.3, np.float32), pattern="GRBG", source="flat")
    return Grid(calibration=path)(mosaic)


@pytest.mark.parametrize("packing, pitch, rotation, kind", [
    ("square", 6, 0.0, "aligned-square"),
    ("square", 6.4, 0.7, "resampled"),  # rotated, non-integer pitch
    ("hex", 6.4, 0.7, "resampled"),
])
def test_the_typed_grid_keeps_the_words_and_methods(tmp_path, packing, pitch, rotation, kind):
    gridded = gridded_of(tmp_path, packing, pitch, rotation, (0.3, -0.2) if kind == "resampled" else (0.0, 0.0))
    geometry = gridded.metadata["geometry"]
    grid = gridded.grid
    assert geometry["grid"] == grid.kind == kind
    assert grid.words == grid_words(geometry) == old_grid_words(geometry)
    assert grid.methods == (OLD_RESAMPLED_METHOD_NAMES if kind == "resampled" else ALL_METHODS)
    assert grid.lenses == tuple(geometry["lenses"]) == gridded.lenses and grid.pitch == tuple(geometry["pitch"])
    if kind == "resampled":
        assert grid.sampling is gridded.sampling and not grid.safety_net
        assert grid.words == ("hexagonal" if packing == "hex" else "rotated, non-integer-pitch square")
    else:
        assert grid.origin == gridded.origin and grid.safety_net and grid.words == "aligned square"
    # the record the outputs keep is the grid's own, and reads back to the same grid
    assert lens_grid(geometry, sampling=gridded.sampling).geometry(geometry["from"]) == geometry


def test_descriptions_without_their_solver_data():
    assert ResampledGrid(None, "hex").words == "hexagonal"
    assert ResampledGrid(None, "square").words == "non-aligned square"
    assert lens_grid({"grid": "resampled", "packing": "square", "features": ["sub-pixel-offset"]}).words \
        == "sub-pixel-offset square"
    with pytest.raises(ValueError, match="lens grid 'hexagonal' is not one it takes"):
        lens_grid({"grid": "hexagonal"})
    mosaic = np.zeros((18, 18), np.float32)
    with pytest.raises(ValueError, match="needs its sampling model"):
        demosaic_grid(mosaic, "GRBG", ResampledGrid(None, "hex"), "malvar")
    with pytest.raises(ValueError, match="needs its pitch"):
        demosaic_grid(mosaic, "GRBG", AlignedGrid(None), "malvar")
    with pytest.raises(ValueError, match="whole number or a pair"):
        AlignedGrid(9.5)
    with pytest.raises(ValueError, match="holds 2x2 lenses of 9x9, but the lens grid has 3x2"):
        demosaic_grid(mosaic, "GRBG", AlignedGrid(9, lenses=(3, 2)), "malvar")
    with pytest.raises(ValueError, match="must be an AlignedGrid or a ResampledGrid"):
        demosaic_grid(mosaic, "GRBG", (9, 9), "malvar")


def test_a_method_the_resampled_grid_does_not_take_is_the_same_one_line(tmp_path):
    hexagonal = ResampledGrid.of(GridGeometry((45, 51), "hex", 5.6, -0.6, (0.1, 0.3)), "GRBG")
    raw = np.full((45, 51), 0.3, np.float32)
    with pytest.raises(ValueError) as info:
        demosaic_grid(raw, "GRBG", hexagonal, "linear4d")
    assert str(info.value) == HEX_REFUSAL
    gridded = gridded_of(tmp_path, "hex", 6.4, 0.7, (0.3, -0.2))
    with pytest.raises(ValueError) as info:
        Demosaic("linear4d")(gridded)
    assert str(info.value) == f"Demosaic: {HEX_REFUSAL}"
    for options, words in (({"start": "linear4d"}, "start linear4d needs an aligned square lens grid"),
                           ({"skip_flat": True}, "skipping flat lenses needs an aligned square lens grid")):
        with pytest.raises(ValueError, match=words):
            demosaic_grid(raw, "GRBG", hexagonal, "admm-uv", **options)


def _aligned_case():
    from lfcl.sim import simulate

    capture = simulate("charts", lenses=(24, 24), lux=12, seed=0)  # auto's smallest frame for a prior
    return capture.normalised_raw(), capture.pattern, AlignedGrid(9)


def _resampled_case():
    geometry = GridGeometry((100, 112), "hex", 5.6, -0.6, (0.1, 0.3))  # 18x19 lenses: auto's smallest for a prior
    rng = np.random.default_rng(0)
    raw = (0.3 * geometry.white_expected("GRBG", 1.0) + 0.01 * rng.standard_normal((100, 112))).astype(np.float32)
    return raw, "GRBG", ResampledGrid.of(geometry, "GRBG")


@pytest.mark.parametrize("case", [_aligned_case, _resampled_case], ids=["aligned", "resampled"])
def test_auto_is_resolved_once(monkeypatch, case):
    mosaic, pattern, grid = case()
    calls = []
    choose = lfcl.demosaic.auto.choose

    def counting(*args, **kwargs):
        calls.append(args)
        return choose(*args, **kwargs)

    monkeypatch.setattr(lfcl.demosaic.auto, "choose", counting)
    result = demosaic_grid(mosaic, pattern, grid, "auto", noise=NOISE, iterations=2)
    rule = isinstance(grid, AlignedGrid)  # a resampled grid runs Malvar without consulting the rule
    assert len(calls) == rule
    resolved = resolve_auto(mosaic, pattern, grid, noise=NOISE)
    assert len(calls) == 2 * rule and result.parameters["auto"] == resolved.record
    assert result.method == resolved.method == resolved.record["method"] and resolved.method in grid.methods
    assert ("safety_net" in result.parameters) == (grid.safety_net and resolved.method != "malvar")
    if isinstance(grid, ResampledGrid):
        assert (resolved.method, resolved.start, resolved.record["lens_ratio"]) == ("malvar", None, None)
        assert "every prior of the resampled solver" in resolved.record["reason"]
    else:
        assert resolved.record["lens_ratio"] is not None
    # auto is its pick run at the picked strength and start
    direct = demosaic_grid(mosaic, pattern, grid, resolved.method, noise=NOISE, iterations=2,
                           strength=resolved.strength, **({"start": resolved.start} if grid.safety_net else {}))
    np.testing.assert_array_equal(result.planes, direct.planes)
    assert result.lightfield.shape[2:] == (*grid.pitch, 3) and result.shape.planes_shape == result.planes.shape


def test_a_given_disparity_map_is_checked_and_solved_with(rng, monkeypatch):
    from lfcl.depth import estimate_disparity

    mosaic = (0.3 + 0.05 * rng.standard_normal((6 * 9, 7 * 9))).astype(np.float32)
    depth = estimate_disparity(mosaic, "GRBG", 9, noise=NOISE)
    given = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=NOISE, iterations=2,
                          disparity=depth)
    assert given.parameters["disparity"]["source"] == "given (the depth output's estimate)"
    assert given.parameters["disparity"]["step"] == depth.step and "disparity" not in given.part_seconds
    # the same map estimated by admm-epi itself (its options made equal to the given one's): the same solve
    own = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=NOISE, iterations=2)
    assert own.parameters["disparity"]["source"] == "estimated for admm-epi" and "disparity" in own.part_seconds
    import lfcl.solvers.epi as epi

    monkeypatch.setitem(epi.EPI_DEPTH_OPTIONS, "step", depth.step)
    same = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=NOISE, iterations=2)
    np.testing.assert_array_equal(given.planes, same.planes)
    small = estimate_disparity(mosaic[:5 * 9], "GRBG", 9, noise=NOISE)
    with pytest.raises(ValueError, match="the disparity map given has 5x7 lenses, this raw 6x7"):
        demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=NOISE, iterations=1, disparity=small)


def test_admm_epi_estimates_its_disparity_once_for_the_start_and_the_solve(rng, monkeypatch):
    """The guarded start reads admm-epi's disparity (its one-colour lenses); the solve takes the same map."""
    import lfcl.depth
    from lfcl.depth import estimate_disparity

    calls = []

    def counted(*args, **kwargs):
        calls.append(kwargs)
        return estimate_disparity(*args, **kwargs)

    monkeypatch.setattr(lfcl.depth, "estimate_disparity", counted)
    mosaic = (0.3 + 0.05 * rng.standard_normal((6 * 9, 7 * 9))).astype(np.float32)
    result = demosaic_grid(mosaic, "GRBG", AlignedGrid((9, 9)), "admm-epi", noise=NOISE, start="guarded", iterations=2)
    assert len(calls) == 1
    assert "one_colour_lenses" in result.parameters["start_guard"]
    assert result.parameters["disparity"]["source"] == "estimated for admm-epi" and "disparity" in result.part_seconds


def test_a_disparity_map_is_refused_on_a_resampled_grid(tmp_path):
    gridded = gridded_of(tmp_path, "hex", 9.4)
    with pytest.raises(ValueError, match="a disparity map is for aligned square lens grids"):
        demosaic_grid(gridded.data, "GRBG", gridded.grid, "admm-uv", noise=NOISE, disparity=object())
