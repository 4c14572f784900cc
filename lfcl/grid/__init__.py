"""The lens grid: lattice, calibration from a white image, the two paths and the vignetting (docs/calibration.md).

* :mod:`~lfcl.grid.lattice`      :class:`LensGrid`: square / hexagonal lattices, lens (i, j) <-> pixel
* :mod:`~lfcl.grid.calibration`  :class:`Calibration`, :class:`WeightModel`
* :mod:`~lfcl.grid.estimate`     estimation from a white image (:func:`calibrate_array`, :func:`calibrate_white`)
* :mod:`~lfcl.grid.files`        ``cal.json`` read (validated) / write, the lens-centre CSV
* :mod:`~lfcl.grid.aligned`      which path a grid takes: exact slicing (aligned square) or resampling
* :mod:`~lfcl.grid.model`        the typed grid the demosaic takes: :class:`AlignedGrid`, :class:`ResampledGrid`
* :mod:`~lfcl.grid.resampling`   the sampling model of any grid: regular light field <-> sensor pixels
* :mod:`~lfcl.grid.vignetting`   the white response: flat-fielding and the data-term weights

Example::

    >>> from lfcl.grid import LensGrid
    >>> grid = LensGrid.from_params("hex", pitch=10.3, rotation_deg=0.5, offset=(0.3, 0.7))
    >>> i, j, rows, cols = grid.centres((600, 600))
"""

from .calibration import VERSION, Calibration, WeightModel
from .estimate import CalibrationError, calibrate_array, calibrate_white, calibration_from_pitch
from .files import (
    calibration_from_dict,
    calibration_to_dict,
    load_calibration,
    read_centres_csv,
    save_calibration,
    write_centres_csv,
)
from .lattice import PACKINGS, LensGrid

__all__ = [
    "PACKINGS", "VERSION", "Calibration", "CalibrationError", "LensGrid", "WeightModel", "calibrate_array",
    "calibrate_white", "calibration_from_dict", "calibration_from_pitch", "calibration_to_dict",
    "load_calibration", "read_centres_csv", "save_calibration", "write_centres_csv",
]
