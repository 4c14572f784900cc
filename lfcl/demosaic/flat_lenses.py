"""Skip the lenses that are flat: no ADMM for them, their colour means instead (issue #6).

A lens whose samples are one constant per colour plus noise (an in-focus flat patch, a
sky, a backdrop, a dark or clipped area) needs no iterations: for such a lens the best
estimate of its light field is that constant, the weighted mean of its samples of each
colour, and the (u, v) prior would only spend iterations smoothing noise towards it. The
test is a chi-square one against the raw's noise model (lfcl/ops/flatlens.py): a lens is
flat when its p-value is above ``FLAT_P`` (the chance that pure noise on a flat lens looks
at least as structured). Only the (u, v) priors (admm-uv, admm-uv-xc) couple no two lenses,
so only they can leave lenses out; the others solve every lens.

The lenses still to solve are packed into a smaller mosaic (:class:`LensPacking`): every
lens keeps its row and column parity, so its Bayer phase, and the packed grid's lens rows
come from a fixed ladder (sixteenths of the sensor's) so that PoCL, which compiles a kernel
for every new global size, compiles a handful of sizes per sensor and not one per image.

Measured (docs/auto.md, ``python research/flat.py``): filling flat lenses with their
means gains PSNR on both views, and the ADMM work drops by the flat share.

Example::

    >>> import numpy as np
    >>> from lfcl.demosaic.flat_lenses import pack_lenses
    >>> active = np.array([[True, False, False, True], [False, False, False, False]])
    >>> packing = pack_lenses(active)
    >>> packing.grid, packing.source.tolist(), packing.target.tolist()
    ((1, 4), [0, 3], [0, 1])
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.special

from ..noise.model import NoiseEstimate
from ..ops.flatlens import LensFlatness, colour_counts, lens_flatness_np
from ..ops.lenscopy import fill_lenses_np
from .names import FLAT_P, SKIPPABLE  # noqa: F401  (SKIPPABLE: re-exported for lfcl.demosaic.methods)

#: The packed grid's lens rows are whole sixteenths of the sensor's (module docstring).
LADDER_STEPS = 16


@dataclasses.dataclass
class FlatLenses:
    """Which lenses are flat, and their colour means."""

    flat: np.ndarray  # [S, T] bool
    means: np.ndarray  # [S, T, 3] float64: the weighted mean of each colour's lit samples
    p_value: np.ndarray  # [S, T]
    threshold: float

    def flat_means(self) -> tuple[np.ndarray, np.ndarray]:
        """The flat lenses' indices s * T + t and their colour means [n, 3]."""
        lenses = np.flatnonzero(self.flat)
        return lenses, self.means.reshape(-1, self.means.shape[-1])[lenses]

    @property
    def share(self) -> float:
        return float(self.flat.mean()) if self.flat.size else 0.0

    def as_dict(self, solved_rows: int | None = None) -> dict:
        """For the outputs' metadata: the counts and the rule, not the per-lens maps.

        ``solved_rows``: the packed solver's lens rows, or None when the flat lenses were too
        few to shrink the solve (then every lens was solved and ``flat_lenses`` is 0).
        """
        S, found = self.flat.shape[0], int(self.flat.sum())
        rule = f"flat within the noise, chi-square p > {self.threshold:g}"
        if solved_rows is None:
            why = (f"{found} lenses {rule}, too few to shrink the solve: every lens solved" if found
                   else f"no lens {rule}")
        else:
            why = f"{rule}: each takes its colour means"
        return {"p_threshold": self.threshold, "found": found, "flat_lenses": found if solved_rows is not None else 0,
                "lenses": int(self.flat.size), "share": self.share, "why": why,
                "solved_lens_rows": solved_rows if solved_rows is not None else S, "sensor_lens_rows": S}


def flat_lenses(mosaic: np.ndarray, pattern: str, pitch, noise: NoiseEstimate, *, origin=(0, 0),
                lens_weights=None, threshold: float = FLAT_P, statistics=None) -> FlatLenses:
    """Test every lens of ``mosaic`` (flat-fielded, [S*U, T*V]) for flatness against ``noise``.

    ``statistics``: the [S, T, 4] means and chi2 already computed (on the device), else the
    numpy reference computes them. A lens is flat only if every colour has at least two lit
    samples (one sample cannot show noise).
    """
    if not (isinstance(threshold, (int, float)) and 0 < threshold < 1):
        raise ValueError(f"the flat-lens p threshold must be in (0, 1), got {threshold!r}")
    if statistics is None:
        statistics = lens_flatness_np(mosaic, pattern, pitch, origin, lens_weights, gain=noise.gain,
                                      floor=noise.floor)
    counts = colour_counts(mosaic.shape, pattern, pitch, origin, lens_weights)
    dof = np.maximum(counts - 1, 0).sum(axis=-1)
    p_value = scipy.special.chdtrc(np.maximum(dof, 1), statistics[..., 3])  # chi-square survival function
    testable = (counts >= 2).all(axis=-1) & np.isfinite(statistics).all(axis=-1)
    flat = testable & (p_value > threshold)
    return FlatLenses(flat, statistics[..., :3].astype(np.float64), p_value, float(threshold))


def flat_lenses_on_device(runtime, device_mosaic, mosaic: np.ndarray, pattern: str, pitch, noise: NoiseEstimate, *,
                          origin=(0, 0), lens_weights=None, threshold: float = FLAT_P) -> FlatLenses:
    """:func:`flat_lenses` with the per-lens statistics computed on the device from ``device_mosaic`` (``mosaic``
    there): only the [S, T, 4] statistics come back to the host."""
    statistics = LensFlatness(runtime, mosaic.shape, pattern, pitch, origin)(device_mosaic, lens_weights, noise.gain,
                                                                             noise.floor)
    return flat_lenses(mosaic, pattern, pitch, noise, origin=origin, lens_weights=lens_weights, threshold=threshold,
                       statistics=statistics)


def fill_flat(planes: np.ndarray, found: FlatLenses, pitch) -> np.ndarray:
    """Set every flat lens of ``planes`` [3, S*U, T*V] (in place) to its colour means; returns planes."""
    lenses, means = found.flat_means()
    return fill_lenses_np(planes, lenses, means, pitch)


@dataclasses.dataclass(frozen=True)
class LensPacking:
    """Lens ``source[i]`` of the full grid (index s * T + t) sits at ``target[i]`` of the packed grid."""

    full: tuple[int, int]  # (S, T)
    grid: tuple[int, int]  # (S', T): the packed grid keeps the lens columns
    source: np.ndarray
    target: np.ndarray

    @property
    def real(self) -> np.ndarray:
        """[S', T] bool: the packed grid's lenses that hold a lens (the rest is zero padding)."""
        mask = np.zeros(self.grid, bool)
        mask.flat[self.target] = True
        return mask

    def pairs(self) -> np.ndarray:
        """(full-grid lens or -1 for zeros, packed lens) for every packed lens: the table of
        lfcl/ops/lenscopy.py, which packs device arrays as :meth:`pack` packs host ones."""
        pairs = np.full((self.grid[0] * self.grid[1], 2), -1, np.int64)
        pairs[:, 1] = np.arange(len(pairs))
        pairs[self.target, 0] = self.source
        return pairs

    def pack(self, array: np.ndarray, pitch) -> np.ndarray:
        """``array`` [..., S*U, T*V] -> [..., S'*U, T*V]: the packed lenses, zeros in the padding."""
        U, V = pitch
        lead = array.shape[:-2]
        full = array.reshape(-1, self.full[0], U, self.full[1], V)
        out = np.zeros((full.shape[0], self.grid[0], U, self.grid[1], V), array.dtype)
        s, t = np.divmod(self.source, self.full[1])
        s2, t2 = np.divmod(self.target, self.grid[1])
        out[:, s2, :, t2, :] = full[:, s, :, t, :]
        return out.reshape(*lead, self.grid[0] * U, self.grid[1] * V)

    def unpack_pairs(self) -> np.ndarray:
        """(packed lens, full-grid lens) for every solved lens: the table of lfcl/ops/lenscopy.py that
        puts the packed lenses back on the device, as :meth:`unpack` does on the host."""
        return np.stack([self.target, self.source], axis=1)

    def unpack(self, packed: np.ndarray, into: np.ndarray, pitch) -> np.ndarray:
        """Write the packed lenses back to their places in ``into`` [..., S*U, T*V] (in place)."""
        U, V = pitch
        full = into.reshape(-1, self.full[0], U, self.full[1], V)
        grid = packed.reshape(-1, self.grid[0], U, self.grid[1], V)
        s, t = np.divmod(self.source, self.full[1])
        s2, t2 = np.divmod(self.target, self.grid[1])
        full[:, s, :, t, :] = grid[:, s2, :, t2, :]
        return into


def _slots(rows: int, columns: int, parity: tuple[int, int]) -> np.ndarray:
    """Lens indices of a rows x columns grid with the given (row, column) parity, row by row."""
    s, t = np.meshgrid(np.arange(parity[0], rows, 2), np.arange(parity[1], columns, 2), indexing="ij")
    return (s * columns + t).ravel()


def pack_lenses(active: np.ndarray) -> LensPacking:
    """The smallest packed grid (lens rows from the ladder) that holds the ``active`` lenses [S, T],
    each at a slot of its own row and column parity (odd pitch: its Bayer phase), in order."""
    S, T = active.shape
    ladder = sorted({max(1, math.ceil(S * k / LADDER_STEPS)) for k in range(1, LADDER_STEPS + 1)})
    parities = [(a, b) for a in range(2) for b in range(2)]
    chosen = {p: np.flatnonzero((active & ((np.arange(S)[:, None] % 2 == p[0]) & (np.arange(T) % 2 == p[1])))
                                .ravel()) for p in parities}
    rows = next(r for r in ladder if all(len(_slots(r, T, p)) >= len(chosen[p]) for p in parities))
    source = np.concatenate([chosen[p] for p in parities])
    target = np.concatenate([_slots(rows, T, p)[:len(chosen[p])] for p in parities])
    order = np.argsort(source, kind="stable")
    return LensPacking((S, T), (rows, T), source[order], target[order])


def skipped_flat_lenses(record: dict | None) -> list[dict]:
    """The ``skipped`` entry of `lfcl process` for ``parameters["flat_lenses"]`` ([] if none was skipped)."""
    if record and record.get("ignored"):  # asked for, but the method auto picked solves every lens
        return [{"output": "--skip-flat", "stage": "demosaic", "reason": record["why"]}]
    if not record or not record.get("flat_lenses"):
        return []
    return [{"output": f"ADMM on {record['flat_lenses']} of {record['lenses']} lenses", "stage": "demosaic",
             "reason": record["why"]}]
