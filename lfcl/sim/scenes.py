"""Built-in scenes and :func:`render_scene`.

A scene is a list of :class:`lfcl.sim.planes.Plane`, front to back, built for a
lens count (and seed). ``charts`` (:mod:`lfcl.sim.charts`), ``deadleaves``
(:mod:`lfcl.sim.deadleaves`), ``finetexture`` (:mod:`lfcl.sim.finetexture`), ``periodic``
(:mod:`lfcl.sim.periodic`, repeating content: a stress scene no default was fitted on) and ``gratings``
(:mod:`lfcl.sim.gratings`, lens-scale gratings off the focal plane, drawn per seed) need no files. :func:`render_disparity` / :func:`planes_disparity`: the true
centre-view disparity map of a scene. With ``texture=IMAGE`` the scene
keeps its planes (depths, disparities, supports, occlusion) but every plane
shows the image (:class:`lfcl.sim.texture.ImageTexture`), fitted to the plane's
box (the background: to the frame).

Rendered values are *relative* linear camera RGB (reflectance-like, roughly
0..1); :func:`lfcl.sim.capture.simulate` scales them to the requested mean
illuminance.
"""

from __future__ import annotations

import numpy as np

from .charts import charts_planes
from .deadleaves import deadleaves_planes
from .finetexture import finetexture_planes
from .gratings import gratings_planes
from .periodic import periodic_planes
from .planes import Plane, render_planes
from .texture import ImageTexture, read_linear

SCENES = ("charts", "deadleaves", "finetexture", "periodic", "gratings")


def check_scene(name: str) -> str:
    if not isinstance(name, str) or name.lower() not in SCENES:
        raise ValueError(f"unknown scene {name!r}: expected one of {', '.join(SCENES)}")
    return name.lower()


def scene_planes(name: str, lenses, seed: int = 0, pitch=(9, 9), texture=None) -> list[Plane]:
    """The planes of scene ``name``; ``texture`` (a path or a linear ``(H, W, 3)`` array) replaces their textures."""
    name = check_scene(name)
    S, T = (int(n) for n in lenses)
    if name == "charts":
        planes = charts_planes((S, T), seed)
    elif name == "finetexture":
        planes = finetexture_planes((S, T), seed, pitch)
    elif name == "periodic":
        planes = periodic_planes((S, T), seed)
    elif name == "gratings":
        planes = gratings_planes((S, T), seed)
    else:
        planes = deadleaves_planes((S, T), seed, pitch)
    if texture is not None:
        image = read_linear(texture) if not isinstance(texture, np.ndarray) else np.asarray(texture, np.float32)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"a texture must be an (H, W, 3) image, got shape {image.shape}")
        for plane in planes:
            box = plane.rect if plane.rect is not None else (0.0, 0.0, float(S), float(T))
            plane.texture = ImageTexture(image, box)
    return planes


def render_scene(name: str, lenses=(64, 64), pitch=9, seed: int = 0, *, texture=None,
                 supersample: int = 3, progress: bool | None = False) -> np.ndarray:
    """Render built-in scene ``name`` as ``[S, T, U, V, 3]`` float32 relative linear RGB (noise-free)."""
    U, V = (int(pitch), int(pitch)) if np.isscalar(pitch) else (int(n) for n in pitch)
    planes = scene_planes(name, lenses, seed, (U, V), texture)
    return render_planes(planes, lenses, (U, V), supersample=supersample, progress=progress)


def planes_disparity(planes, lenses) -> np.ndarray:
    """True centre-view disparity ``[S, T]`` float32 of ``planes`` (front to back), lenses per view step.

    Lens ``(s, t)`` gets the disparity of the frontmost plane whose support covers
    its centre ``(s + 1/2, t + 1/2)`` seen from the centre of the views
    (``u - u0 = v - v0 = 0``); NaN where no plane does. Sign convention of
    :mod:`lfcl.sim.planes`: a feature at row ``y`` of the centre view appears at
    ``y - d (u - u0)`` in view ``u``.
    """
    S, T = (int(n) for n in lenses)
    y, x = (a.ravel() for a in np.meshgrid(np.arange(S) + 0.5, np.arange(T) + 0.5, indexing="ij"))
    out = np.full(S * T, np.nan, dtype=np.float32)
    open_ = np.ones(S * T, dtype=bool)
    for plane in planes:
        hit = open_ & plane.covers(x, y)
        out[hit] = plane.disparity
        open_ &= ~hit
    return out.reshape(S, T)


def render_disparity(name: str, lenses=(64, 64), seed: int = 0, pitch=9) -> np.ndarray:
    """True centre-view disparity ``[S, T]`` float32 of built-in scene ``name`` (:func:`planes_disparity`)."""
    U, V = (int(pitch), int(pitch)) if np.isscalar(pitch) else (int(n) for n in pitch)
    return planes_disparity(scene_planes(name, lenses, seed, (U, V)), lenses)
