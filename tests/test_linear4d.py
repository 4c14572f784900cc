"""linear4d: kernel vs numpy twin, twin vs a direct per-pixel evaluation, the fitting code, the shipped model."""

from __future__ import annotations

import inspect
import json
import zlib

import numpy as np
import pyopencl as cl
import pytest
from fit_linear4d import (  # research/, on sys.path through conftest.py
    DEFAULT_LAYOUT,
    DEFAULT_LUX,
    NormalEquations,
    accumulate,
    fit,
    main,
    solve,
    tap_layout,
)

from lfcl.layout import PATTERNS
from lfcl.ops.linear4d import (
    CLASSES,
    Linear4d,
    Linear4dModel,
    cfa_classes,
    fold_missing_lenses,
    linear4d,
    linear4d_np,
    load_model,
    pixel_phases,
    row_tables,
    select_coefficients,
    tap_colours,
    tap_offsets,
    tap_samples,
    valid_taps,
)

ORIGINS = [(0, 0), (1, 0), (0, 1), (1, 1)]
TAPS = tap_layout(3, 0, True)  # the shipped layout: 7x7 in the lens and the same (u, v) in 8 neighbours


def _case(seed_text: str, lenses, pitch=(9, 9), taps=TAPS):
    rng = np.random.default_rng(zlib.crc32(seed_text.encode()))
    S, T = lenses
    U, V = pitch
    mosaic = rng.random((S * U, T * V), dtype=np.float32)
    coefficients = rng.normal(size=(U, V, 4, 3, len(taps))).astype(np.float32)
    return mosaic, coefficients


# --- direct evaluation, written from the rules of lfcl/ops/linear4d.py without its helpers ----------------------


def _direct(mosaic, pattern, pitch, taps, coefficients, origin):
    """One pixel and one tap at a time: colour letters from the pattern string, lens mirror by hand."""
    U, V = pitch
    H, W = mosaic.shape
    S, T = H // U, W // V

    def colour(row, col):  # sensor coordinates
        return pattern[2 * ((row + origin[0]) % 2) + (col + origin[1]) % 2]

    def lens(i, d, n):
        j = i + d
        if j < 0 or j >= n:
            j = i - d
        return j if 0 <= j < n else None

    out = np.zeros((3, H, W))
    for row in range(H):
        for col in range(W):
            s, u, t, v = row // U, row % U, col // V, col % V
            own, right = colour(row, col), colour(row, col + 1)
            cls = {"R": 0, "B": 3}.get(own, 1 if right == "R" else 2)
            for k, (ds, dt, du, dv) in enumerate(taps):
                if not (0 <= u + du < U and 0 <= v + dv < V):
                    continue
                ss, tt = lens(s, ds, S), lens(t, dt, T)
                if ss is None or tt is None:
                    continue
                value = float(mosaic[ss * U + u + du, tt * V + v + dv])
                for c in range(3):
                    out[c, row, col] += float(coefficients[u, v, cls, c, k]) * value
    return out


@pytest.mark.parametrize("lenses, pitch, pattern, origin", [
    ((2, 3), (5, 5), "GRBG", (0, 0)),
    ((3, 2), (4, 5), "BGGR", (1, 0)),   # even u pitch: neighbouring lens rows keep their parity
    ((1, 2), (5, 3), "RGGB", (1, 1)),   # one lens row: the s taps read 0
])
def test_numpy_twin_matches_direct_evaluation(lenses, pitch, pattern, origin):
    taps = np.array([(0, 0, 0, 0), (0, 0, -1, 2), (0, 0, 2, -1), (1, 0, 0, 0), (-1, 1, 1, 0), (0, -1, 0, -1),
                     (1, 1, -1, -1), (-1, 0, 0, 1)])
    mosaic, coefficients = _case(f"direct{lenses}{pitch}", lenses, pitch, taps)
    got = linear4d_np(mosaic, pattern, pitch, taps, coefficients, origin)
    # with one lens row the twin first folds the s taps' weight onto in-lens taps (tested below)
    want = _direct(mosaic, pattern, pitch, taps.tolist(), fold_missing_lenses(coefficients, pitch, taps, lenses), origin)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("lenses", [(1, 3), (3, 1), (1, 1)])
def test_a_single_lens_row_or_column_keeps_flat_colours(lenses):
    pitch = (9, 9)
    rng = np.random.default_rng(3)
    flat = _keep_flat_colours(rng.normal(size=(9, 9, 4, 3, len(TAPS))), pitch, TAPS)
    folded = fold_missing_lenses(flat, pitch, TAPS, lenses)
    gone = ((TAPS[:, 0] != 0) & (lenses[0] < 2)) | ((TAPS[:, 1] != 0) & (lenses[1] < 2))
    assert np.all(folded[..., gone] == 0) and gone.any()
    np.testing.assert_allclose(_flat_colour_sums(folded.astype(np.float64), pitch, TAPS),
                               np.broadcast_to(np.eye(3), (9, 9, 4, 3, 3)), atol=1e-5)
    assert fold_missing_lenses(flat, pitch, TAPS, (2, 2)) is flat


def test_cfa_classes_follow_the_pattern():
    assert cfa_classes("RGGB").tolist() == [[0, 1], [2, 3]]
    assert cfa_classes("GRBG").tolist() == [[1, 0], [3, 2]]
    assert cfa_classes("BGGR", (1, 1)).tolist() == [[0, 1], [2, 3]]  # origin (1, 1) of BGGR is RGGB
    assert cfa_classes("GBRG", (0, 1)).tolist() == [[3, 2], [1, 0]]


def test_valid_taps_drop_what_leaves_the_lens():
    valid = valid_taps((9, 9), TAPS)
    k = TAPS.tolist().index([0, 0, -3, 0])
    assert not valid[:3, :, k].any() and valid[3:, :, k].all()
    k = TAPS.tolist().index([1, 1, 0, 0])
    assert valid[:, :, k].all()


def test_tap_samples_keep_cfa_colour_at_the_image_border():
    """A mirrored neighbour lens (s - ds) lies an even number of rows away: same CFA colour."""
    pitch = (9, 9)
    rows, cols = np.indices((27, 36))  # 3 x 4 lenses
    channel = (rows % 2) * 2 + cols % 2  # a mosaic whose value is its Bayer cell
    taps = np.array([(ds, dt, 0, 0) for ds in (-1, 0, 1) for dt in (-1, 0, 1)])
    samples = tap_samples(channel.astype(np.float32), pitch, taps)
    for k, (ds, dt, _, _) in enumerate(taps.tolist()):
        expected = ((rows + 9 * ds) % 2) * 2 + (cols + 9 * dt) % 2
        np.testing.assert_array_equal(samples[k], expected)


# --- kernel vs numpy twin -------------------------------------------------------------------------------------


@pytest.mark.parametrize("lenses", [(3, 5), (1, 2), (2, 1), (4, 7)], ids=lambda s: f"{s[0]}x{s[1]}lenses")
@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"o{o[0]}{o[1]}")
@pytest.mark.parametrize("pattern", PATTERNS)
def test_kernel_matches_numpy(runtime, pattern, origin, lenses):
    mosaic, coefficients = _case(f"{pattern}{origin}{lenses}", lenses)
    op = Linear4d(runtime, mosaic.shape, pattern, (9, 9), TAPS, coefficients, origin)
    got = op.forward(runtime.to_device(mosaic)).get()
    want = linear4d_np(mosaic, pattern, (9, 9), TAPS, coefficients, origin)
    assert got.shape == (3, *mosaic.shape) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5 * float(np.abs(want).max()))


def test_kernel_other_pitch(runtime):
    """An even pitch and another tap layout go through the same kernel."""
    taps = tap_layout(1, 1, False)
    mosaic, coefficients = _case("pitch6", (3, 4), (6, 6), taps)
    op = Linear4d(runtime, mosaic.shape, "GBRG", (6, 6), taps, coefficients, (1, 0))
    want = linear4d_np(mosaic, "GBRG", (6, 6), taps, coefficients, (1, 0))
    np.testing.assert_allclose(op.forward(runtime.to_device(mosaic)).get(), want, rtol=0, atol=1e-4)


def test_kernel_writes_nothing_past_the_planes(runtime):
    mosaic, coefficients = _case("guard", (2, 3))
    H, W = mosaic.shape
    guard = 4096
    mf = cl.mem_flags
    src = cl.Buffer(runtime.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=mosaic)
    host_out = np.full(3 * H * W + guard, -7.0, dtype=np.float32)
    dst = cl.Buffer(runtime.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=host_out)
    op = Linear4d(runtime, mosaic.shape, "GRBG", (9, 9), TAPS, coefficients)
    runtime.launch("linear4d", "linear4d", (4, H + 3), src, dst, op.tables.data, op.offsets.data,
                   np.int32(len(TAPS)), np.int32(H), np.int32(W), defines=op.defines)
    cl.enqueue_copy(runtime.queue, host_out, dst)
    runtime.queue.finish()
    assert np.all(host_out[3 * H * W:] == -7.0)
    want = linear4d_np(mosaic, "GRBG", (9, 9), TAPS, coefficients)
    np.testing.assert_allclose(host_out[:3 * H * W].reshape(3, H, W), want, rtol=0, atol=2e-5 * np.abs(want).max())


def test_forward_checks_shapes_and_writes_into_out(runtime):
    mosaic, coefficients = _case("out", (2, 2))
    op = Linear4d(runtime, mosaic.shape, "RGGB", (9, 9), TAPS, coefficients)
    out = runtime.zeros((3, *mosaic.shape))
    assert op.forward(runtime.to_device(mosaic), out=out) is out
    with pytest.raises(ValueError, match="mosaic must be float32"):
        op.forward(runtime.to_device(mosaic[:9]))
    with pytest.raises(ValueError, match="whole number"):
        Linear4d(runtime, (10, 18), "RGGB", (9, 9), TAPS, coefficients)
    with pytest.raises(ValueError, match="coefficients must have shape"):
        Linear4d(runtime, mosaic.shape, "RGGB", (9, 9), TAPS, coefficients[..., :-1])
    with pytest.raises(ValueError, match="cross-lens"):
        Linear4d(runtime, mosaic.shape, "RGGB", (9, 9), [(2, 0, 0, 0)], coefficients[..., :1])


def test_row_tables_and_offsets_layout():
    _, coefficients = _case("tables", (2, 2))
    tables = row_tables(coefficients, (9, 9), TAPS, "GRBG", (0, 1))
    assert tables.shape == (18, 3, len(TAPS), 18 + 16)
    u, v, cls = pixel_phases((18, 18), (9, 9), "GRBG", (0, 1))
    valid = valid_taps((9, 9), TAPS)
    for row, col in [(0, 0), (4, 13), (17, 9), (10, 17)]:
        want = coefficients[u[row, col], v[row, col], cls[row, col]] * valid[u[row, col], v[row, col]]
        np.testing.assert_array_equal(tables[row, :, :, col], want)
    np.testing.assert_array_equal(tables[:, :, :, 18:], tables[:, :, :, :16])  # the 16-lane extension repeats
    offsets = tap_offsets((9, 9), TAPS)
    k = TAPS.tolist().index([-1, 1, 0, 0])
    assert offsets[k].tolist() == [-9, 9, 9, -9]


# --- the fitting code -----------------------------------------------------------------------------------------


def _keep_flat_colours(coefficients, pitch, taps):
    """Shift each phase's taps so that every output colour's taps of input colour j sum to [j == colour]."""
    colours = tap_colours(pitch, taps)
    valid = valid_taps(pitch, taps)
    out = coefficients.copy()
    for u, v, cls, c in np.ndindex(*coefficients.shape[:4]):
        for j in range(3):
            pick = valid[u, v] & (colours[cls] == j)
            out[u, v, cls, c, pick] += (float(j == c) - out[u, v, cls, c, pick].sum()) / pick.sum()
    return out


def _flat_colour_sums(coefficients, pitch, taps):
    """``[..., 3 output, 3 input]``: the sum of each output's coefficients over each input colour's taps."""
    colours = tap_colours(pitch, taps)  # [4, NT]
    masks = np.stack([colours == j for j in range(3)], axis=-1).astype(np.float64)  # [4, NT, 3]
    return np.einsum("...uvzck,zkj->...uvzcj", coefficients * valid_taps(pitch, taps)[:, :, None, None, :], masks)


@pytest.mark.parametrize("keep_flat", [False, True])
def test_fit_recovers_a_known_linear_filter(keep_flat):
    """Truth made by a known filter of random mosaics: the normal equations give it back."""
    pitch, taps = (5, 5), tap_layout(1, 0, True)
    rng = np.random.default_rng(7)
    known = rng.normal(size=(5, 5, 4, 3, len(taps))) * valid_taps(pitch, taps)[:, :, None, None, :]
    if keep_flat:
        known = _keep_flat_colours(known, pitch, taps)
    equations = NormalEquations.zeros(pitch, len(taps))
    for _ in range(3):
        mosaic = rng.random((8 * 5, 8 * 5))
        truth = linear4d_np(mosaic, "GRBG", pitch, taps, known).astype(np.float64)
        accumulate(equations, mosaic, truth, pitch, taps, "GRBG")
    assert equations.samples.min() == 3 * 16
    fitted = solve(equations, pitch, taps, ridge=1e-12, keep_flat_colours=keep_flat)
    np.testing.assert_allclose(fitted, known, atol=1e-4)


def test_tap_colours():
    taps = np.array([(0, 0, 0, 0), (0, 0, 0, 1), (0, 1, 0, 0), (1, 1, 0, 0), (0, 0, 1, 1), (1, 0, 0, 0)])
    # R pixel: itself R, right G, the next lens's same (u, v) 9 columns on: G, diagonal lens: B
    assert tap_colours((9, 9), taps).tolist() == [[0, 1, 1, 2, 2, 1], [1, 0, 0, 1, 1, 2],
                                                  [1, 2, 2, 1, 1, 0], [2, 1, 1, 0, 0, 1]]
    assert tap_colours((8, 8), taps)[0].tolist() == [0, 1, 0, 0, 2, 0]  # even pitch: same parity next lens


def test_normal_equations_match_a_direct_least_squares():
    """Grouping by phase, the ridge term and the flat-colour constraint against np.linalg.lstsq on the
    stacked design matrix (the constraint through its null space)."""
    from scipy.linalg import null_space

    pitch, taps, ridge = (5, 5), tap_layout(1, 0, False), 1e-2
    rng = np.random.default_rng(8)
    mosaic, truth = rng.random((20, 30)), rng.random((3, 20, 30))
    equations = NormalEquations.zeros(pitch, len(taps))
    accumulate(equations, mosaic, truth, pitch, taps, "BGGR")
    free = solve(equations, pitch, taps, ridge, keep_flat_colours=False)
    constrained = solve(equations, pitch, taps, ridge, keep_flat_colours=True)
    samples = tap_samples(mosaic, pitch, taps)
    colours = tap_colours(pitch, taps)
    u, v, cls = pixel_phases(mosaic.shape, pitch, "BGGR")
    for uu, vv, cc in [(0, 0, 0), (2, 3, 1), (4, 4, 3), (1, 0, 2)]:
        pick = (u == uu) & (v == vv) & (cls == cc)
        keep = np.flatnonzero(valid_taps(pitch, taps)[uu, vv])
        dropped = np.setdiff1d(np.arange(len(taps)), keep)
        X, Y = samples[keep][:, pick].T, truth[:, pick].T
        root = np.sqrt(ridge * np.trace(X.T @ X) / len(keep))
        want = np.linalg.lstsq(np.vstack([X, root * np.eye(len(keep))]),
                               np.vstack([Y, np.zeros((len(keep), 3))]), rcond=None)[0].T
        np.testing.assert_allclose(free[uu, vv, cc][:, keep], want, rtol=1e-8, atol=1e-10)
        C = np.array([colours[cc, keep] == j for j in range(3)], dtype=np.float64)
        N = null_space(C)
        for c in range(3):
            w0 = np.linalg.lstsq(C, np.eye(3)[c], rcond=None)[0]
            z = np.linalg.lstsq(np.vstack([X @ N, root * N]), np.concatenate([Y[:, c] - X @ w0, -root * w0]),
                                rcond=None)[0]
            np.testing.assert_allclose(constrained[uu, vv, cc, c, keep], w0 + N @ z, rtol=1e-7, atol=1e-9)
        assert np.all(free[uu, vv, cc][:, dropped] == 0) and np.all(constrained[uu, vv, cc][:, dropped] == 0)
    np.testing.assert_allclose(_flat_colour_sums(constrained, pitch, taps), np.broadcast_to(np.eye(3), (5, 5, 4, 3, 3)),
                               atol=1e-12)


def test_fit_is_deterministic_and_the_script_writes_a_loadable_model(tmp_path):
    layout = {"in_lens_radius": 1, "cross_radius": 0, "diagonal_lenses": True}
    kwargs = {"lenses": (4, 4), "pitch": (9, 9), "lux_levels": (50.0, 4.0), "scenes": 1, "seed_base": 3,
              "layout": layout, "ridge": 1e-3}
    first, second = fit(**kwargs), fit(**kwargs)
    np.testing.assert_array_equal(first.coefficients, second.coefficients)
    assert first.coefficients.shape == (2, 9, 9, 4, 3, 17)
    assert first.relative_noise[0] < first.relative_noise[1]  # sets sorted: 50 lux (less noise) first
    path = tmp_path / "model.npz"
    main(["-o", str(path), "--lenses", "4x4", "--scenes", "1", "--seed-base", "3", "--lux", "50,4",
          "--in-lens-radius", "1", "--cross-radius", "0", "--ridge", "1e-3"])
    loaded = load_model(path)
    np.testing.assert_array_equal(loaded.coefficients, first.coefficients)
    np.testing.assert_array_equal(loaded.taps, first.taps)
    assert loaded.metadata["training_scenes"]["seeds"] == [3]
    assert loaded.metadata["lux"] == [50.0, 4.0]
    assert loaded.metadata["tap_layout_arguments"] == layout


# --- the shipped coefficients ---------------------------------------------------------------------------------


def test_shipped_model_loads_and_is_finite():
    model = load_model()
    meta = model.metadata
    assert model.pitch == (9, 9)
    assert np.all(np.isfinite(model.coefficients))
    assert model.coefficients.shape[1:5] == (9, 9, len(CLASSES), 3)
    assert np.all(np.diff(model.relative_noise) > 0)
    assert len(meta["lux"]) == len(model.relative_noise)
    # made by the documented command with its defaults (the script was lfcl/bench/fit_linear4d.py when the
    # shipped file was fitted; it moved to research/ unchanged)
    assert meta["command"] in ("python -m lfcl.bench.fit_linear4d -o lfcl/data/linear4d.npz",
                               "python research/fit_linear4d.py -o lfcl/data/linear4d.npz")
    defaults = inspect.signature(fit).parameters
    seeds = list(range(defaults["seed_base"].default, defaults["seed_base"].default + defaults["scenes"].default))
    assert meta["training_scenes"]["seeds"] == seeds
    assert meta["lux"] == sorted(DEFAULT_LUX, reverse=True)
    assert meta["ridge"] == defaults["ridge"].default and meta["tap_layout_arguments"] == DEFAULT_LAYOUT
    # the taps are the layout the recorded fitting arguments make
    layout = meta["tap_layout_arguments"]
    np.testing.assert_array_equal(model.taps, tap_layout(layout["in_lens_radius"], layout["cross_radius"],
                                                         layout["diagonal_lenses"]))
    invalid = ~valid_taps(model.pitch, model.taps)
    assert np.all(model.coefficients.transpose(0, 3, 4, 1, 2, 5)[..., invalid] == 0)
    sums = _flat_colour_sums(model.coefficients.astype(np.float64), model.pitch, model.taps)
    np.testing.assert_allclose(sums, np.broadcast_to(np.eye(3), sums.shape), atol=1e-5)
    json.dumps(meta)  # plain JSON metadata


@pytest.mark.parametrize("pattern", PATTERNS)
def test_shipped_model_keeps_a_flat_colour_field_on_the_device(runtime, pattern):
    """A uniform colour (R, G, B) = (0.2, 0.5, 0.3) comes back as itself at every pixel, borders included."""
    model = load_model()
    rgb = np.array([0.2, 0.5, 0.3], np.float32)
    H, W = 3 * 9, 4 * 9
    rows, cols = np.indices((H, W))
    letters = np.array(list(pattern)).reshape(2, 2)[rows % 2, cols % 2]
    mosaic = np.select([letters == "R", letters == "G"], [rgb[0], rgb[1]], rgb[2]).astype(np.float32)
    for coefficients in model.coefficients[[0, -1]]:
        op = Linear4d(runtime, (H, W), pattern, (9, 9), model.taps, coefficients)
        got = op.forward(runtime.to_device(mosaic)).get()
        np.testing.assert_allclose(got, np.broadcast_to(rgb[:, None, None], got.shape), atol=1e-5)


def test_shipped_model_beats_malvar_on_a_held_out_training_scene():
    """A scene of the training generator that no set saw (seed 99): linear4d beats Malvar's PSNR."""
    from training_scenes import training_planes

    from lfcl.layout import exchange_to_planes
    from lfcl.ops.malvar import malvar_np
    from lfcl.sim import render_planes, simulate

    radiance = render_planes(training_planes((8, 8), 99), (8, 8), (9, 9))
    model = load_model()
    assert 99 not in model.metadata["training_scenes"]["seeds"]
    capture = simulate(lightfield=radiance, lux=12.0, seed=99)
    mosaic, truth = capture.normalised_raw(), exchange_to_planes(capture.truth)
    sigma = float(np.sqrt(capture.sensor.noise_profile()[0] * mosaic.mean() + capture.sensor.noise_profile()[1]))
    coefficients = select_coefficients(model, sigma / float(mosaic.mean()))
    ours = linear4d_np(mosaic, capture.pattern, (9, 9), model.taps, coefficients)
    theirs = malvar_np(mosaic, capture.pattern)
    assert np.mean((ours - truth) ** 2) < 0.8 * np.mean((theirs - truth) ** 2)


def test_select_coefficients_interpolates_in_log_noise():
    U = V = 3
    taps = tap_layout(1, -1, True)
    sets = np.stack([np.full((U, V, 4, 3, len(taps)), value, np.float32) for value in (1.0, 3.0)])
    model = Linear4dModel((U, V), taps, sets, np.array([0.01, 0.04]), {})
    assert np.all(select_coefficients(model, 0.001) == 1.0)
    assert np.all(select_coefficients(model, 1.0) == 3.0)
    np.testing.assert_allclose(select_coefficients(model, 0.02), 2.0, rtol=1e-6)  # halfway in log
    assert np.all(select_coefficients(model, float("inf")) == 3.0)  # no signal: the noisiest set
    with pytest.raises(ValueError):
        select_coefficients(model, float("nan"))
    with pytest.raises(ValueError, match="increasing"):
        Linear4dModel((U, V), taps, sets, np.array([0.04, 0.01]), {})


def test_public_function_checks_the_pitch(runtime):
    with pytest.raises(ValueError, match="fitted for 9x9"):
        linear4d(runtime, np.ones((14, 14), np.float32), "GRBG", (7, 7))


def test_public_function_matches_numpy_with_a_given_noise(runtime):
    from lfcl.noise.model import NoiseEstimate

    model = load_model()
    mosaic, _ = _case("public", (2, 3))
    mosaic *= 0.2
    noise = NoiseEstimate(gain=1e-4, floor=1e-6, sigma=0.004, source="test")
    got = linear4d(runtime, mosaic, "GBRG", (9, 9), origin=(1, 0), noise=noise)
    coefficients = select_coefficients(model, 0.004 / float(mosaic.astype(np.float64).mean()))
    want = linear4d_np(mosaic, "GBRG", (9, 9), model.taps, coefficients, (1, 0))
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-5 * float(np.abs(want).max()))
    np.testing.assert_array_equal(linear4d(runtime, mosaic, "GBRG", 9, origin=(1, 0), noise=noise), got)  # 9: 9x9


def test_demosaic_lightfield_runs_linear4d(runtime):
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.noise.model import NoiseEstimate
    from lfcl.sim import simulate

    capture = simulate("charts", lenses=(4, 4), lux=12.0, seed=0)
    mosaic = capture.normalised_raw()
    noise = NoiseEstimate(gain=1e-4, floor=1e-6, sigma=0.005, source="test")
    result = demosaic_grid(mosaic, capture.pattern, AlignedGrid((9, 9)), "linear4d", noise=noise, safety_net=False)
    assert result.method == "linear4d" and result.iterations == 0 and result.noise is noise
    np.testing.assert_array_equal(result.planes, linear4d(runtime, mosaic, capture.pattern, (9, 9), noise=noise))
    estimated = demosaic_grid(mosaic, capture.pattern, AlignedGrid((9, 9)), "linear4d")  # noise from the raw
    assert estimated.noise is not None and estimated.noise.source == "raw"
