"""lfcl: OpenCL demosaicing and denoising of plenoptic (light-field) camera raws.

The public API, small on purpose (the stages, operators and solvers stay importable from their
modules for those who need them)::

    read_raw(path, pattern=None)             -> lfcl.io.raw.Mosaic (DNG, camera raw, or an image mosaic)
    lightfield(raw, pitch=..., method="auto") -> the light field [S, T, U, V, 3] float32, any lens grid
    process(path, out_dir, recipe="default") -> what `lfcl process` does: the files, and their summary
    malvar(mosaic, pattern)                  -> Malvar-He-Cutler (2004) of a plain Bayer mosaic [H, W, 3]

Example::

    >>> import numpy as np, lfcl
    >>> from lfcl.sim import simulate
    >>> capture = simulate("charts", lenses=(4, 6), lux=12)
    >>> lf = lfcl.lightfield(capture.normalised_raw(), pattern=capture.pattern, pitch=9)
    >>> lf.shape
    (4, 6, 9, 9, 3)

Importing lfcl imports neither numpy nor pyopencl (``lfcl --help`` stays fast): each name loads its
module on first use.
"""

__version__ = "0.1.0"

__all__ = ["__version__", "lightfield", "malvar", "process", "read_raw"]


def read_raw(path, pattern: str | None = None):
    """Read a raw file into a :class:`lfcl.io.raw.Mosaic`.

    Parameters
    ----------
    path : str or os.PathLike
        A DNG or camera raw (through rawpy/LibRaw), or an EXR/TIFF/PNG single-plane mosaic.
    pattern : str, optional
        The Bayer pattern (``"GRBG"`` ...); read from raws, required for image mosaics.

    Returns
    -------
    Mosaic
        ``data`` float32 [H, W] normalised to black 0 and white 1, ``pattern``, the camera's colour
        matrices, as-shot white balance and DNG noise profile where the file has them.

    Raises
    ------
    ValueError
        A file that does not exist, an unreadable or unsupported one, or an image mosaic without ``pattern``.
    """
    from .pipeline.stages import Decode

    return Decode(pattern)(path)  # the pipeline's own stage: the same checks and errors as lfcl.lightfield's


def lightfield(raw, *, pitch: int | None = None, calibration=None, white=None, pattern: str | None = None,
             method: str | None = None, device=None, **options):
    """Demosaic (and denoise) a lenslet raw into its light field in the exchange layout ``[S, T, U, V, 3]``.

    Parameters
    ----------
    raw : str, os.PathLike, lfcl.io.raw.Mosaic or numpy.ndarray
        A raw file, a :func:`read_raw` result, or a normalised [H, W] mosaic (then ``pattern`` is needed).
        (The name is not ``demosaic``: that is the package lfcl.demosaic, the driver behind this call.)
    pitch, calibration, white
        The lens grid, at most one: an aligned square grid of ``pitch`` pixels (default 9), a
        calibration file (``lfcl calibrate``) or a white image; rotated, non-integer-pitch and
        hexagonal grids are resampled (docs/geometry.md).
    pattern : str, optional
        The Bayer pattern of an image mosaic or array.
    method : str, optional
        ``METHOD[:START]``: one of ``lfcl.demosaic.names.METHODS``, optionally with the ADMM methods' first
        estimate (``lfcl.demosaic.names.STARTS``), as ``admm-uv-xc:guarded``; default ``auto`` (docs/auto.md).
    device : str or int, optional
        An OpenCL device (``lfcl devices``); default ``LFCL_DEVICE``, else the first GPU, else the first device.
    **options
        The Demosaic stage's options: ``lam``, ``iterations``, ``strength``, ``tolerance_db``,
        ``skip_flat``, ``safety_net``, ``auto_costly`` (with ``auto``; False: ``--auto-cheap``), ``max_memory``
        (lfcl/pipeline/stages.py).

    Returns
    -------
    numpy.ndarray
        float32 ``[S, T, U, V, 3]`` linear camera RGB (docs/layout.md).
    """
    from .demosaic.names import DEFAULT_METHOD
    from .io.raw import Mosaic
    from .pipeline.stages import Decode, Demosaic, Grid

    if isinstance(raw, Mosaic):
        from .layout import parse_pattern

        if pattern is not None and parse_pattern(pattern) != raw.pattern:  # as a raw file with another pattern
            raise ValueError(f"lightfield: pattern {pattern!r} given, but the raw's is {raw.pattern}")
        mosaic = raw
    elif hasattr(raw, "ndim"):  # a numpy array: the normalised mosaic itself
        import numpy as np

        if pattern is None:
            raise ValueError("lightfield: a mosaic array needs its Bayer pattern (pattern='GRBG', ...)")
        if np.ndim(raw) != 2:
            raise ValueError(f"lightfield: a mosaic array is 2-D [H, W], got shape {np.shape(raw)}")
        mosaic = Mosaic(data=np.ascontiguousarray(raw, dtype=np.float32), pattern=pattern, source="array")
    else:
        mosaic = Decode(pattern)(raw)
    gridded = Grid(pitch=pitch, calibration=calibration, white=white, pattern=pattern)(mosaic)
    stage = Demosaic(method or DEFAULT_METHOD, device=device, **options)
    return stage(gridded).lightfield


def process(path, out_dir, recipe="default", **overrides) -> dict:
    """Run `lfcl process` on one raw file from Python: decode, lens grid, demosaic, outputs.

    Parameters
    ----------
    path : str or os.PathLike
        The raw file.
    out_dir : str or os.PathLike
        Where the outputs and ``summary.json`` go (docs/outputs.md).
    recipe : str, os.PathLike or dict
        A packaged recipe (``default``, ``lowlight``, ``preview``), a ``.toml`` file or a dict (docs/stages.md).
    **overrides
        Recipe keys (``method``, as ``METHOD[:START]``, ``strength``, ``lam``, ``iterations``, ``outputs``,
        ``refocus``, ``fmt``, ``previews``) and ``pattern``, ``pitch``, ``calibration``, ``white``, ``device``.

    Returns
    -------
    dict
        The run's summary, as written to ``summary.json``.
    """
    from .pipeline.recipes import pipeline_from_recipe

    return pipeline_from_recipe(recipe, **overrides).run(path, out_dir)


def __getattr__(name):
    # lfcl.malvar is imported on first use, so that `import lfcl` (and `lfcl --help`) needs no numpy/pyopencl.
    if name == "malvar":
        from .ops.malvar import malvar

        return malvar
    raise AttributeError(f"module 'lfcl' has no attribute {name!r}")
