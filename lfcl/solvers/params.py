"""Parameters and results shared by the ADMM solvers (device and numpy reference)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np


@dataclasses.dataclass(frozen=True)
class AdmmParams:
    """Settings of the ADMM-TV solver (paper, section 3.4).

    lam:        weight of the TV prior (lambda).
    lam_xc:     weight of the cross-channel prior ||D C x||_1, C x = (x_R - x_G, x_B - x_G)
                (docs/admm.md); 0 (the paper's problem) leaves that block out of K.
    rho:        augmented-Lagrangian penalty; kappa = lam / rho is the shrinkage threshold.
    max_iter:   ADMM iterations at most.
    cg_steps:   conjugate-gradient steps at most per x-update (warm-started).
    cg_tol:     CG stops early when ||r|| <= cg_tol * ||rhs||.
    abs_tol, rel_tol: Boyd et al.'s stopping rule on the primal and dual residuals
                (0 disables it).
    change_tol: stop when rms(x_k - x_{k-1}) <= change_tol (0 disables it); the early
                stop that the noise-matched defaults use (docs/admm.md).
    x_update:   "auto" (exact per-lens solve when the prior is over (u, v) only, else CG),
                "cg" (always conjugate gradients) or "lens" (exact; (u, v) only). The
                numpy reference always uses CG.
    extrapolation: beta in [0, 1]: CG's warm start x_k + beta (x_k - x_{k-1}) instead of x_k, from
                the second x-update on (admm-epi's solver and the numpy reference; 0: x_k, the only
                value the other solvers take).
    """

    lam: float = 0.01
    lam_xc: float = 0.0
    rho: float = 0.3
    max_iter: int = 30
    cg_steps: int = 4
    cg_tol: float = 1e-4
    abs_tol: float = 0.0
    rel_tol: float = 0.0
    change_tol: float = 0.0
    x_update: str = "auto"
    extrapolation: float = 0.0

    def __post_init__(self):
        for name in ("lam", "lam_xc", "rho", "cg_tol", "abs_tol", "rel_tol", "change_tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"ADMM parameter {name} must be a finite number >= 0, got {value!r}")
        if not (isinstance(self.extrapolation, (int, float)) and 0 <= self.extrapolation <= 1):
            raise ValueError(f"ADMM parameter extrapolation must be a number in [0, 1], got {self.extrapolation!r}")
        if self.rho <= 0:
            raise ValueError(f"ADMM parameter rho must be > 0, got {self.rho!r}")
        if self.x_update not in ("auto", "cg", "lens"):
            raise ValueError(f"ADMM parameter x_update must be 'auto', 'cg' or 'lens', got {self.x_update!r}")
        for name in ("max_iter", "cg_steps"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"ADMM parameter {name} must be an integer >= 1, got {value!r}")

    @property
    def kappa(self) -> float:
        return self.lam / self.rho

    @property
    def kappa_xc(self) -> float:
        """The cross-channel block's shrinkage threshold lam_xc / rho."""
        return self.lam_xc / self.rho

    @property
    def cross_channel(self) -> bool:
        """Whether K stacks the cross-channel block D C under D."""
        return self.lam_xc > 0


@dataclasses.dataclass
class IterationRecord:
    """What one ADMM iteration did."""

    iteration: int
    objective: float  # 1/2 ||A x - b||^2 + lam ||D x||_1 (+ lam_xc ||D C x||_1)
    primal_residual: float  # ||K x - z||, K = D (or [D; D C])
    dual_residual: float  # rho ||K^T (z - z_prev)||
    rms_change: float  # rms(x_k - x_{k-1})
    cg_steps: int  # CG steps of the x-update (0: exact per-lens solve)


@dataclasses.dataclass
class AdmmResult:
    x: object  # [3, H, W] planes: numpy (reference) or a device array
    history: list[IterationRecord]
    stop_reason: str

    @property
    def iterations(self) -> int:
        return len(self.history)


@dataclasses.dataclass
class BandedResult:
    """The runs of one solver over bands of lens rows (each stopped by its own rule), as one result."""

    runs: list  # AdmmResult per band (x dropped), top to bottom
    band_rows: list  # the lens rows each band wrote

    @property
    def iterations(self) -> int:
        return max((run.iterations for run in self.runs), default=0)

    @property
    def history(self) -> list[IterationRecord]:
        return [record for run in self.runs for record in run.history]

    def history_rows(self) -> list[dict]:
        """Every band's records as dicts with their ``band``."""
        return [dict(dataclasses.asdict(r), band=i) for i, run in enumerate(self.runs) for r in run.history]

    @property
    def stop_reason(self) -> str:
        if len(self.runs) == 1:
            return self.runs[0].stop_reason
        counts = [run.iterations for run in self.runs]
        spread = f"{min(counts)}" if min(counts) == max(counts) else f"{min(counts)}-{max(counts)}"
        return (f"{len(self.runs)} bands of lens rows, {spread} iterations (mean over lens rows "
                f"{np.average(counts, weights=self.band_rows):.1f}), each stopped by its own rule "
                f"(last band: {self.runs[-1].stop_reason})")


def stop_reason(params: AdmmParams, record: IterationRecord, primal_scale: float, dual_scale: float,
                n_z: int, n_x: int) -> str | None:
    """Why to stop after ``record``, or None to go on.

    primal_scale = max(||D x||, ||z||), dual_scale = ||rho D^T u|| (Boyd et al. 2011, 3.3.1).
    """
    values = (record.objective, record.primal_residual, record.dual_residual, record.rms_change)
    if not all(math.isfinite(v) for v in values):
        raise FloatingPointError(
            f"ADMM diverged at iteration {record.iteration}: objective {record.objective:.4g}, "
            f"primal residual {record.primal_residual:.4g}, dual residual {record.dual_residual:.4g}"
        )
    # From the Malvar start the first x-update changes nothing (Malvar keeps every
    # measured sample), so the change rule only applies from the second iteration.
    if params.change_tol > 0 and record.iteration > 1 and record.rms_change <= params.change_tol:
        return f"rms change {record.rms_change:.3g} <= change_tol {params.change_tol:.3g}"
    if params.abs_tol > 0 or params.rel_tol > 0:
        eps_primal = math.sqrt(n_z) * params.abs_tol + params.rel_tol * primal_scale
        eps_dual = math.sqrt(n_x) * params.abs_tol + params.rel_tol * dual_scale
        if record.primal_residual <= eps_primal and record.dual_residual <= eps_dual:
            return "primal and dual residuals below tolerance"
    if record.iteration >= params.max_iter:
        return f"reached max_iter {params.max_iter}"
    return None


def extrapolate(history) -> bool:
    """Whether the next x-update starts from the extrapolated point (AdmmParams.extrapolation > 0) after the
    iterations of ``history`` (IterationRecord; admm-epi's solver, lfcl/solvers/epi.py, and the numpy reference):
    not after an iteration that changed x more than the one before it, a restart as for accelerated gradient methods
    (O'Donoghue and Candes 2015). Without it the change stalled and rose on a noisy real light field, the change
    rule did not fire for 34 iterations and the mean image fell 1.8 dB (docs/admm.md, "The extrapolated warm start")."""
    return len(history) < 2 or history[-1].rms_change <= history[-2].rms_change
