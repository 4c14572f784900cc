"""Lenslet (plenoptic) camera simulator with exact ground truth.

A scene (fronto-parallel textured planes, or a loaded 4D light field) is
rendered as a light field ``[S, T, U, V, 3]``, scaled to a mean illuminance,
CFA-sampled through a microlens geometry and exposed by a noisy sensor model
(paper section 2.2; docs/simulator.md). Modules, one job each:

* :mod:`~lfcl.sim.geometry`   microlens grid: sample <-> sensor pixel, vignetting
* :mod:`~lfcl.sim.planes`     planes renderer (disparity, occlusion, sub-sampling)
* :mod:`~lfcl.sim.charts`     the ``charts`` scene (resolution charts)
* :mod:`~lfcl.sim.deadleaves` the ``deadleaves`` scene
* :mod:`~lfcl.sim.finetexture` the ``finetexture`` scene (lens-scale detail off the focal plane)
* :mod:`~lfcl.sim.texture`    images as linear RGB and as plane textures
* :mod:`~lfcl.sim.scenes`     scene registry, :func:`render_scene`
* :mod:`~lfcl.sim.lightfield` loading HCI folders and ``.npy`` light fields
* :mod:`~lfcl.sim.sensor`     :class:`SensorModel`: lux -> electrons -> DN
* :mod:`~lfcl.sim.dng`        CFA DNG writer
* :mod:`~lfcl.sim.capture`    :func:`simulate`, :class:`Capture`, :func:`write_capture`

Example::

    >>> from lfcl.sim import simulate
    >>> cap = simulate("charts", lenses=(8, 8), lux=12.0, seed=0)
    >>> cap.raw.shape, cap.truth.shape
    ((72, 72), (8, 8, 9, 9, 3))
"""

from .capture import Capture, parse_exposure, parse_lenses, simulate, write_capture
from .geometry import LensletGeometry
from .lightfield import load_lightfield
from .planes import Plane, render_planes
from .scenes import SCENES, render_scene, scene_planes
from .sensor import SensorModel

__all__ = [
    "SCENES", "Capture", "LensletGeometry", "Plane", "SensorModel", "load_lightfield", "parse_exposure",
    "parse_lenses", "render_planes", "render_scene", "scene_planes", "simulate", "write_capture",
]
