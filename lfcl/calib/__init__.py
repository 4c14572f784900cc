"""Lenslet calibration: the lens grid and the white-image weight model of a camera (docs/calibration.md).

* :mod:`~lfcl.calib.grid`      :class:`LensGrid`: square / hexagonal lattices, lens (i, j) <-> pixel
* :mod:`~lfcl.calib.model`     :class:`Calibration`, :class:`WeightModel`
* :mod:`~lfcl.calib.estimate`  estimation from a white image (:func:`calibrate_array`, :func:`calibrate_white`)
* :mod:`~lfcl.calib.io`        ``cal.json`` read (validated) / write, the lens-centre CSV

Example::

    >>> from lfcl.calib import LensGrid
    >>> grid = LensGrid.from_params("hex", pitch=10.3, rotation_deg=0.5, offset=(0.3, 0.7))
    >>> i, j, rows, cols = grid.centres((600, 600))
"""

from .estimate import CalibrationError, calibrate_array, calibrate_white, calibration_from_pitch
from .grid import PACKINGS, LensGrid
from .io import (
    calibration_from_dict,
    calibration_to_dict,
    load_calibration,
    read_centres_csv,
    save_calibration,
    write_centres_csv,
)
from .model import VERSION, Calibration, WeightModel

__all__ = [
    "PACKINGS", "VERSION", "Calibration", "CalibrationError", "LensGrid", "WeightModel", "calibrate_array",
    "calibrate_white", "calibration_from_dict", "calibration_from_pitch", "calibration_to_dict",
    "load_calibration", "read_centres_csv", "save_calibration", "write_centres_csv",
]
