"""The lens grid a raw is demosaiced on, as a typed value: :class:`AlignedGrid` or :class:`ResampledGrid`.

An aligned square grid of integer pitch is sliced into lenses exactly (lfcl/demosaic/methods.py); any other
calibrated grid (rotated, non-integer pitch, sub-pixel offset, hexagonal) is demosaiced through its sampling
model, the resampling inside the forward operator (lfcl/demosaic/resampled.py, docs/geometry.md). What differs
between the two -- the kind the outputs record, the words messages use, the methods and starts it takes, whether
the safety net applies, its lens count, the ``geometry`` record of every output -- is an attribute of the grid
here, not a branch on a metadata string. The Grid stage (lfcl/pipeline/stages.py) builds one; the demosaic
driver (lfcl/demosaic/driver.py) takes one.

A grid may be a description only (``AlignedGrid.pitch`` or ``ResampledGrid.sampling`` None), e.g. a
calibration checked before any raw is read; the driver needs the whole grid.

Example::

    >>> grid = AlignedGrid(9)
    >>> grid.pitch, grid.kind, grid.words
    ((9, 9), 'aligned-square', 'aligned square')
    >>> ResampledGrid(None, "hex").words, ResampledGrid(None, "square", ("rotated",)).words
    ('hexagonal', 'rotated square')
"""

from __future__ import annotations

import dataclasses
import numbers
from typing import ClassVar

from ..demosaic.names import METHODS, RESAMPLED_METHODS, STARTS
from .aligned import ALIGNED, RESAMPLED

#: The grid kinds: the ``grid`` of the outputs' ``geometry`` record, ``AlignedGrid.kind`` and ``ResampledGrid.kind``.
GRID_KINDS = (ALIGNED, RESAMPLED)


def _pair(value, what: str) -> tuple[int, int]:
    """``value`` as a pair of whole numbers (one number: twice), or a one-line ValueError naming ``what``."""
    pair = (value, value) if isinstance(value, numbers.Integral) else tuple(value) if hasattr(value, "__iter__") else ()
    if len(pair) != 2 or not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in pair):
        raise ValueError(f"{what} must be a whole number or a pair of them, got {value!r}")
    return int(pair[0]), int(pair[1])


@dataclasses.dataclass(frozen=True, eq=False)
class AlignedGrid:
    """An aligned square grid of integer pitch: the mosaic is sliced into whole lenses exactly.

    ``pitch``: pixels per lens, ``(U, V)`` or an int for ``U = V`` (None: not known yet). ``origin``: the
    sensor (row, col) of the mosaic's first pixel, which gives its Bayer phase (for the Grid stage also the
    first whole lens's top-left pixel). ``lenses``: ``(S, T)``, None: as many as the mosaic holds.
    ``lens_response``: ``[U, V]`` vignetting from a white image (lfcl/grid/vignetting.py) or None.
    """

    pitch: tuple | None
    origin: tuple = (0, 0)
    lenses: tuple | None = None
    lens_response: object = None  # numpy [U, V] or None

    kind: ClassVar[str] = ALIGNED
    words: ClassVar[str] = "aligned square"
    #: The method names it takes (lfcl.demosaic.names.METHODS: all of them) and the ADMM starts.
    methods: ClassVar[tuple] = METHODS
    starts: ClassVar[tuple] = STARTS
    #: Whether the safety net (lfcl/demosaic/safety_net.py) applies: it compares lens means on whole lenses.
    safety_net: ClassVar[bool] = True

    def __post_init__(self):
        if self.pitch is not None:
            pitch = _pair(self.pitch, "an aligned grid's pitch")
            if min(pitch) < 1:
                raise ValueError(f"an aligned grid's pitch must be >= 1 pixel, got {self.pitch!r}")
            object.__setattr__(self, "pitch", pitch)
        object.__setattr__(self, "origin", _pair(self.origin, "an aligned grid's origin"))
        if self.lenses is not None:
            object.__setattr__(self, "lenses", _pair(self.lenses, "an aligned grid's lens count"))

    def check_complete(self) -> None:
        """A one-line ValueError if this is a description only (no pitch): the driver needs the whole grid."""
        if self.pitch is None:
            raise ValueError("an aligned lens grid needs its pitch (AlignedGrid.pitch)")

    def check_method(self, method: str, what: str | None = None) -> str:
        """``method`` if it runs on this grid, else a one-line ValueError (every known method runs here)."""
        if method not in self.methods:
            raise ValueError(f"unknown method {method!r}: expected one of {', '.join(self.methods)}")
        return method

    def check_options(self, start=None, skip_flat=None) -> None:
        """A one-line ValueError for a ``start`` it does not take (``skip_flat`` is checked per method later)."""
        if start not in (None, *self.starts):
            raise ValueError(f"start must be one of {', '.join(self.starts)}, got {start!r}")

    def geometry(self, how: str) -> dict:
        """The ``geometry`` record of the outputs (docs/outputs.md): ``how`` is where the grid came from."""
        S, T = self.lenses
        return {"grid": self.kind, "pitch": list(self.pitch), "lenses": [S, T],
                "first_lens_pixel": list(self.origin), "from": how}


@dataclasses.dataclass(frozen=True, eq=False)
class ResampledGrid:
    """Any other calibrated grid, demosaiced through its sampling model (docs/geometry.md).

    ``sampling``: the :class:`lfcl.grid.resampling.SamplingModel` (None: not built yet). ``packing``:
    ``square`` or ``hex``. ``features``: why it is resampled (lfcl.grid.aligned.fit_grid: ``rotated``,
    ``non-integer-pitch``, ``sub-pixel-offset``, ``non-aligned``, ``hexagonal``), for its words.
    """

    sampling: object  # lfcl.grid.resampling.SamplingModel or None
    packing: str = "square"
    features: tuple = ()

    kind: ClassVar[str] = RESAMPLED
    #: ``auto`` and the methods the resampled solver has; it starts from Malvar only and has no safety net.
    methods: ClassVar[tuple] = ("auto", *RESAMPLED_METHODS)
    starts: ClassVar[tuple] = ("malvar",)
    safety_net: ClassVar[bool] = False

    def __post_init__(self):
        object.__setattr__(self, "features", tuple(self.features or ()))

    @classmethod
    def of(cls, source, pattern: str | None = None, *, views=None, threshold: float | None = None, lenses=None,
           features=()) -> ResampledGrid:
        """The grid of a :class:`lfcl.grid.Calibration`, a :class:`lfcl.sim.geometry.GridGeometry` (through
        :func:`lfcl.grid.resampling.sampling_model` with ``views``, ``threshold``, ``lenses``) or a ready
        ``SamplingModel`` (then ``pattern``, if given, must be its pattern)."""
        from ..layout import parse_pattern
        from .resampling import SamplingModel, sampling_model

        if isinstance(source, SamplingModel):
            if pattern is not None and parse_pattern(pattern) != source.pattern:
                raise ValueError(f"the raw is {parse_pattern(pattern)} but the sampling model is for "
                                 f"{source.pattern}")
            sampling = source
        else:
            sampling = sampling_model(source, pattern, views=views, threshold=threshold, lenses=lenses)
        return cls(sampling, sampling.grid.packing, features)

    @property
    def words(self) -> str:
        """``hexagonal`` or e.g. ``rotated, non-integer-pitch square``: the grid in words, for messages."""
        if self.packing == "hex":
            return "hexagonal"
        return f"{', '.join(self.features or ('non-aligned',))} square"

    @property
    def pitch(self) -> tuple:
        """``(U, V)``: the views per lens of the regular light field."""
        return tuple(self.sampling.views)

    @property
    def lenses(self) -> tuple:
        """``(S, T)``: the regular light field's lenses."""
        return tuple(self.sampling.lenses)

    def check_complete(self) -> None:
        """A one-line ValueError if this is a description only (no sampling model): the driver needs the whole
        grid."""
        if self.sampling is None:
            raise ValueError("a resampled lens grid needs its sampling model (Gridded.sampling, ResampledGrid.of)")

    def check_method(self, method: str, what: str | None = None) -> str:
        """``method`` if it runs on this grid, else a one-line ValueError naming those that do (``what``: the
        grid, for the message; default ``the <words> lens grid``)."""
        if method not in self.methods:
            raise ValueError(f"method {method!r} does not run on {what or f'the {self.words} lens grid'}: the "
                             "resampling path (rotated, non-integer-pitch, hexagonal grids) takes "
                             f"{', '.join(self.methods)}")
        return method

    def check_options(self, start=None, skip_flat=None) -> None:
        """A one-line ValueError for a start other than Malvar's or for skipping flat lenses: aligned grids only."""
        if start not in (None, *self.starts):
            raise ValueError(f"start {start} needs an aligned square lens grid; this one is {self.words} (use the "
                             "default start)")
        if skip_flat not in (None, False):
            raise ValueError(f"skipping flat lenses needs an aligned square lens grid; this one is {self.words} "
                             "(leave skip_flat out)")

    def geometry(self, how: str) -> dict:
        """The ``geometry`` record of the outputs (docs/outputs.md): ``how`` is where the grid came from."""
        (U, V), (S, T) = self.sampling.views, self.sampling.lenses
        return {"grid": self.kind, "pitch": [U, V], "lenses": [S, T], "from": how, "packing": self.packing,
                "features": list(self.features), "lens_origin": list(self.sampling.lens_origin)}


def lens_grid(geometry: dict, *, pitch=None, origin=None, lenses=None, lens_response=None, sampling=None):
    """The typed grid a ``geometry`` record describes (the Grid stage's ``metadata["geometry"]``, a
    ``summary.json``'s, or ``{"grid": kind, "packing": ..., "features": ...}`` from lfcl.grid.aligned.fit_grid):
    the one place that reads its ``grid`` string. ``pitch``, ``origin``, ``lenses``, ``lens_response`` complete
    an aligned grid (default: the record's), ``sampling`` a resampled one. An unknown kind is a one-line
    ValueError naming :data:`GRID_KINDS`."""
    kind = geometry.get("grid")
    if kind == ALIGNED:
        return AlignedGrid(pitch if pitch is not None else geometry.get("pitch"),
                           origin if origin is not None else geometry.get("first_lens_pixel", (0, 0)),
                           lenses if lenses is not None else geometry.get("lenses"), lens_response)
    if kind == RESAMPLED:
        return ResampledGrid(sampling, geometry.get("packing", "square"), tuple(geometry.get("features") or ()))
    raise ValueError(f"lens grid {kind!r} is not one it takes ({', '.join(GRID_KINDS)})")
