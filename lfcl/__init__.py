"""lfcl: OpenCL demosaicing and denoising of plenoptic (light-field) camera raws."""

__version__ = "0.1.0"

from .ops.malvar import malvar

__all__ = ["__version__", "malvar"]
