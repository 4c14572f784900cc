"""The sampling model of any lens grid (lfcl/grid/resampling.py) and the sparse device maps (lfcl/ops/resample.py)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
from conftest import relative_dot_error

from lfcl.grid.resampling import sampling_model
from lfcl.layout import channel_map
from lfcl.ops.cfa import cfa_sample_np
from lfcl.ops.resample import SparseOperator, multiply, sparse_adjoint_np, sparse_apply_np
from lfcl.sim.geometry import GridGeometry

GRIDS = {
    "square": GridGeometry((95, 103), "square", 9.0, 0.0, (0.0, 0.0)),
    "rotated": GridGeometry((97, 101), "square", 9.4, 0.7, (0.3, -0.2)),
    "hex": GridGeometry((91, 107), "hex", 9.4, 0.7, (0.3, -0.2)),
    "hex-coarse": GridGeometry((61, 67), "hex", 10.3, -0.5, (-0.2, 0.4)),
}
GRIDS_BY_SHAPE = {g.sensor_shape: g for g in GRIDS.values()}


@pytest.fixture(scope="module", params=sorted(GRIDS))
def model(request):
    return sampling_model(GRIDS[request.param], "GRBG")


# --- the sampling model ---------------------------------------------------------

def test_aligned_integer_grid_is_the_exact_slicing():
    # pitch 9, no rotation or offset: every regular sample is a sensor pixel (docs/layout.md)
    geometry = GridGeometry((72, 81), "square", 9.0)
    m = sampling_model(geometry, "GRBG", response=np.ones((72, 81)))
    assert m.exact and m.lens_origin == (0, 0) and m.lenses == (8, 9) and m.views == (9, 9)
    x = np.random.default_rng(0).random(m.planes_shape)
    A = m.forward_matrix()
    assert A.shape == (72 * 81, x.size) and A.nnz == 72 * 81  # one tap of weight 1 a pixel
    np.testing.assert_array_equal(A @ x.ravel(), cfa_sample_np(x, "GRBG").ravel())
    M = m.resample_matrix()
    image = np.random.default_rng(1).random(72 * 81)
    np.testing.assert_array_equal(M @ image, image)


def test_views_default_to_the_rounded_pitch():
    assert sampling_model(GridGeometry((80, 80), "square", 9.4), "RGGB").views == (9, 9)
    assert sampling_model(GridGeometry((80, 80), "hex", 10.6), "RGGB").views == (11, 11)
    assert sampling_model(GridGeometry((80, 80), "hex", 10.6), "RGGB", views=7).views == (7, 7)


def test_lens_block_is_whole_lenses_and_hex_starts_on_an_even_row(model):
    H, W = model.sensor_shape
    rows, cols = model.sample_positions()
    assert rows.min() >= -0.5 and rows.max() <= H - 0.5 and cols.min() >= -0.5 and cols.max() <= W - 0.5
    S, T = model.lenses
    i0, j0 = model.lens_origin
    top = 2 if model.grid.packing == "hex" else 1  # a hex block starts on an even row
    for grown in ((i0 - top, j0, S + top, T), (i0, j0, S + 1, T), (i0, j0 - 1, S, T + 1), (i0, j0, S, T + 1)):
        # the block is as large as the sensor allows: one more lens row or column leaves it
        r, c = sampling_model(GRIDS_BY_SHAPE[model.sensor_shape], "GRBG", lenses=grown).sample_positions()
        assert r.min() < -0.5 or r.max() > H - 0.5 or c.min() < -0.5 or c.max() > W - 0.5
    if model.grid.packing == "hex":
        assert model.lens_origin[0] % 2 == 0
        crow, ccol = model.lens_centres()
        # odd regular rows are the ones shifted by half a pitch along the lens row
        step = np.asarray(model.grid.col_step)
        shift = np.array([crow[1, 0] - crow[0, 0], ccol[1, 0] - ccol[0, 0]]) - np.asarray(model.grid.row_step)
        np.testing.assert_allclose(shift, step / 2, atol=1e-9)


def test_sample_positions_and_pixel_coordinates_are_inverse(model):
    rows, cols = model.sample_positions()
    s, t, u, v = model.pixel_coordinates(rows, cols)
    S, T = model.lenses
    U, V = model.views
    ss, tt, uu, vv = np.meshgrid(np.arange(S), np.arange(T), np.arange(U), np.arange(V), indexing="ij")
    # the corners of a hex lens's U x V square lie nearer to the next lens row: check the inner samples
    inner = (np.abs(uu - (U - 1) / 2) <= 2) & (np.abs(vv - (V - 1) / 2) <= 2)
    np.testing.assert_array_equal(s[inner], ss[inner])
    np.testing.assert_array_equal(t[inner], tt[inner])
    np.testing.assert_allclose(u[inner], uu[inner], atol=1e-9)
    np.testing.assert_allclose(v[inner], vv[inner], atol=1e-9)


def test_forward_rows_interpolate_within_the_pixel_s_own_lens_and_colour(model):
    pixels = model.measured_pixels()
    H, W = model.sensor_shape
    assert np.all(model.response.ravel()[pixels] >= model.threshold)
    assert not np.all(model.valid())  # the dark pixels between micro-images are left out
    A = model.forward_matrix(pixels)
    counts = np.diff(A.indptr)
    assert counts.min() >= 1 and counts.max() <= 4
    np.testing.assert_allclose(np.asarray(A.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert A.data.min() > 0
    rows, cols = np.divmod(pixels, W)
    s, t, u, v = model.pixel_coordinates(rows.astype(float), cols.astype(float))
    S, T = model.lenses
    U, V = model.views
    N = model.samples
    row_of = np.repeat(np.arange(pixels.size), counts)
    plane, rest = np.divmod(A.indices, N)
    r4, c4 = np.divmod(rest, T * V)
    ts, tv = np.divmod(c4, V)
    ss, tu = np.divmod(r4, U)
    colour = channel_map((H, W), "GRBG").ravel()[pixels]
    np.testing.assert_array_equal(plane, colour[row_of])
    np.testing.assert_array_equal(ss, s[row_of])
    np.testing.assert_array_equal(ts, t[row_of])
    # taps are the (clamped) neighbours of the pixel's continuous view position
    assert np.all(np.abs(tu - np.clip(u[row_of], 0, U - 1)) < 1 + 1e-9)
    assert np.all(np.abs(tv - np.clip(v[row_of], 0, V - 1)) < 1 + 1e-9)
    # and reproduce a light field that is linear in (u, v) exactly (bilinear interpolation)
    x = np.zeros((3, S, U, T, V))
    x += (np.arange(U) * 0.3)[None, None, :, None, None] - (np.arange(V) * 0.2)[None, None, None, None, :]
    inside = (u >= 0) & (u <= U - 1) & (v >= 0) & (v <= V - 1)
    np.testing.assert_allclose((A @ x.ravel())[inside], (0.3 * u - 0.2 * v)[inside], atol=1e-9)


def test_resample_rows_use_valid_pixels_of_the_same_lens(model):
    M = model.resample_matrix()
    assert M.shape == (model.samples, int(np.prod(model.sensor_shape)))
    np.testing.assert_allclose(np.asarray(M.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    counts = np.diff(M.indptr)
    assert counts.min() >= 1 and counts.max() <= 4
    assert np.all(model.valid().ravel()[M.indices])
    T = model.lenses[1]
    U, V = model.views
    H, W = model.sensor_shape
    rows, cols = np.divmod(M.indices, W)
    s, t, _, _ = model.pixel_coordinates(rows.astype(float), cols.astype(float))
    sample = np.repeat(np.arange(model.samples), counts)
    r4, c4 = np.divmod(sample, T * V)
    np.testing.assert_array_equal(s, r4 // U)
    np.testing.assert_array_equal(t, c4 // V)
    # a constant image stays constant; where all 4 neighbours are usable a linear image is interpolated exactly
    np.testing.assert_allclose(M @ np.full(H * W, 0.7), 0.7, atol=1e-12)
    pr, pc = (a.transpose(0, 2, 1, 3).ravel() for a in model.sample_positions())  # planes order
    image = (0.25 * np.arange(H)[:, None] - 0.5 * np.arange(W)[None, :]).ravel()
    first = M.indices[M.indptr[:-1]]  # sorted: the top-left tap
    full = (counts == 4) & (first == np.floor(pr).astype(int) * W + np.floor(pc).astype(int))  # own 4 neighbours
    on_pixel = (pr == np.rint(pr)) & (pc == np.rint(pc))
    full |= (counts == 1) & on_pixel & (first == np.rint(pr).astype(int) * W + np.rint(pc).astype(int))
    assert full.mean() > 0.3
    np.testing.assert_allclose((M @ image)[full], (0.25 * pr - 0.5 * pc)[full], atol=1e-9)


def test_flat_field_divides_by_the_response_and_fills_the_gaps():
    geometry = GRIDS["hex"]
    m = sampling_model(geometry, "GRBG")
    raw = (0.4 * m.response).astype(np.float32)
    flat = m.flat_field(raw)
    valid = m.valid()
    np.testing.assert_allclose(flat[valid], 0.4, rtol=1e-6)
    np.testing.assert_allclose(flat[~valid], 0.4, rtol=1e-6)  # filled from valid same-colour pixels
    b, w = m.data(raw)
    np.testing.assert_allclose(b, 0.4, rtol=1e-6)
    np.testing.assert_allclose(w, m.response.ravel()[m.measured_pixels()] ** 2, rtol=1e-6)
    _, w_interp = m.data(raw, interpolation_weight=3.0)
    assert np.all(w_interp <= w) and np.all(w_interp >= w / 4)


def test_sampling_model_bad_input():
    geometry = GRIDS["rotated"]
    with pytest.raises(ValueError, match="pattern"):
        sampling_model(geometry, None)
    with pytest.raises(ValueError, match="views"):
        sampling_model(geometry, "GRBG", views=1)
    with pytest.raises(ValueError, match="threshold"):
        sampling_model(geometry, "GRBG", threshold=1.5)
    with pytest.raises(ValueError, match="response"):
        sampling_model(geometry, "GRBG", response=np.ones((3, 3)))
    with pytest.raises(ValueError, match="even lens row"):
        sampling_model(GRIDS["hex"], "GRBG", lenses=(1, 0, 3, 3))
    with pytest.raises(ValueError, match="Calibration or a GridGeometry"):
        sampling_model("cal.json", "GRBG")
    with pytest.raises(ValueError, match="no whole lens"):
        sampling_model(GridGeometry((8, 8), "square", 9.4), "GRBG")


def test_calibration_and_geometry_agree():
    from lfcl.grid import calibration_from_pitch

    cal = calibration_from_pitch(9.4, (97, 101), "square", 0.7, (0.3, -0.2), pattern="GRBG")
    a = sampling_model(cal)
    b = sampling_model(GRIDS["rotated"], "GRBG", response=np.ones((97, 101)), threshold=0.0)
    assert (a.lens_origin, a.lenses, a.views) == (b.lens_origin, b.lenses, b.views)
    assert (a.forward_matrix() != b.forward_matrix()).nnz == 0
    with pytest.raises(ValueError, match="RGGB"):
        sampling_model(cal, "RGGB")


# --- the sparse device maps -----------------------------------------------------

@pytest.mark.parametrize("planes", [1, 3])
def test_sparse_operator_matches_numpy(runtime, rng, planes):
    M = scipy.sparse.random(37, 53, density=0.08, random_state=3, format="csr")  # odd sizes, empty rows
    M = (M + scipy.sparse.csr_matrix(([1.0], ([36], [52])), shape=(37, 53))).tocsr()
    op = SparseOperator(runtime, M, planes=planes)
    x = rng.standard_normal(planes * 53).astype(np.float32)
    y = rng.standard_normal(planes * 37).astype(np.float32)
    scale = rng.random(37).astype(np.float32)
    add = rng.standard_normal(planes * 53).astype(np.float32)
    dx, dy, dadd = runtime.to_device(x), runtime.to_device(y), runtime.to_device(add)
    np.testing.assert_allclose(op.forward(dx).get(), sparse_apply_np(M, x, planes), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(op.forward_scaled(dx, runtime.to_device(scale)).get(),
                               np.tile(scale, planes) * sparse_apply_np(M, x, planes), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(op.adjoint(dy).get(), sparse_adjoint_np(M, y, planes), rtol=1e-5, atol=1e-6)
    op.adjoint_add(dy, dadd, 0.3, out=dadd)  # in place on add
    np.testing.assert_allclose(dadd.get(), sparse_adjoint_np(M, y, planes) + 0.3 * add, rtol=1e-5, atol=1e-6)


def test_residual_and_multiply(runtime, rng):
    M = scipy.sparse.random(41, 29, density=0.1, random_state=5, format="csr")
    op = SparseOperator(runtime, M)
    x, b, sw = (rng.standard_normal(n).astype(np.float32) for n in (29, 41, 41))
    got = op.residual(runtime.to_device(x), runtime.to_device(b), runtime.to_device(sw)).get()
    np.testing.assert_allclose(got, sw * (sparse_apply_np(M, x) - b), rtol=1e-5, atol=1e-6)
    a, c = (rng.standard_normal(1001).astype(np.float32) for _ in range(2))
    np.testing.assert_array_equal(multiply(runtime, runtime.to_device(a), runtime.to_device(c)).get(), a * c)


def test_numpy_twins_are_adjoint(rng):
    M = scipy.sparse.random(23, 31, density=0.2, random_state=7, format="csr")
    x, y = rng.standard_normal(2 * 31), rng.standard_normal(2 * 23)
    lhs = float(np.dot(sparse_apply_np(M, x, 2), y))
    rhs = float(np.dot(x, sparse_adjoint_np(M, y, 2)))
    assert relative_dot_error(lhs, rhs) < 1e-12


def test_device_maps_of_real_grids_pass_the_dot_test(runtime, rng, model):
    A = SparseOperator(runtime, model.forward_matrix(), in_shape=model.planes_shape)
    H, W = model.sensor_shape
    M = SparseOperator(runtime, model.resample_matrix(), planes=3, in_shape=(3, H, W), out_shape=model.planes_shape)
    for op in (A, M):
        x = rng.standard_normal(op.in_shape).astype(np.float32)
        y = rng.standard_normal(op.out_shape).astype(np.float32)
        fx = op.forward(runtime.to_device(x)).get()
        aty = op.adjoint(runtime.to_device(y)).get()
        lhs = float(np.dot(fx.ravel().astype(np.float64), y.ravel()))
        rhs = float(np.dot(x.ravel().astype(np.float64), aty.ravel()))
        assert relative_dot_error(lhs, rhs) < 1e-5
        np.testing.assert_allclose(fx.ravel(), sparse_apply_np(op.matrix, x.ravel(), op.planes), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(aty.ravel(), sparse_adjoint_np(op.matrix, y.ravel(), op.planes), rtol=1e-5,
                                   atol=1e-5)


def test_sparse_operator_bad_input(runtime):
    with pytest.raises(ValueError, match="in_shape"):
        SparseOperator(runtime, scipy.sparse.eye(4, format="csr"), in_shape=(5,))
    with pytest.raises(ValueError, match="NaN"):
        SparseOperator(runtime, scipy.sparse.csr_matrix(np.array([[np.nan, 1.0]])))
    op = SparseOperator(runtime, scipy.sparse.eye(4, format="csr"))
    with pytest.raises(ValueError, match="x must be float32"):
        op.forward(runtime.to_device(np.zeros(5, np.float32)))
    y = runtime.to_device(np.zeros(4, np.float32))
    with pytest.raises(ValueError, match="must not be y"):
        op.adjoint_add(y, runtime.to_device(np.zeros(4, np.float32)), 1.0, out=y)
