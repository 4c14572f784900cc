"""lfcl: OpenCL demosaicing and denoising of plenoptic (light-field) camera raws."""

__version__ = "0.1.0"

from .ops.malvar import malvar  # noqa: E402

__all__ = ["malvar", "__version__"]
