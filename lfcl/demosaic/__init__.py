"""Demosaicing a lenslet mosaic: the one entry point (driver.py: ``demosaic_grid`` on an aligned or a resampled
lens grid, lfcl/grid/model.py), the method registry and the aligned solver (methods.py), the resampled solver,
the starts, flat lenses, the safety net and ``--method auto``.

Importing this package imports nothing heavy: lfcl/demosaic/names.py feeds ``lfcl --help``."""
