"""Every linear operator of lfcl.ops passes lfcl.testing.dottest on the device (PyLops-style), in one place."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse

from lfcl.testing import dottest, operator_shapes


def _cfa(rt, rng):
    from lfcl.ops.cfa import CfaSampling

    return CfaSampling(rt, (18, 27), "GRBG", (1, 0))


def _gradient(dims, masked=False):
    def make(rt, rng):
        from lfcl.ops.gradient import Gradient

        op = Gradient(rt, (3, 27, 18), (9, 9), dims)
        if masked:  # a vignetted lens: differences touching its dark corners are left out
            v, u = np.meshgrid(np.arange(9) - 4, np.arange(9) - 4)
            op.set_lens_weights(np.clip(1.2 - 0.06 * (u**2 + v**2), 0, 1))
        return op
    return make


def _cross(rt, rng):
    from lfcl.ops.crosschannel import CrossGradient

    return CrossGradient(rt, (3, 18, 27), (9, 9), "uvst")


def _epi(rt, rng):
    from lfcl.ops.epi import EpiGradient

    op = EpiGradient(rt, (3, 5 * 9, 4 * 9), (9, 9))
    op.set_maps(rng.uniform(-1.5, 1.5, (5, 4)).astype(np.float32), rng.uniform(0, 1, (5, 4)).astype(np.float32))
    return op


def _sparse(rt, rng):
    from lfcl.ops.resample import SparseOperator

    matrix = scipy.sparse.random(40, 30, density=0.2, random_state=3, format="csr")
    return SparseOperator(rt, matrix, planes=3, in_shape=(3, 30), out_shape=(3, 40))


OPERATORS = {"cfa": _cfa, "gradient uv": _gradient("uv"), "gradient st": _gradient("st"),
             "gradient uvst": _gradient("uvst"), "gradient uv masked": _gradient("uv", masked=True),
             "cross-channel uvst": _cross, "epipolar": _epi, "sparse resampling": _sparse}


@pytest.mark.parametrize("name", list(OPERATORS))
def test_every_linear_operator_passes_the_dot_test(runtime, name):
    op = OPERATORS[name](runtime, np.random.default_rng(5))
    assert dottest(op, runtime, rng=np.random.default_rng(7)) <= 1e-5


def test_the_dot_test_catches_a_wrong_adjoint(runtime):
    from lfcl.ops.gradient import Gradient

    op = Gradient(runtime, (1, 9, 18), (9, 9), "uv")
    op.adjoint = lambda z, out=None: _negated(runtime, z)
    with pytest.raises(AssertionError, match="dot test"):
        dottest(op, runtime)


def _negated(runtime, z):
    """-(the first block of z): a map of the right shapes that is not D's adjoint."""
    return runtime.to_device(-z.get()[0])


def test_operator_shapes_refuses_an_object_without_them():
    with pytest.raises(ValueError, match="does not say its input and output shapes"):
        operator_shapes(object())


def test_the_public_api_demosaics_to_the_exchange_layout_and_processes_a_file(tmp_path):
    import json

    import lfcl
    from lfcl.demosaic.driver import demosaic_grid
    from lfcl.grid.model import AlignedGrid
    from lfcl.sim import simulate, write_capture

    capture = simulate("charts", lenses=(4, 6), lux=12, seed=1)
    mosaic = capture.normalised_raw()
    lightfield = lfcl.lightfield(mosaic, pattern=capture.pattern, pitch=9, method="admm-uvst", iterations=3)
    planes = demosaic_grid(mosaic, capture.pattern, AlignedGrid((9, 9)), "admm-uvst", iterations=3).planes
    assert lightfield.shape == (4, 6, 9, 9, 3) and lightfield.dtype == np.float32
    np.testing.assert_array_equal(lightfield[1, 2, 3, 4], planes[:, 1 * 9 + 3, 2 * 9 + 4])  # row s*U+u, col t*V+v
    folder = write_capture(capture, tmp_path / "cap")
    raw = lfcl.read_raw(folder / "raw.dng")
    assert raw.pattern == capture.pattern and raw.data.shape == mosaic.shape
    for call in (lfcl.read_raw, lfcl.lightfield):  # a missing file is a user's error like any other: ValueError
        with pytest.raises(ValueError, match="nothere.dng' does not exist"):
            call(str(tmp_path / "nothere.dng"))
    summary = lfcl.process(folder / "raw.dng", tmp_path / "out", "preview", pitch=9)
    assert summary["method"] == "malvar" and json.loads((tmp_path / "out" / "summary.json").read_text())["method"] == \
        "malvar"
    with pytest.raises(ValueError, match="needs its Bayer pattern"):
        lfcl.lightfield(mosaic)
    with pytest.raises(ValueError, match=r"is 2-D \[H, W\], got shape \(24,\)"):
        lfcl.lightfield(mosaic[0, :24], pattern=capture.pattern)
    other = "RGGB" if raw.pattern != "RGGB" else "GRBG"  # a read raw keeps its own pattern, as a raw file does
    with pytest.raises(ValueError, match=f"pattern '{other.lower()}' given, but the raw's is {raw.pattern}"):
        lfcl.lightfield(raw, pattern=other.lower(), pitch=9, method="malvar")
    assert lfcl.lightfield(raw, pattern=raw.pattern.lower(), pitch=9, method="malvar").shape == (4, 6, 9, 9, 3)
