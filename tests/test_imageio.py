"""Image writing: formats, metadata in every format, atomic writes, refusal of NaN."""

from __future__ import annotations

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from lfcl.io.images import read_image, write_image


@pytest.mark.parametrize("suffix,tolerance", [(".exr", 0), (".tif", 1 / 65535), (".png", 1 / 255)])
def test_round_trip_and_metadata(tmp_path, rng, suffix, tolerance):
    image = rng.random((7, 5, 3)).astype(np.float32)
    path = write_image(tmp_path / f"a{suffix}", image, {"method": "malvar", "params": {"lam": 0.1}})
    back = read_image(path)
    assert back.shape == (7, 5, 3)
    np.testing.assert_allclose(back, image, atol=tolerance * 0.51 + 1e-7)
    description = oiio.ImageInput.open(str(path)).spec().getattribute("ImageDescription")
    assert json.loads(description)["lfcl"] == {"method": "malvar", "params": {"lam": 0.1}}
    assert [p.name for p in tmp_path.iterdir()] == [f"a{suffix}"]


def test_exr_keeps_values_outside_0_1(tmp_path):
    image = np.array([[[-0.25, 1.5, 0.5]]], np.float32)
    np.testing.assert_array_equal(read_image(write_image(tmp_path / "x.exr", image)), image)


def test_nan_is_refused_and_nothing_is_written(tmp_path):
    image = np.zeros((2, 2, 3), np.float32)
    image[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN or Inf"):
        write_image(tmp_path / "x.exr", image)
    assert list(tmp_path.iterdir()) == []


def test_unknown_extension_is_refused(tmp_path):
    with pytest.raises(ValueError, match="unsupported output extension"):
        write_image(tmp_path / "x.bmp", np.zeros((2, 2), np.float32))
    assert list(tmp_path.iterdir()) == []


def test_written_files_get_the_usual_permissions(tmp_path):
    import os

    umask = os.umask(0o022)
    try:
        path = write_image(tmp_path / "x.exr", np.zeros((2, 2, 3), np.float32))
    finally:
        os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o644
