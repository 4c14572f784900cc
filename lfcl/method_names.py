"""The names of the demosaic/denoise methods, importable without numpy (for `lfcl --help`).

What each does and its defaults: lfcl/methods.py.
"""

METHODS = ("auto", "malvar", "admm-uv", "admm-st", "admm-uvst", "linear4d", "admm-uv-xc", "admm-uvst-xc")
