"""Demosaicing a lenslet mosaic: the method registry and driver (methods.py), the resampled-grid
driver, the starts, flat lenses, the safety net and ``--method auto``.

Importing this package imports nothing heavy: lfcl/demosaic/names.py feeds ``lfcl --help``."""
