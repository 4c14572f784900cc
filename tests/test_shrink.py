"""Soft thresholding S_kappa and the fused ADMM z/u update: device vs numpy, edge values."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.shrink import Shrinkage, soft_threshold_np, zu_update_np

SIZES = [1, 7, 17, 1000, 12345, 1_000_003]
KAPPAS = [0.0, 0.05, 0.7, 1e30]


@pytest.fixture(scope="module")
def shrinkage(runtime):
    return Shrinkage(runtime)


def definition(v: np.ndarray, kappa: float) -> np.ndarray:
    return np.sign(v) * np.maximum(np.abs(v) - kappa, 0)


# -- numpy twins ---------------------------------------------------------------------


def test_numpy_twin_matches_the_definition(rng):
    v = rng.standard_normal(1000).astype(np.float32)
    for kappa in KAPPAS:
        np.testing.assert_array_equal(soft_threshold_np(v, kappa), definition(v, np.float32(kappa)))


def test_numpy_zu_update_is_scaled_admm(rng):
    dx, z, u = (rng.standard_normal(500).astype(np.float32) for _ in range(3))
    z_new, u_new, dz = zu_update_np(dx, z, u, 0.3)
    v = dx + u
    np.testing.assert_array_equal(z_new, soft_threshold_np(v, 0.3))
    np.testing.assert_array_equal(u_new, v - z_new)
    np.testing.assert_array_equal(dz, z_new - z)


@pytest.mark.parametrize("kappa", [-1e-3, float("nan"), float("inf"), -float("inf")])
def test_bad_kappa_is_rejected(runtime, shrinkage, kappa):
    v = np.ones(3, np.float32)
    with pytest.raises(ValueError, match="kappa"):
        soft_threshold_np(v, kappa)
    with pytest.raises(ValueError, match="kappa"):
        zu_update_np(v, v, v, kappa)
    d = [runtime.to_device(v) for _ in range(4)]
    with pytest.raises(ValueError, match="kappa"):
        shrinkage.soft_threshold(d[0], kappa)
    with pytest.raises(ValueError, match="kappa"):
        shrinkage.zu_update(*d, kappa)


# -- soft threshold on the device --------------------------------------------------------


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kappa", KAPPAS)
def test_soft_threshold_matches_numpy(runtime, shrinkage, rng, n, kappa):
    v = rng.standard_normal(n).astype(np.float32)
    got = shrinkage.soft_threshold(runtime.to_device(v), kappa).get()
    np.testing.assert_array_equal(got, soft_threshold_np(v, kappa))


def test_values_at_and_around_kappa(runtime, shrinkage):
    kappa = np.float32(0.25)
    up, down = np.nextafter(kappa, np.float32(1)), np.nextafter(kappa, np.float32(0))
    v = np.array([kappa, -kappa, up, -up, down, -down, 0, -0.0, 3, -3], np.float32)
    expected = np.array([0, 0, up - kappa, kappa - up, 0, 0, 0, 0, 2.75, -2.75], np.float32)
    got = shrinkage.soft_threshold(runtime.to_device(v), kappa).get()
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(got, soft_threshold_np(v, kappa))
    assert got[2] > 0 and got[3] < 0  # one ulp past kappa survives, with its sign


def test_kappa_zero_is_the_identity_and_large_kappa_zeroes(runtime, shrinkage, rng):
    v = (rng.standard_normal(12345) * 10).astype(np.float32)
    dv = runtime.to_device(v)
    np.testing.assert_array_equal(shrinkage.soft_threshold(dv, 0.0).get(), v)
    assert not np.any(shrinkage.soft_threshold(dv, 1e3).get())
    assert not np.any(shrinkage.soft_threshold(dv, np.abs(v).max()).get())


def test_in_place_any_shape_and_nan(runtime, shrinkage, rng):
    v = rng.standard_normal((3, 18, 27)).astype(np.float32)
    v[1, 2, 3] = np.nan
    dv = runtime.to_device(v)
    assert shrinkage.soft_threshold(dv, 0.5, out=dv) is dv
    got = dv.get()
    np.testing.assert_array_equal(got, soft_threshold_np(v, 0.5))
    assert np.isnan(got[1, 2, 3])
    with pytest.raises(ValueError, match="out must be float32 of shape"):
        shrinkage.soft_threshold(dv, 0.5, out=runtime.empty((3, 18, 26)))


# -- fused z/u update ----------------------------------------------------------------------


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kappa", KAPPAS)
def test_zu_update_matches_numpy(runtime, shrinkage, rng, n, kappa):
    dx, z, u = (rng.standard_normal(n).astype(np.float32) for _ in range(3))
    d_dx, d_z, d_u = (runtime.to_device(a) for a in (dx, z, u))
    d_dz = runtime.empty((n,))
    assert shrinkage.zu_update(d_dx, d_z, d_u, d_dz, kappa) == (d_z, d_u, d_dz)
    for got, expected in zip((d_z, d_u, d_dz), zu_update_np(dx, z, u, kappa)):
        np.testing.assert_array_equal(got.get(), expected)
    np.testing.assert_array_equal(d_dx.get(), dx)  # D x is only read


def test_zu_update_extremes_and_dz_in_dx(runtime, shrinkage, rng):
    shape = (2, 3, 9, 10)
    dx, z, u = (rng.standard_normal(shape).astype(np.float32) for _ in range(3))
    # kappa = 0: z' = dx + u, u' = 0
    d = [runtime.to_device(a) for a in (dx, z, u)]
    shrinkage.zu_update(d[0], d[1], d[2], d[0], 0.0)  # dz written over dx
    np.testing.assert_array_equal(d[1].get(), dx + u)
    assert not np.any(d[2].get())
    np.testing.assert_array_equal(d[0].get(), (dx + u) - z)
    # large kappa: z' = 0, u' = dx + u, dz = -z
    d = [runtime.to_device(a) for a in (dx, z, u)]
    d_dz = runtime.empty(shape)
    shrinkage.zu_update(d[0], d[1], d[2], d_dz, 1e30)
    assert not np.any(d[1].get())
    np.testing.assert_array_equal(d[2].get(), dx + u)
    np.testing.assert_array_equal(d_dz.get(), -z)


def test_zu_update_rejects_bad_buffers(runtime, shrinkage):
    a, b, c, d = (runtime.zeros((10,)) for _ in range(4))
    with pytest.raises(ValueError, match="u must be float32 of shape"):
        shrinkage.zu_update(a, b, runtime.zeros((11,)), d, 0.1)
    with pytest.raises(ValueError, match="dz must be float32"):
        shrinkage.zu_update(a, b, c, runtime.zeros((10,), np.float64), 0.1)
    with pytest.raises(ValueError, match="distinct"):
        shrinkage.zu_update(a, b, c, b, 0.1)
    with pytest.raises(ValueError, match="dx, z and u must have one shape"):
        zu_update_np(np.zeros(3), np.zeros(3), np.zeros(4), 0.1)
