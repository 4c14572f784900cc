"""The harmonic fill of dark lens pixels: numpy twin vs its defining property, device vs numpy."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.ops.gradient import gradient_gram_np
from lfcl.ops.lensfill import LensFill, fill_matrix, lens_fill_np


def ring_weights(U, V, floor):
    u = (np.arange(U) - (U - 1) / 2) / (U / 2)
    v = (np.arange(V) - (V - 1) / 2) / (V / 2)
    w = np.clip(1 - 0.8 * (u[:, None] ** 2 + v[None, :] ** 2), 0, None)
    w[w < floor] = 0
    return w.astype(np.float32)


@pytest.mark.parametrize("pitch", [(9, 9), (4, 7)])
def test_fill_is_harmonic_and_keeps_lit_pixels(rng, pitch):
    U, V = pitch
    w = ring_weights(U, V, 0.3)
    assert (w == 0).any() and (w > 0).any()
    x = rng.standard_normal((3, 3 * U, 2 * V))
    filled = lens_fill_np(x, w, pitch)
    dark = np.tile(w == 0, (3, 2))
    np.testing.assert_array_equal(filled[:, ~dark], x[:, ~dark])
    # the defining property: the lens Laplacian D_uv^T D_uv of the result vanishes at dark pixels
    assert np.abs(gradient_gram_np(filled, pitch, "uv")[:, dark]).max() < 1e-12
    # a constant lens stays constant
    np.testing.assert_allclose(lens_fill_np(np.full_like(x, 0.3), w, pitch), 0.3, rtol=0, atol=1e-12)


def test_device_matches_numpy(runtime, rng):
    w = ring_weights(9, 9, 0.3)
    x = rng.standard_normal((3, 27, 36)).astype(np.float32)
    device = runtime.to_device(x)
    LensFill(runtime, x.shape, (9, 9))(device, w, runtime.to_device(w.ravel()))
    np.testing.assert_allclose(device.get(), lens_fill_np(x, w, (9, 9)), rtol=0, atol=1e-5)


def test_no_dark_pixel_is_identity_and_all_dark_raises(rng):
    x = rng.standard_normal((3, 9, 9))
    np.testing.assert_array_equal(lens_fill_np(x, np.ones((3, 3)), (3, 3)), x)
    assert not fill_matrix(np.ones((3, 3)), (3, 3)).any()
    with pytest.raises(ValueError, match="nothing to fill"):
        fill_matrix(np.zeros((3, 3)), (3, 3))
    with pytest.raises(ValueError, match="lens weights must be 3x3"):
        fill_matrix(np.ones((2, 3)), (3, 3))
