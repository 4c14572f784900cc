"""lfcl: OpenCL demosaicing and denoising of plenoptic (light-field) camera raws."""

__version__ = "0.1.0"

__all__ = ["__version__", "malvar"]


def __getattr__(name):
    # lfcl.malvar is imported on first use, so that `import lfcl` (and `lfcl --help`) needs no numpy/pyopencl.
    if name == "malvar":
        from .ops.malvar import malvar

        return malvar
    raise AttributeError(f"module 'lfcl' has no attribute {name!r}")
