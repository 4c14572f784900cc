"""Freeze the lenses that have stopped changing and drop them from the work (issue #6).

With a prior over (u, v) only (admm-uv, admm-uv-xc) the problem is separable lens by
lens: A^T W A + rho K^T K is block diagonal per lens, the shrinkage is element-wise and
K = M [D_uv; D_uv C] joins pixels of one lens only. A lens's ADMM trajectory therefore does
not depend on any other lens, and a group of lenses can be moved into a smaller solver and
go on there exactly as it would have in the whole one.

The rule: the global stop rule (rms change of the whole light field <= change_tol) still
decides when the solve stops. After every iteration from the second on, each *block* of
2 x 4 lenses (2 lens rows, 4 lens columns) whose own rms change is <= ``fraction *
change_tol`` is a candidate; once the blocks that are not candidates are at most
``shrink_at`` of the blocks in the current solver, the candidates are frozen (they keep
their x) and the others move, with their x, z, u (zc, uc) and mosaic, into a smaller
AdmmSolver (lfcl/ops/lenscopy.py), where the iteration goes on. The history stays the whole
problem's: the rms change is over all samples, and it, the misfit, the prior and the primal
residual add the frozen lenses' values of the iteration they froze at (constants afterwards;
a frozen lens's change is far below the tolerance, but counting it as 0 let the global rule
stop one iteration early on charts at 50 lux and cost 0.05 dB on the mean image).

Why blocks of 2 x 4 lenses: ``lens_solve`` already leaves each work-item's squared update
on the host every iteration (its work-items g = 2j, 2j + 1 hold lenses 4j .. 4j + 3 of a
lens row), so a block's change costs nothing; 2 lens rows and 4 lens columns keep every
lens's Bayer phase when blocks move to even positions (odd pitch). Whole lens rows were the
first design, but on the built-in scenes a lens row almost never falls far below the
tolerance before the whole image does (docs/auto.md).

Example::

    >>> import numpy as np
    >>> from lfcl.device import get_runtime
    >>> from lfcl.solvers.admm import AdmmSolver
    >>> from lfcl.solvers.freeze import FreezeSettings, solve_with_freezing
    >>> from lfcl.solvers.params import AdmmParams
    >>> rt = get_runtime()
    >>> b = rt.to_device(np.full((36, 72), 0.5, np.float32))
    >>> x0 = rt.to_device(np.full((3, 36, 72), 0.5, np.float32))
    >>> solver = AdmmSolver(rt, (36, 72), "GRBG", (9, 9), "uv")
    >>> result, report = solve_with_freezing(solver, b, x0, AdmmParams(lam=0.01, change_tol=1e-4),
    ...                                      FreezeSettings(fraction=0.2))
    >>> result.x.shape, report.lenses
    ((3, 36, 72), 32)
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pyopencl.array as cla

from ..ops import check_device_array
from ..ops.lenscopy import LensCopy
from .admm import AdmmSolver, OutsideSums
from .params import AdmmParams, AdmmResult, IterationRecord

BLOCK = (2, 4)  # lens rows x lens columns frozen together (module docstring)


@dataclasses.dataclass(frozen=True)
class FreezeSettings:
    """When lenses freeze and when the solver shrinks.

    fraction:  a block of lenses freezes when its rms change per iteration is <= fraction *
               change_tol (0 < fraction <= 1; 0 turns freezing off).
    shrink_at: the frozen blocks leave the work once the blocks still changing are at most
               this share of the current solver's blocks (0 < shrink_at < 1): each move costs
               a solver and a copy, so it waits until it pays.
    """

    fraction: float = 0.3  # measured: at most 0.004 dB lost, docs/auto.md
    shrink_at: float = 0.75

    def __post_init__(self):
        if not (isinstance(self.fraction, (int, float)) and 0 <= self.fraction <= 1):
            raise ValueError(f"freeze fraction must be a number in [0, 1], got {self.fraction!r}")
        if not (isinstance(self.shrink_at, (int, float)) and 0 < self.shrink_at < 1):
            raise ValueError(f"freeze shrink_at must be a number in (0, 1), got {self.shrink_at!r}")


@dataclasses.dataclass
class FreezeReport:
    """What freezing did in one solve (all counts in lenses or lens-iterations)."""

    applied: bool  # False: the solve ran plain (``why`` says why)
    why: str
    lenses: int  # lenses of the problem
    iterations: int = 0
    frozen_lenses: int = 0
    lens_iterations_skipped: int = 0  # sum over frozen lenses of the iterations after they froze
    slot_iterations: int = 0  # lens slots x iterations the solvers ran (moved grids have padding)
    moves: list = dataclasses.field(default_factory=list)  # one dict per move to a smaller solver
    frozen_at: np.ndarray | None = None  # [S, T] the iteration each lens froze at, 0 for never (not in as_dict)

    @property
    def skipped_share(self) -> float:
        """The share of the plain solve's lens-iterations that froze lenses skipped."""
        total = self.lenses * self.iterations
        return self.lens_iterations_skipped / total if total else 0.0

    @property
    def work_share(self) -> float:
        """Lens-iterations run (padding included) relative to the plain solve's."""
        total = self.lenses * self.iterations
        return self.slot_iterations / total if total else 1.0

    def as_dict(self) -> dict:
        """For the outputs' metadata (JSON): the counts and moves, not the per-lens map."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "frozen_at"}
        return {**fields, "skipped_share": self.skipped_share, "work_share": self.work_share}


def combine_reports(reports: list[FreezeReport]) -> dict:
    """One summary of several solves' reports (bands of lens rows), as a dict."""
    if len(reports) == 1:
        return reports[0].as_dict()
    lens_iterations = sum(r.lenses * r.iterations for r in reports)
    skipped = sum(r.lens_iterations_skipped for r in reports)
    slots = sum(r.slot_iterations for r in reports)
    return {"applied": any(r.applied for r in reports), "why": "; ".join(sorted({r.why for r in reports})),
            "bands": len(reports), "lenses": sum(r.lenses for r in reports),
            "frozen_lenses": sum(r.frozen_lenses for r in reports), "lens_iterations_skipped": skipped,
            "slot_iterations": slots, "skipped_share": skipped / lens_iterations if lens_iterations else 0.0,
            "work_share": slots / lens_iterations if lens_iterations else 1.0}


def why_not_frozen(solver: AdmmSolver, params: AdmmParams, settings: FreezeSettings) -> str | None:
    """Why freezing does not apply to this solve (None: it does). :meth:`AdmmSolver.prepare` first."""
    if settings.fraction <= 0:
        return "freeze fraction 0"
    if solver.dims != ("u", "v"):
        return f"the {''.join(solver.dims)} prior couples neighbouring lenses"
    if not solver.exact_update:
        return "the x-update is CG, not the exact per-lens solve (no per-lens change)"
    if params.change_tol <= 0:
        return "no stop rule on the change of x to compare against"
    if params.abs_tol > 0 or params.rel_tol > 0:
        return "the residual stop rule (abs_tol, rel_tol) needs all lenses' state"
    return None


@dataclasses.dataclass
class _Stage:
    """One solver of the sequence: its x and mosaic, and where its lenses come from."""

    solver: AdmmSolver
    x: object
    b: object
    lens_map: np.ndarray  # [S, T] padded to whole blocks: index of the lens in the full grid, -1 for none
    first_iteration: int = 0  # the history's length when this stage began

    @property
    def lens_slots(self) -> int:
        """Lenses the stage's solver works on (padding included)."""
        return (self.solver.height // self.solver.U) * (self.solver.width // self.solver.V)

    @property
    def block_lenses(self) -> np.ndarray:
        """Real lenses per block [block rows, block columns]."""
        s, t = self.lens_map.shape
        return (self.lens_map >= 0).reshape(s // BLOCK[0], BLOCK[0], t // BLOCK[1], BLOCK[1]).sum(axis=(1, 3))


def _padded(shape) -> tuple[int, int]:
    return tuple(-(-n // k) * k for n, k in zip(shape, BLOCK))


def block_change2(solver: AdmmSolver) -> np.ndarray:
    """The squared change of x per block in the last iteration, [block rows, block columns]."""
    groups = solver.lens_group_changes()  # [S, ceil(T / 4)]
    rows = _padded(groups.shape)[0]
    groups = np.pad(groups, ((0, rows - groups.shape[0]), (0, 0)))
    return groups.reshape(rows // BLOCK[0], BLOCK[0], -1).sum(axis=1)


def block_rms_change(change2: np.ndarray, solver: AdmmSolver, block_lenses: np.ndarray) -> np.ndarray:
    """The rms change per block from its squared change (inf for blocks without a lens)."""
    samples = 3 * solver.U * solver.V * block_lenses
    return np.where(samples > 0, np.sqrt(change2 / np.maximum(samples, 1)), np.inf)


def solve_with_freezing(solver: AdmmSolver, b, x0, params: AdmmParams, settings: FreezeSettings,
                        callback=None, lens_weights=None, samples: int | None = None) -> tuple[AdmmResult, FreezeReport]:
    """:meth:`AdmmSolver.solve` that freezes converged blocks of lenses (module docstring).

    Same arguments (``samples`` too) and result as ``solver.solve``; ``callback(record, x)`` gets the current
    solver's x (after a move, the lenses still changing, in blocks, padded with zeros).
    Where freezing does not apply (:func:`why_not_frozen`) this is ``solver.solve``.
    """
    solver.set_lens_weights(lens_weights)
    check_device_array(b, (solver.height, solver.width), "b")
    check_device_array(x0, solver.planes_shape, "x0")
    solver.prepare(params, lens_weights)
    U, V = solver.U, solver.V
    S, T = solver.height // U, solver.width // V
    why = why_not_frozen(solver, params, settings)
    if why is not None:
        result = solver.solve(b, x0, params, callback=callback, lens_weights=lens_weights, samples=samples)
        return result, FreezeReport(False, why, S * T, iterations=result.iterations,
                                    slot_iterations=S * T * result.iterations)
    runtime, copy = solver.runtime, LensCopy(solver.runtime, (U, V))
    x_full = x0.copy()
    solver.start(x_full)
    lens_map = np.full(_padded((S, T)), -1, np.int64)
    lens_map[:S, :T] = np.arange(S * T).reshape(S, T)
    stage = _Stage(solver, x_full, b, lens_map)
    history: list[IterationRecord] = []
    outside = OutsideSums(samples=samples if samples is not None else x_full.size)
    report = FreezeReport(True, f"blocks of {BLOCK[0]}x{BLOCK[1]} lenses below {settings.fraction:g} x change_tol",
                          S * T)
    report.frozen_at = np.zeros((S, T), np.int64)
    moving: dict = {}
    columns = lens_map.shape[1] // BLOCK[1]  # moved solvers keep the full grid's width in blocks
    ladder = ladder_rows(lens_map.shape[0] // BLOCK[0], settings.shrink_at)

    def handover(current: AdmmSolver, record: IterationRecord, own: OutsideSums) -> bool:
        if record.iteration < 2:  # from a Malvar start the first x-update changes nothing
            return False
        lenses = stage.block_lenses
        change2 = block_change2(current)
        rms = block_rms_change(change2, current, lenses)
        keep = (lenses > 0) & (rms > settings.fraction * params.change_tol)
        n = int(keep.sum())
        if n == 0 or n > settings.shrink_at * np.count_nonzero(lenses):
            return False
        current_rows = -(-(current.height // current.U) // BLOCK[0])
        rows = min((r for r in ladder if r * columns >= n), default=current_rows)  # the smallest that holds them
        if rows >= current_rows:
            return False
        moving.update(keep=keep, grid=(rows, columns), own=own, change2=float(change2[~keep].sum()))
        return True

    while True:
        reason = stage.solver.iterate(stage.b, stage.x, params, history, callback=callback, outside=outside,
                                      handover=handover)
        report.slot_iterations += stage.lens_slots * (len(history) - stage.first_iteration)
        if reason is not None:
            break
        stage, frozen, frozen_sums = _move(stage, moving["keep"], moving["grid"], moving["own"], x_full, params, copy,
                                           lens_weights, runtime)
        stage.first_iteration = len(history)
        outside = OutsideSums(samples=outside.samples, misfit2=outside.misfit2 + frozen_sums.misfit2,
                              prior=outside.prior + frozen_sums.prior, primal2=outside.primal2 + frozen_sums.primal2,
                              change2=outside.change2 + moving["change2"])
        report.frozen_at.flat[frozen] = len(history)
        report.moves.append({"iteration": len(history), "frozen_lenses": len(frozen),
                             "active_lenses": int(np.count_nonzero(stage.lens_map >= 0)),
                             "solver_lenses": list(stage.lens_map.shape)})
    if stage.solver is not solver:  # the lenses still changing at the end go home
        _copy_home(stage, x_full, np.ones(stage.lens_map.shape, bool), copy)
    solver.finish(x_full)
    report.iterations = len(history)
    frozen = report.frozen_at[report.frozen_at > 0]
    report.frozen_lenses = len(frozen)
    report.lens_iterations_skipped = int(np.sum(report.iterations - frozen))
    return AdmmResult(x=x_full, history=history, stop_reason=reason), report


def _block_mask(blocks: np.ndarray) -> np.ndarray:
    """A per-block boolean array expanded to its lenses."""
    return np.repeat(np.repeat(blocks, BLOCK[0], axis=0), BLOCK[1], axis=1)


def _copy_home(stage: _Stage, x_full, lenses: np.ndarray, copy: LensCopy):
    """Copy the stage's x of the ``lenses`` (boolean, stage grid) to their place in the full x."""
    T = stage.solver.width // stage.solver.V
    s, t = np.nonzero(lenses & (stage.lens_map >= 0))
    copy(stage.x, x_full, np.stack([s * T + t, stage.lens_map[s, t]], axis=1))


def ladder_rows(block_rows: int, shrink_at: float) -> list[int]:
    """The block-row counts a moved solver may have, largest first: ceil(block_rows shrink_at^k).

    Sizes that depend only on the sensor and not on the data: PoCL compiles a kernel anew
    for every new global size (over a second each at 160x160 lenses) and keeps what it
    compiled on disk, so a fixed ladder pays that once per sensor size, not once per image.
    """
    rows, k = [], 1
    while not rows or rows[-1] > 1:
        rows.append(max(1, math.ceil(block_rows * shrink_at**k)))
        k += 1
    return sorted(set(rows), reverse=True)


def _compact(stage: _Stage, blocks: np.ndarray, grid_blocks: tuple[int, int]):
    """Lay the ``blocks`` (boolean, stage grid) of the stage side by side, row by row, in a new
    grid of ``grid_blocks`` (rows, columns) blocks: every lens keeps its position in its block,
    so its Bayer phase.

    Returns the new grid's lens map (full-grid index, -1 for padding) and the copy pairs
    (stage lens -> new lens; -1 -> padding lens, which gets zeros).
    """
    chosen = np.argwhere(blocks)  # [n, 2] block (row, column), in order
    rows, columns = grid_blocks
    S_new, T_new = rows * BLOCK[0], columns * BLOCK[1]
    T_old = stage.solver.width // stage.solver.V
    q_row, q_col = np.divmod(np.arange(len(chosen)), columns)
    i, j = np.meshgrid(np.arange(BLOCK[0]), np.arange(BLOCK[1]), indexing="ij")
    s = chosen[:, 0, None, None] * BLOCK[0] + i  # [n, 2, 4] lens positions in the stage grid
    t = chosen[:, 1, None, None] * BLOCK[1] + j
    s2 = q_row[:, None, None] * BLOCK[0] + i  # and in the new grid
    t2 = q_col[:, None, None] * BLOCK[1] + j
    new_map = np.full((S_new, T_new), -1, np.int64)
    new_map[s2, t2] = stage.lens_map[s, t]
    pairs = np.full((S_new * T_new, 2), -1, np.int64)  # padding lenses: zeros, they stay zero (no data)
    pairs[:, 1] = np.arange(S_new * T_new)
    real = stage.lens_map[s, t] >= 0
    pairs[(s2 * T_new + t2)[real], 0] = (s * T_old + t)[real]
    return new_map, pairs


def _move(stage: _Stage, keep: np.ndarray, grid_blocks: tuple[int, int], own: OutsideSums, x_full,
          params: AdmmParams, copy: LensCopy, lens_weights, runtime):
    """Freeze the blocks not in ``keep``; move the others into a new solver of ``grid_blocks``.

    The new solver works in the old one's memory (AdmmSolver ``buffers``): each state array is
    gathered into an old scratch buffer, whose role it takes, and the emptied state buffers
    become the new scratch (the queue runs in order, so each is read before it is reused).
    Returns the new stage, the frozen lenses (indices in the full grid) and their sums at this
    iteration: the stage's own sums minus the moved lenses', recomputed in the new solver
    (another solver for the frozen lenses alone would need a new size, so a new compile).
    """
    old, memory = stage.solver, stage.solver.buffers()
    U, V = old.U, old.V
    new_map, pairs = _compact(stage, keep, grid_blocks)
    frozen = (stage.lens_map >= 0) & ~_block_mask(keep)
    owned_x = stage.x is not x_full  # the first stage works on the full x itself: frozen lenses are home
    if owned_x:
        _copy_home(stage, x_full, frozen, copy)
    roles = {"z": "dz", "u": "z", "dz": "u", "rhs": "tmp", "zc": "dzc", "uc": "zc", "dxc": "dxc", "dzc": "uc"}
    given = {new: memory[was] for new, was in roles.items() if was in memory}
    if owned_x:
        given["tmp"] = stage.x
    solver = AdmmSolver(runtime, (new_map.shape[0] * U, new_map.shape[1] * V), old.pattern, (U, V), old.dims,
                        old.origin, buffers=given)
    x = cla.Array(runtime.queue, solver.planes_shape, np.float32, data=memory["rhs"].base_data,
                  offset=memory["rhs"].offset)
    b = runtime.empty((solver.height, solver.width))
    table = copy.upload(pairs)
    copy(stage.x, x, table)
    copy(stage.b, b, table)
    solver.prepare(params, lens_weights)  # allocates the cross-channel views
    for src, dst in zip(old.duals(), solver.duals()):  # z, u (zc, uc): each read before its memory is reused
        copy(src, dst, table)
    moved = solver.state_sums(b, x, params)
    frozen_sums = OutsideSums(samples=0, misfit2=max(own.misfit2 - moved.misfit2, 0.0),
                              prior=max(own.prior - moved.prior, 0.0), primal2=max(own.primal2 - moved.primal2, 0.0))
    return _Stage(solver, x, b, new_map), stage.lens_map[frozen], frozen_sums
