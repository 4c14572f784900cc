"""Malvar-He-Cutler (2004) demosaicing: kernel vs numpy twin vs colour-demosaicing."""

from __future__ import annotations

import itertools
import zlib
from pathlib import Path

import numpy as np
import pyopencl as cl
import pytest

from lfcl.device import get_runtime
from lfcl.layout import PATTERNS, packed_pattern
from lfcl.ops.malvar import Malvar, _image_streamed, malvar, malvar_np, mirror_index, row_bands

# colour-demosaicing 0.2.7 imports convolve from the deprecated scipy.ndimage.filters.
pytestmark = pytest.mark.filterwarnings("ignore:Please import:DeprecationWarning")

ORIGINS = [(0, 0), (1, 0), (0, 1), (1, 1)]
SIZES = [(37, 53), (1, 1), (2, 3), (5, 5), (64, 64)]
LIGHTHOUSE = Path(__file__).resolve().parents[2] / "shared" / "data" / "lighthouse"


@pytest.fixture(scope="module")
def runtime():
    return get_runtime()


def _mosaic(shape, seed=0):
    return np.random.default_rng(seed).random(shape, dtype=np.float32)


def _run_device(runtime, mosaic, pattern, origin=(0, 0)):
    op = Malvar(runtime, mosaic.shape, pattern, origin)
    return op.forward(runtime.to_device(mosaic)).get()


def _border_mask(shape, width=2):
    mask = np.ones(shape, dtype=bool)
    mask[width:-width, width:-width] = False
    return mask


# --- mirror rule ---------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
def test_mirror_index_is_numpy_reflect_pad(n):
    index = np.arange(-9, n + 9)
    assert np.array_equal(mirror_index(index, n), np.pad(np.arange(n), 9, mode="reflect"))
    assert np.all((mirror_index(index, n) >= 0) & (mirror_index(index, n) < n))
    if n >= 2:  # the extension keeps every sample's CFA parity
        assert np.array_equal(mirror_index(index, n) % 2, index % 2)


# --- kernel vs numpy twin --------------------------------------------------------


@pytest.mark.parametrize("shape", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"o{o[0]}{o[1]}")
@pytest.mark.parametrize("pattern", PATTERNS)
def test_kernel_matches_numpy(runtime, pattern, origin, shape):
    mosaic = _mosaic(shape, seed=zlib.crc32(f"{pattern}{origin}{shape}".encode()))
    got = _run_device(runtime, mosaic, pattern, origin)
    want = malvar_np(mosaic, pattern, origin)
    assert got.shape == (3, *shape) and got.dtype == np.float32
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)


def test_kernel_bounds_checked_with_padded_global_size(runtime):
    """A global size rounded up to an 8x8 work-group writes nothing past the planes."""
    H, W = 37, 53
    mosaic = _mosaic((H, W), seed=3)
    guard = 4096
    mf = cl.mem_flags
    src = cl.Buffer(runtime.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=mosaic)
    host_out = np.full(3 * H * W + guard, -7.0, dtype=np.float32)
    dst = cl.Buffer(runtime.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=host_out)
    runtime.launch(
        "malvar", "malvar", (56, 40), src, dst, np.int32(H), np.int32(W),
        packed_pattern("GRBG"), np.int32(0), np.int32(0), local_size=(8, 8),
    )
    cl.enqueue_copy(runtime.queue, host_out, dst)
    runtime.queue.finish()
    assert np.all(host_out[3 * H * W :] == -7.0)
    np.testing.assert_allclose(
        host_out[: 3 * H * W].reshape(3, H, W), malvar_np(mosaic, "GRBG"), rtol=0, atol=1e-6
    )


def test_forward_writes_into_out(runtime):
    mosaic = _mosaic((6, 9), seed=4)
    op = Malvar(runtime, mosaic.shape, "BGGR")
    out = runtime.zeros((3, 6, 9))
    result = op.forward(runtime.to_device(mosaic), out=out)
    assert result is out
    np.testing.assert_allclose(out.get(), malvar_np(mosaic, "BGGR"), rtol=0, atol=1e-6)
    with pytest.raises(ValueError):
        op.forward(runtime.to_device(mosaic), out=runtime.zeros((3, 9, 6)))
    with pytest.raises(ValueError):
        op.forward(runtime.to_device(mosaic.T.copy()))


# --- numpy twin vs colour-demosaicing -------------------------------------------


@pytest.mark.parametrize("pattern", PATTERNS)
def test_numpy_interior_matches_colour_demosaicing(pattern):
    from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004

    mosaic = _mosaic((30, 42), seed=11)
    want = demosaicing_CFA_Bayer_Malvar2004(mosaic.astype(np.float64), pattern).transpose(2, 0, 1)
    got = malvar_np(mosaic, pattern)
    np.testing.assert_allclose(got[:, 2:-2, 2:-2], want[:, 2:-2, 2:-2], rtol=0, atol=1e-6)


@pytest.mark.parametrize("shape", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
@pytest.mark.parametrize("pattern", PATTERNS)
def test_numpy_border_is_colour_demosaicing_on_mirror_padded_mosaic(pattern, shape):
    """Mirror border == colour-demosaicing on the mosaic padded by 2 with np.pad 'reflect'.

    Padding by an even width keeps the phase, and the 2-pixel frame of colour's
    output (where its own 'reflect' border acts) is cut away.
    """
    from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004

    mosaic = _mosaic(shape, seed=12)
    padded = np.pad(mosaic.astype(np.float64), 2, mode="reflect")
    want = demosaicing_CFA_Bayer_Malvar2004(padded, pattern)[2:-2, 2:-2].transpose(2, 0, 1)
    np.testing.assert_allclose(malvar_np(mosaic, pattern), want, rtol=0, atol=1e-6)


@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"o{o[0]}{o[1]}")
def test_origin_shifts_the_phase(origin):
    """An odd crop origin equals the pattern of the crop's first 2x2 cell."""
    mosaic = _mosaic((12, 14), seed=13)
    shifted = {(0, 0): "GRBG", (1, 0): "BGGR", (0, 1): "RGGB", (1, 1): "GBRG"}[origin]
    np.testing.assert_array_equal(malvar_np(mosaic, "GRBG", origin), malvar_np(mosaic, shifted))


# --- conformance: Kodak lighthouse (colour-demosaicing test data) ----------------


def _read_exr(name):
    import OpenImageIO

    buf = OpenImageIO.ImageBuf(str(LIGHTHOUSE / name))
    pixels = buf.get_pixels(OpenImageIO.FLOAT)
    assert pixels is not None and pixels.size, f"could not read {name}: {buf.geterror()}"
    return np.asarray(pixels, dtype=np.float32)


def test_lighthouse_conformance(runtime):
    if not LIGHTHOUSE.is_dir():
        pytest.skip(f"conformance data folder {LIGHTHOUSE} is missing (shared/data/lighthouse next to the repository)")
    cfa = _read_exr("Lighthouse_CFA_GRBG.exr")
    reference = _read_exr("Lighthouse_Malvar2004_GRBG.exr")
    mosaic = np.ascontiguousarray(cfa[:, :, 0])
    assert mosaic.shape == reference.shape[:2] == (768, 512)

    got = _run_device(runtime, mosaic, "GRBG").transpose(1, 2, 0)
    border = _border_mask(mosaic.shape)
    interior_error = np.abs(got - reference)[~border].max()
    assert interior_error <= 1e-5, f"interior max abs error {interior_error:.3g}"

    twin = malvar_np(mosaic, "GRBG").transpose(1, 2, 0)
    border_error = np.abs(got - twin)[border].max()
    assert border_error <= 1e-5, f"border max abs error vs numpy {border_error:.3g}"

    # The public API gives the same image.
    np.testing.assert_array_equal(malvar(mosaic, "GRBG"), got)


# --- public API -----------------------------------------------------------------


def test_malvar_returns_hwc_float32(runtime):
    mosaic = _mosaic((9, 11), seed=21)
    rgb = malvar(mosaic, "rggb")
    assert rgb.shape == (9, 11, 3) and rgb.dtype == np.float32 and rgb.flags.c_contiguous
    np.testing.assert_allclose(rgb, malvar_np(mosaic, "RGGB").transpose(1, 2, 0), rtol=0, atol=1e-6)
    # (H, W, 1) and integer input are accepted (converted to float32, not scaled).
    np.testing.assert_array_equal(malvar(mosaic[:, :, None], "RGGB"), rgb)
    ints = (mosaic * 255).astype(np.uint8)
    np.testing.assert_allclose(
        malvar(ints, "RGGB"), malvar_np(ints.astype(np.float32), "RGGB").transpose(1, 2, 0), rtol=0, atol=1e-4
    )


@pytest.mark.parametrize("shape, rows", [((1, 1), 2), ((2, 5), 2), ((9, 7), 2), ((9, 7), 4), ((37, 13), 5), ((64, 33), 512)])
def test_streamed_bands_match_numpy(runtime, shape, rows):
    # The GPU path (bands of rows up, through the filters and down on three queues, each band waiting for its
    # neighbours' uploads) run here on any device: band edges must not show, odd last bands included.
    mosaic = _mosaic(shape, seed=sum(shape) + rows)
    op = Malvar(runtime, shape, "GBRG", origin=(1, 0))
    np.testing.assert_allclose(_image_streamed(op, mosaic, rows=rows),
                               malvar_np(mosaic, "GBRG", origin=(1, 0)).transpose(1, 2, 0), rtol=0, atol=1e-6)


@pytest.mark.parametrize("height, rows", [(1, 2), (2, 2), (3, 2), (9, 4), (10, 4), (1024, 512), (1025, 512)])
def test_row_bands_cover_the_image_with_bands_of_two_rows_or_more(height, rows):
    bands = row_bands(height, rows)
    assert bands[0][0] == 0 and bands[-1][1] == height
    assert all(a[1] == b[0] for a, b in itertools.pairwise(bands))
    assert all(r1 - r0 <= rows + 1 for r0, r1 in bands)
    assert all(r1 - r0 >= 2 for r0, r1 in bands) or len(bands) == 1
    with pytest.raises(ValueError, match="2 rows"):
        row_bands(height, 1)


@pytest.mark.parametrize(
    "mosaic, pattern, match",
    [
        (np.zeros((4, 4, 3), np.float32), "RGGB", r"\(4, 4, 3\)"),
        (np.zeros((4,), np.float32), "RGGB", r"\(4,\)"),
        (np.zeros((4, 4), np.complex64), "RGGB", "complex64"),
        (np.zeros((4, 4), bool), "RGGB", "bool"),
        (np.zeros((4, 4), object), "RGGB", "object"),
        (np.zeros((4, 4), np.float32), "RGBX", "RGBX"),
        (np.zeros((0, 4), np.float32), "RGGB", "empty"),
        (np.array([[0.0, np.nan], [0.0, 0.0]]), "RGGB", "finite"),
        (np.array([[0.0, 1e39], [0.0, 0.0]]), "RGGB", "finite"),
    ],
    ids=["hw3", "1d", "complex", "bool", "object", "pattern", "empty", "nan", "overflow"],
)
def test_malvar_rejects_bad_input(mosaic, pattern, match):
    with pytest.raises(ValueError, match=match):
        malvar(mosaic, pattern)


# --- lens-bounded ----------------------------------------------------------------

LENSES = [((9, 9), (3, 4)), ((5, 5), (2, 3)), ((4, 6), (3, 2)), ((2, 2), (3, 3)), ((1, 3), (4, 2))]


@pytest.mark.parametrize("lens, grid", LENSES, ids=lambda v: "x".join(map(str, v)))
@pytest.mark.parametrize("origin", ORIGINS, ids=lambda o: f"o{o[0]}{o[1]}")
@pytest.mark.parametrize("pattern", PATTERNS)
def test_lens_bounded_is_malvar_of_each_lens_on_its_own(runtime, pattern, origin, lens, grid):
    """Every lens demosaiced as an image of its own (its Bayer phase from its place), side by side."""
    (U, V), (S, T) = lens, grid
    mosaic = _mosaic((S * U, T * V), seed=U * 7 + V)
    expected = np.empty((3, S * U, T * V), np.float32)
    for s in range(S):
        for t in range(T):
            block = np.s_[s * U:(s + 1) * U, t * V:(t + 1) * V]
            expected[(slice(None), *block)] = malvar_np(mosaic[block], pattern, (origin[0] + s * U, origin[1] + t * V))
    np.testing.assert_allclose(malvar_np(mosaic, pattern, origin, lens=lens), expected, rtol=0, atol=1e-6)
    device = Malvar(runtime, mosaic.shape, pattern, origin, lens=lens).forward(runtime.to_device(mosaic)).get()
    np.testing.assert_allclose(device, expected, rtol=0, atol=1e-5)


def test_lens_bounded_differs_from_the_sensor_wide_malvar_only_near_lens_borders():
    mosaic = _mosaic((27, 27), seed=11)
    plain, bounded = malvar_np(mosaic, "GRBG"), malvar_np(mosaic, "GRBG", lens=(9, 9))
    local = np.arange(27) % 9
    inner = ((local >= 2) & (local <= 6))[:, None] & ((local >= 2) & (local <= 6))[None, :]
    np.testing.assert_array_equal(plain[:, inner], bounded[:, inner])
    assert np.abs(plain[:, ~inner] - bounded[:, ~inner]).max() > 0.01


def test_lens_bounded_needs_whole_lenses(runtime):
    with pytest.raises(ValueError, match="whole lenses"):
        Malvar(runtime, (20, 18), "GRBG", lens=(9, 9))
    with pytest.raises(ValueError, match="whole lenses"):
        malvar_np(np.zeros((18, 20), np.float32), "GRBG", lens=(9, 9))
