"""The numerical stress suite (``lfcl bench stress``): every method on inputs chosen to break it.

Repository issue "Robustness", item 1. Each *case* is a mosaic (with its pattern,
pitch and keyword arguments for :func:`lfcl.demosaic.driver.demosaic_grid`) that one
or more methods process twice; each (case, method) pair gives one row:

* ``outcome``: ``ok``, or the exception's type (its message in ``message``);
* ``iterations``, ``max_abs`` (max |x| of the output; ``"inf"``/``"nan"`` when the
  output holds such values), ``finite`` (output), ``history_finite`` (objective,
  residuals and rms change of every ADMM iteration), ``repeatable`` (the second
  run gave the same bytes, the same history, or the same error), ``seconds``
  (first run, end to end);
* ``contract``: ``pass`` or ``FAIL: why``, the rules of :func:`verdict`.

The contract: no NaN/Inf in any output and in no ADMM history; a problem (NaN/Inf
in the input, a bad parameter, a solver that overflows) is a ``ValueError`` or
``FloatingPointError`` whose message names it, never a silent garbage image; the
same input on the same device gives the same bytes. Results must also be
*plausible* (:func:`plausibility`): per colour, the mean of the output within 10 %
(of the largest channel mean) of the Malvar start's or of the mean of that colour's
samples, and its peak at most twice Malvar's. The worst deviation measured over the
lambda/rho grid below on the simulated charts scene (8x8 lenses, 12 and 0.05 lux)
was 3.3 % for the means and 1.0x for the peaks, so the rule has a 3x margin and
flags gross failures only (e.g. a method that zeroes whole colour planes). Flat
inputs (all 0, all 1, constant) must come back flat within 1e-5.

Cases (S x T lenses of 9 x 9 pixels, the simulated ``charts`` scene at 12 lux,
GRBG, seed 0, unless said):

* ``grid``: lambda in 1e-6..1e2 x rho in 1e-4..1e3, 10 iterations, every ADMM method,
  through ``demosaic_grid(lam=, rho=, iterations=)``;
* ``images``: all 0, all 1 (saturated), constant 0.37, hot and dead pixels;
* ``input``: a NaN, +Inf or -Inf pixel and an all-NaN mosaic (must be a ValueError);
  one pixel at 3e38 and the whole scene times 1e30 (finite float32 that overflows
  the arithmetic: a result or a clear error, never NaN/Inf);
* ``params``: lambda NaN / Inf / negative, rho 0, 0 iterations (ValueError);
* ``shape``: 1x1, 1xT, Sx1 and 3x5 lenses; pitch 1 (the 9S x 9T sensor as a plain
  camera), 2 and 3 (simulated), 9; the noise level from the simulator's noise
  profile, as ``lfcl process`` takes it from a DNG. Also 1x1 lenses without a
  noise profile: with the defaults (the noise cannot be estimated from one lens: a
  clear error is fine) and with lambda and iterations given (no noise level is
  needed: a result is expected);
* ``raw``: 12-, 14- and 16-bit DNGs at full scale (a 100 lux exposure: about half
  the pixels at the white level) written with :func:`lfcl.sim.dng.write_dng`, read
  back with :func:`lfcl.io.raw.read_mosaic`, the noise level from their NoiseProfile;
  and a 16-bit DNG with every pixel at 65535 (at least 3x3 lenses: LibRaw refuses
  raws under 22 pixels a side);
* ``noise``: extreme noise, the scene at 0.05 lux, all defaults;
* ``weights``: a white-image lens response (``AlignedGrid(lens_response=)``, Case.grid):
  a vignetted disc whose corners fall below the flat-field threshold, and one with a
  single usable pixel per lens (every other pixel left out of the data term).

:func:`reference_agreement` compares the float32 device solver (CG x-update) with the
float64 numpy reference (:func:`lfcl.solvers.reference.admm_reference`) over the same
lambda/rho grid; :func:`x_tolerance` and :func:`history_errors` state the tolerances.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..demosaic.driver import demosaic_grid
from ..demosaic.methods import ADMM_DEFAULTS, METHODS, admm_params
from ..grid.model import AlignedGrid
from .timing import format_table

ADMM_METHODS = tuple(ADMM_DEFAULTS)
#: The methods whose solver is AdmmSolver, compared with lfcl.solvers.reference over the lambda/rho grid
#: (admm-epi has its own solver and float64 reference: lfcl/solvers/epi.py, tests/test_epi.py).
GRID_METHODS = tuple(m for m in ADMM_METHODS if ADMM_DEFAULTS[m].dims != "epi")
GRID_LAMBDAS = (1e-6, 1e-4, 1e-2, 1.0, 1e2)
GRID_RHOS = (1e-4, 1e-2, 1.0, 1e2, 1e3)
GRID_ITERATIONS = 10
BIT_DEPTHS = (12, 14, 16)
EXTREME_LUX = 0.05
CLEAR_ERRORS = (ValueError, FloatingPointError)
MEAN_SLACK = 0.10  # plausibility: channel means within 10 % of the largest Malvar channel mean
PEAK_FACTOR = 2.0  # plausibility: max |x| at most twice Malvar's
FLAT_TOLERANCE = 1e-5
FLOAT32_EPS = float(np.finfo(np.float32).eps)  # 2^-23
#: The depth output (lfcl.depth.estimate_disparity) runs as a row of its own on the cases of these groups;
#: on a flat input its confidence must say "unknown" (below DEPTH_UNKNOWN everywhere).
DEPTH = "depth"
DEPTH_GROUPS = ("images", "input", "shape", "raw", "noise")
DEPTH_UNKNOWN = 0.5


@dataclasses.dataclass
class Case:
    """One input of the suite and what is expected of every method on it."""

    name: str
    group: str
    mosaic: np.ndarray
    pattern: str
    pitch: tuple[int, int]
    methods: tuple[str, ...] = METHODS
    kwargs: dict = dataclasses.field(default_factory=dict)  # for demosaic_grid (lens_response: the grid's)
    expect: str = "ok"  # "ok", "error" (a ValueError/FloatingPointError) or "either"
    error_match: str | None = None  # regex an expected error's message must match
    refusable: tuple[str, ...] = ()  # methods that may refuse it with a ValueError where "ok" is expected
    flat: float | None = None  # the output must equal this everywhere (within FLAT_TOLERANCE)
    note: str = ""

    def grid(self) -> AlignedGrid:
        """The input's lens grid (lfcl.grid.model): ``pitch``, and ``kwargs``' ``lens_response`` if it has one."""
        return AlignedGrid(self.pitch, lens_response=self.kwargs.get("lens_response"))

    def options(self) -> dict:
        """``kwargs`` less the grid's ``lens_response``: the keyword arguments of demosaic_grid."""
        return {k: v for k, v in self.kwargs.items() if k != "lens_response"}


def _noise_of(sensor, mosaic):
    """The noise model ``lfcl process`` takes from the simulator's DNG NoiseProfile."""
    from ..noise.model import from_noise_profile

    s, o = sensor.noise_profile()
    return from_noise_profile([s, o] * 3, mosaic)


def _shape_case(name, capture, pitch=(9, 9), mosaic=None, **kw) -> Case:
    mosaic = capture.normalised_raw() if mosaic is None else mosaic
    return Case(name, "shape", mosaic, capture.pattern, pitch, kwargs={"noise": _noise_of(capture.sensor, mosaic)}, **kw)


def dng_capture(bits: int, lenses, directory: Path, lux: float = 100.0):
    """(mosaic read back from a ``bits``-bit DNG, the capture written into it, the DNG path)."""
    from ..io.raw import read_mosaic
    from ..sim import SensorModel, simulate
    from ..sim.dng import write_dng

    sensor = SensorModel(adc_bits=bits, black_level_dn=64 << (bits - 12))
    capture = simulate("charts", lenses=lenses, lux=lux, seed=0, sensor=sensor)
    path = Path(directory) / f"full_scale_{bits}bit.dng"
    write_dng(path, capture.raw, capture.pattern, capture.black_level, capture.white_level, [sensor.noise_profile()] * 3)
    return read_mosaic(path), capture, path


def build_cases(lenses=(8, 8), groups=None) -> list[Case]:
    """The suite's cases for an S x T lens array (``groups``: only those groups)."""
    from ..noise.model import from_noise_profile
    from ..sim import simulate

    S, T = (int(n) for n in lenses)
    if S < 1 or T < 1:
        raise ValueError(f"lenses must be at least 1x1, got {S}x{T}")
    wanted = set(groups) if groups is not None else None
    cases: list[Case] = []

    def want(group):
        return wanted is None or group in wanted

    # With the defaults the noise is estimated from the raw, which needs 2x2 lenses or more:
    # below that a clear ValueError is a fair answer.
    estimable = "ok" if S >= 2 and T >= 2 else "either"
    base = simulate("charts", lenses=(S, T), lux=12.0, seed=0)
    scene, pattern = base.normalised_raw(), base.pattern
    shape = scene.shape

    if want("grid"):
        # the solvers alone: with the safety net the soft threshold would hold five methods' lens means to Malvar's
        # whatever lambda did (the net's own extremes are the other groups'). At lambda 1 admm-epi flattens the
        # frame to its mean, which the channel means cannot tell from a demosaic, and the net's flat-lens fill
        # then puts the in-focus lenses back and the channel means 11 % off (docs/auto.md, "Flat lenses the net
        # fills").
        for lam in GRID_LAMBDAS:
            for rho in GRID_RHOS:
                cases.append(Case(f"lam={lam:g} rho={rho:g}", "grid", scene, pattern, (9, 9), ADMM_METHODS,
                                  {"lam": lam, "rho": rho, "iterations": GRID_ITERATIONS, "safety_net": False}))
    if want("images"):
        cases += [
            Case("all zero", "images", np.zeros(shape, np.float32), pattern, (9, 9), flat=0.0, expect=estimable),
            Case("saturated (all 1.0)", "images", np.ones(shape, np.float32), pattern, (9, 9), flat=1.0,
                 expect=estimable),
            Case("constant 0.37", "images", np.full(shape, 0.37, np.float32), pattern, (9, 9), flat=0.37,
                 expect=estimable),
        ]
        spoilt = scene.copy()
        rng = np.random.default_rng(7)
        rows, cols = rng.integers(0, shape[0], 8), rng.integers(0, shape[1], 8)
        spoilt[rows[:4], cols[:4]] = 1.0  # hot
        spoilt[rows[4:], cols[4:]] = 0.0  # dead
        cases.append(Case("4 hot + 4 dead pixels", "images", spoilt, pattern, (9, 9), expect=estimable))
    if want("input"):
        for label, value in (("NaN", np.nan), ("+Inf", np.inf), ("-Inf", -np.inf)):
            bad = scene.copy()
            bad[shape[0] // 2, shape[1] // 3] = value
            cases.append(Case(f"one {label} pixel", "input", bad, pattern, (9, 9), expect="error",
                              error_match=r"NaN|Inf|finite"))
        cases.append(Case("all NaN", "input", np.full(shape, np.nan, np.float32), pattern, (9, 9), expect="error",
                          error_match=r"NaN|Inf|finite"))
        huge = scene.copy()
        huge[shape[0] // 2, shape[1] // 2] = np.float32(3e38)
        cases.append(Case("one pixel at 3e38", "input", huge, pattern, (9, 9), expect="either",
                          note="finite float32 input whose Malvar filter overflows"))
        cases.append(Case("scene x 1e30", "input", scene * np.float32(1e30), pattern, (9, 9), expect="either",
                          note="squares overflow float32 in the residuals"))
    if want("params"):
        for label, kwargs in (("lambda NaN", {"lam": float("nan")}), ("lambda Inf", {"lam": float("inf")}),
                              ("lambda -1", {"lam": -1.0}), ("rho 0", {"rho": 0.0}),
                              ("rho NaN", {"rho": float("nan")}), ("0 iterations", {"iterations": 0})):
            cases.append(Case(label, "params", scene, pattern, (9, 9), ADMM_METHODS,
                              {**kwargs, "noise": _noise_of(base.sensor, scene)}, expect="error",
                              error_match=r"lam|rho|max_iter|iteration"))
    if want("shape"):
        one = simulate("charts", lenses=(1, 1), lux=12.0, seed=0)
        cases.append(_shape_case("1x1 lenses", one))
        cases.append(Case("1x1 lenses, no noise profile, defaults", "shape", one.normalised_raw(), one.pattern, (9, 9),
                          expect="either", note="the noise cannot be estimated from one lens"))
        cases.append(Case("1x1 lenses, no noise profile, lam+iterations", "shape", one.normalised_raw(), one.pattern,
                          (9, 9), kwargs={"lam": 0.001, "iterations": 5}, refusable=("auto", "linear4d"),
                          note="neither lam nor the stopping rule needs a noise level; auto's pick and linear4d's "
                               "filter do (refusing is fine)"))
        cases.append(_shape_case(f"1x{T} lenses", simulate("charts", lenses=(1, T), lux=12.0, seed=0)))
        cases.append(_shape_case(f"{S}x1 lenses", simulate("charts", lenses=(S, 1), lux=12.0, seed=0)))
        cases.append(_shape_case("3x5 lenses", simulate("charts", lenses=(3, 5), lux=12.0, seed=0)))
        cases.append(_shape_case(f"pitch 1 ({shape[0]}x{shape[1]} lenses)", base, pitch=(1, 1), expect="either",
                                 note="every lens is one pixel: the (u, v) prior is empty (refusing is fine)"))
        for pitch in (2, 3):
            cases.append(_shape_case(f"pitch {pitch}", simulate("charts", lenses=(S, T), pitch=pitch, lux=12.0, seed=0),
                                     pitch=(pitch, pitch), refusable=("linear4d",),
                                     note="linear4d ships coefficients for pitch 9 only (refusing is fine)"))
        cases.append(Case("pitch 9, defaults", "shape", scene, pattern, (9, 9), expect=estimable))
    if want("raw"):
        raw_lenses = (max(S, 3), max(T, 3))  # LibRaw refuses raws under 22 pixels a side
        with tempfile.TemporaryDirectory(prefix="lfcl-stress-") as tmp:
            for bits in BIT_DEPTHS:
                mosaic, capture, _ = dng_capture(bits, raw_lenses, Path(tmp))
                saturated = float(np.mean(capture.raw == capture.white_level))
                cases.append(Case(f"{bits}-bit DNG, full scale", "raw", mosaic.data, mosaic.pattern, (9, 9),
                                  kwargs={"noise": from_noise_profile(mosaic.noise_profile, mosaic.data)},
                                  note=f"white level {mosaic.white:g}, {100 * saturated:.0f} % of pixels at it"))
            from ..io.raw import read_mosaic
            from ..sim.dng import write_dng

            path = Path(tmp) / "white_16bit.dng"
            write_dng(path, np.full(mosaic.data.shape, 65535, np.uint16), pattern, 0, 65535)
            white = read_mosaic(path)
            cases.append(Case("16-bit DNG, every pixel 65535", "raw", white.data, white.pattern, (9, 9), flat=1.0))
    if want("noise"):
        dark = simulate("charts", lenses=(S, T), lux=EXTREME_LUX, seed=0)
        cases.append(Case(f"{EXTREME_LUX:g} lux", "noise", dark.normalised_raw(), dark.pattern, (9, 9),
                          expect=estimable))
    if want("weights"):
        noise = _noise_of(base.sensor, scene)
        yy, xx = np.mgrid[-4:5, -4:5]
        disc = np.clip(1.0 - (yy**2 + xx**2) / 25.0, 0.0, 1.0).astype(np.float32)
        single = np.zeros((9, 9), np.float32)
        single[4, 4] = 1.0
        cases.append(Case("lens response: vignetted disc", "weights", scene, pattern, (9, 9),
                          kwargs={"noise": noise, "lens_response": disc},
                          note="corners below the flat-field threshold get weight 0"))
        cases.append(Case("lens response: one usable pixel per lens", "weights", scene, pattern, (9, 9),
                          kwargs={"noise": noise, "lens_response": single}, expect="either",
                          note="each lens measures one colour; the prior must fill in the others (or refuse)"))
    return cases


# --------------------------------------------------------------------------- running and judging


def _history_finite(history) -> bool | None:
    if not history:
        return None
    keys = ("objective", "primal_residual", "dual_residual", "rms_change")
    return all(math.isfinite(float(r[k])) for r in history for k in keys)


def _max_abs(planes: np.ndarray):
    """max |x| as a float, or "nan"/"inf" when the output holds such values."""
    if np.isnan(planes).any():
        return "nan"
    peak = float(np.abs(planes).max()) if planes.size else 0.0
    return peak if math.isfinite(peak) else "inf"


def measured_means(mosaic: np.ndarray, pattern: str) -> np.ndarray:
    """Per colour, the mean of the mosaic samples of that colour (nan for a colour with none)."""
    from ..layout import channel_map

    channels = channel_map(mosaic.shape, pattern, (0, 0))
    values = np.asarray(mosaic, np.float64)
    return np.array([values[channels == c].mean() if (channels == c).any() else np.nan for c in range(3)])


def plausibility(planes: np.ndarray, start: np.ndarray, measured: np.ndarray | None = None) -> str | None:
    """Why ``planes`` is not a plausible demosaic, or None.

    ``start``: the Malvar result of the same mosaic; ``measured``: the mean of each
    colour's samples (:func:`measured_means`). Each channel mean of ``planes`` must be
    within MEAN_SLACK (of the largest Malvar channel mean) of Malvar's or of the
    measured one (both are fair estimates: on a tiny sensor Malvar's borders weigh
    more), and its peak at most PEAK_FACTOR times Malvar's.
    """
    start = np.asarray(start, np.float64)
    planes = np.asarray(planes, np.float64)
    if not np.isfinite(start).all():
        return None  # nothing to compare with
    means, reference = planes.mean(axis=(1, 2)), start.mean(axis=(1, 2))
    scale = float(np.abs(reference).max())
    off = np.abs(means - reference)
    if measured is not None:
        off = np.fmin(off, np.abs(means - np.asarray(measured, np.float64)))
    worst = float(off.max())
    if worst > MEAN_SLACK * scale + 1e-6:
        return (f"channel means {np.array2string(means, precision=3)} vs Malvar's "
                f"{np.array2string(reference, precision=3)} ({100 * worst / max(scale, 1e-30):.0f} % off)")
    peak, malvar_peak = float(np.abs(planes).max()), float(np.abs(start).max())
    if peak > PEAK_FACTOR * malvar_peak + 1e-6:
        return f"max |x| {peak:.3g} is more than {PEAK_FACTOR:g}x Malvar's {malvar_peak:.3g}"
    return None


def verdict(case: Case, row: dict) -> str:
    """``pass`` or ``FAIL: why`` for one row (see the module docstring)."""
    if row["outcome"] == "ok":
        if not row["finite"]:
            return "FAIL: silent NaN/Inf in the output"
        if row["history_finite"] is False:
            return "FAIL: NaN/Inf in the history"
        if case.expect == "error":
            return "FAIL: returned a result where a ValueError was expected"
        if row.get("check"):
            return f"FAIL: {row['check']}"
    else:
        if row["outcome"] not in ("ValueError", "FloatingPointError"):
            return f"FAIL: unexpected {row['outcome']}"
        if case.expect == "ok" and row.get("method") not in case.refusable:
            return "FAIL: refused an input it should process"
        if case.error_match and not re.search(case.error_match, row["message"] or ""):
            return "FAIL: the message does not name the problem"
    if row["repeatable"] is False:
        return "FAIL: a second run gave different bytes"
    return "pass"


def _json_value(value):
    if hasattr(value, "sigma"):  # a NoiseEstimate
        return {"sigma": value.sigma, "source": value.source}
    if isinstance(value, np.ndarray):
        return {"array": list(value.shape), "min": float(value.min()), "max": float(value.max())}
    return value if not isinstance(value, float) or math.isfinite(value) else str(value)


@dataclasses.dataclass
class _DepthResult:
    """estimate_disparity's maps in the shape of a demosaic result, for the suite's checks."""

    planes: np.ndarray  # [2, S, T]: disparity, confidence
    history: list
    iterations: int = 0
    stop_reason: str = "direct"


def _attempt(case: Case, method: str, device):
    start = time.perf_counter()
    try:
        if method == DEPTH:
            from ..depth import estimate_disparity

            depth = estimate_disparity(case.mosaic, case.pattern, case.pitch, device=device,
                                       noise=case.kwargs.get("noise"))
            result = _DepthResult(np.stack([depth.disparity, depth.confidence]), [])
        else:
            result = demosaic_grid(case.mosaic, case.pattern, case.grid(), method, device=device, **case.options())
    except Exception as exc:
        return None, exc, time.perf_counter() - start
    return result, None, time.perf_counter() - start


def _fingerprint(result, error):
    if error is not None:
        return (type(error).__name__, str(error))
    return (result.planes.tobytes(), repr(result.history), result.iterations)


def run_case(case: Case, method: str, device=None, repeat: bool = True) -> dict:
    """One row: ``method`` on ``case`` (twice when ``repeat``)."""
    from ..ops.malvar import malvar_np

    result, error, seconds = _attempt(case, method, device)
    row = {"case": case.name, "group": case.group, "method": method, "expect": case.expect,
           "parameters": {k: _json_value(v) for k, v in case.kwargs.items()},
           "outcome": "ok", "message": None, "iterations": None, "stop_reason": None, "max_abs": None,
           "finite": None, "history_finite": None, "repeatable": None, "seconds": seconds, "check": None,
           "note": case.note}
    if error is not None:
        row.update(outcome=type(error).__name__, message=" ".join(str(error).split()))
    else:
        planes = result.planes
        row.update(iterations=result.iterations, stop_reason=result.stop_reason, max_abs=_max_abs(planes),
                   finite=bool(np.isfinite(planes).all()), history_finite=_history_finite(result.history))
        if row["finite"] and method == DEPTH:
            confidence = planes[1]
            if confidence.min() < 0 or confidence.max() > 1:
                row["check"] = f"a depth confidence outside [0, 1] ({confidence.min():.3g}..{confidence.max():.3g})"
            elif case.flat is not None and confidence.max() >= DEPTH_UNKNOWN:
                row["check"] = f"a flat input's depth confidence reached {confidence.max():.3g} (should say unknown)"
        elif row["finite"]:
            if case.flat is not None:
                off = float(np.abs(planes.astype(np.float64) - case.flat).max())
                if off > FLAT_TOLERANCE:
                    row["check"] = f"a flat {case.flat:g} input came back {off:.3g} off flat"
            else:
                mosaic = case.mosaic
                if case.kwargs.get("lens_response") is not None:  # Malvar runs on the flat-fielded mosaic
                    from ..grid.vignetting import flat_field

                    mosaic, weights = flat_field(mosaic, case.kwargs["lens_response"])
                with np.errstate(all="ignore"):
                    start = malvar_np(mosaic, case.pattern)
                if case.kwargs.get("lens_response") is not None:  # judge the lit pixels: the dark ones are
                    lit = np.tile(weights > 0, (mosaic.shape[0] // weights.shape[0], mosaic.shape[1] // weights.shape[1]))
                    planes, start = planes[:, lit][..., None], start[:, lit][..., None]  # filled (docs/admm.md)
                row["check"] = plausibility(planes, start, measured_means(mosaic, case.pattern))
    if repeat:
        again, again_error, _ = _attempt(case, method, device)
        row["repeatable"] = _fingerprint(result, error) == _fingerprint(again, again_error)
    row["contract"] = verdict(case, row)
    return row


def run(lenses=(8, 8), device=None, groups=None, only=None, repeat: bool = True,
        progress: Callable[[str], object] | None = None) -> dict:
    """Every (case, method) row of the suite; a JSON-ready dict.

    ``groups``: only these case groups; ``only``: only cases whose name contains one
    of these substrings (case-insensitive).
    """
    from ..device import get_runtime

    runtime = get_runtime(device)
    cases = build_cases(lenses, groups)
    if only:
        needles = [s.lower() for s in only]
        cases = [c for c in cases if any(n in c.name.lower() or n == c.group for n in needles)]
        if not cases:
            raise ValueError(f"no stress case matches {', '.join(only)}")
    # Warm-up, untimed: the first call of each method builds its OpenCL programs.
    from ..sim import simulate

    small = simulate("charts", lenses=(2, 2), lux=12.0, seed=0)
    warm = _shape_case("warm-up", small)
    for method in METHODS:
        _attempt(warm, method, device)
    rows = []
    for case in cases:
        for method in case.methods + ((DEPTH,) if case.group in DEPTH_GROUPS else ()):
            if progress:
                progress(f"{case.name} / {method}")
            rows.append(run_case(case, method, device, repeat=repeat))
    failures = [r for r in rows if r["contract"] != "pass"]
    return {"device": runtime.name, "lenses": [int(n) for n in lenses], "pitch": [9, 9], "scene": "charts",
            "lux": 12.0, "seed": 0, "grid_iterations": GRID_ITERATIONS, "rows": rows,
            "failures": len(failures)}


def _short(text: str, width: int = 70) -> str:
    return text if len(text) <= width else text[: width - 3] + "..."


def format_report(report: dict) -> str:
    """The rows as a Markdown table, then one line per contract failure."""
    def yes(value):
        return "-" if value is None else ("yes" if value else "NO")

    def peak(value):
        return "-" if value is None else (value if isinstance(value, str) else f"{value:.4g}")

    headers = ["case", "method", "outcome", "iterations", "max |x|", "finite", "history finite", "repeatable",
               "seconds", "contract"]
    rows = []
    for r in report["rows"]:
        outcome = "ok" if r["outcome"] == "ok" else f"{r['outcome']}: {_short(r['message'] or '', 60)}"
        rows.append([r["case"], r["method"], outcome, "-" if r["iterations"] is None else str(r["iterations"]),
                     peak(r["max_abs"]), yes(r["finite"]), yes(r["history_finite"]), yes(r["repeatable"]),
                     f"{r['seconds']:.3f}", "pass" if r["contract"] == "pass" else "FAIL"])
    title = (f"Numerical stress suite on {report['device']}: {report['lenses'][0]}x{report['lenses'][1]} lenses "
             f"of 9x9 (charts, 12 lux, seed 0); grid rows run {report['grid_iterations']} iterations.")
    lines = [title, "", format_table(headers, rows, "lllrrlllrl")]
    failures = [r for r in report["rows"] if r["contract"] != "pass"]
    lines.append("")
    if failures:
        lines.append(f"{len(failures)} of {len(report['rows'])} rows break the contract:")
        for r in failures:
            detail = f" ({r['message']})" if r["message"] else ""
            lines.append(f"- {r['case']} / {r['method']}: {r['contract'][6:]}{detail}")
    else:
        lines.append(f"All {len(report['rows'])} rows keep the contract.")
    return "\n".join(lines)


# --------------------------------------------------------------------------- float32 device vs float64 reference


def x_tolerance(rho: float) -> float:
    """Allowed ||x_device - x_reference|| / ||x_reference|| in CG mode (same params, same start).

    Measured on the reference problem (3x4 lenses, charts at 0.05 and 12 lux, the
    lambda/rho grid, 10-30 iterations): at most 8e-7 for rho <= 1 (3.4e-7 with the
    suite's 20 iterations), where the x-update's normal matrix A^T A + rho D^T D is
    well conditioned and float32 costs a few ulps an iteration: 1e-5 allows 10x.
    With rho >= 100 its condition number grows like rho lambda_max(D^T D) /
    lambda_min(A^T A + rho D^T D) (thousands at rho = 100, ten times more at 1000),
    float32 CG loses that many ulps per x-update, and the soft threshold turns the
    differences into different support decisions: up to 6.6e-4 with 20 iterations
    and 1.4e-3 with 30 (admm-st, lambda >= 1, rho = 100, 0.05 lux), so 1e-2.
    """
    return 1e-5 if rho <= 1.0 else 1e-2


def history_errors(device_history, reference_history, lam: float, rho: float, n_z: int, scale: float) -> dict:
    """Worst |device - reference| / tolerance of the objective and residuals over the iterations (<= 1 passes).

    Tolerances, each a relative part plus what float32 rounding of quantities of
    size ``scale`` (max |x|) allows over ``n_z`` gradient samples, for rho <= 1:

    * objective 1/2||Ax - b||^2 + lam ||Dx||_1: 1e-4 relative + n_z eps (scale^2 + lam scale):
      every |Dx| and misfit sample is rounded to about eps scale;
    * primal residual ||Dx - z||: 1e-3 relative + sqrt(n_z) eps scale (a norm of
      differences that can be as small as the rounding itself);
    * dual residual rho ||D^T (z - z_prev)||: 1e-3 relative + 4 rho sqrt(n_z) eps scale
      (D^T sums up to 4 rounded differences per sample).

    Where rho > 1 all three are multiplied by x_tolerance(rho) / x_tolerance(1) (1000):
    the history follows the iterate, which loses that much to the conditioning.
    Measured (reference problem, 20 iterations, 0.05 and 12 lux): at most 0.04 of the
    tolerance for rho <= 1; for rho >= 100 up to 114x the unscaled tolerance (admm-st,
    lambda >= 1, rho = 100, 0.05 lux), i.e. 0.11 of the scaled one.
    """
    eps = FLOAT32_EPS
    loosen = x_tolerance(rho) / x_tolerance(1.0)
    worst = {"objective": 0.0, "primal_residual": 0.0, "dual_residual": 0.0}
    for mine, ref in zip(device_history, reference_history):
        tolerance = {
            "objective": 1e-4 * abs(ref.objective) + n_z * eps * (scale**2 + lam * scale),
            "primal_residual": 1e-3 * ref.primal_residual + math.sqrt(n_z) * eps * scale,
            "dual_residual": 1e-3 * ref.dual_residual + 4 * rho * math.sqrt(n_z) * eps * scale,
        }
        for key, tol in tolerance.items():
            error = abs(getattr(mine, key) - getattr(ref, key))
            worst[key] = max(worst[key], error / max(loosen * tol, 1e-300))
    return worst


REFERENCE_LENSES = (3, 4)
REFERENCE_LUX = EXTREME_LUX
REFERENCE_ITERATIONS = 20


def reference_agreement(methods=GRID_METHODS, lams=GRID_LAMBDAS, rhos=GRID_RHOS, lenses=REFERENCE_LENSES,
                        lux: float = REFERENCE_LUX, iterations: int = REFERENCE_ITERATIONS, device=None,
                        progress: Callable[[str], object] | None = None) -> dict:
    """The float32 device solver (x_update="cg") against the float64 reference, same params and start.

    Parameters are ``admm_params(method, sigma, lam=, rho=, iterations=)`` with
    x_update="cg" (sigma from the simulator's noise profile); the start is the
    numpy Malvar of the mosaic for both.
    """
    from ..device import get_runtime
    from ..ops.malvar import malvar_np
    from ..sim import simulate
    from ..solvers.admm import AdmmSolver
    from ..solvers.reference import admm_reference

    runtime = get_runtime(device)
    capture = simulate("charts", lenses=lenses, lux=lux, seed=0)
    b = capture.normalised_raw()
    x0 = malvar_np(b, capture.pattern)
    sigma = _noise_of(capture.sensor, b).sigma
    b_dev, x0_dev = runtime.to_device(b), runtime.to_device(x0)
    rows = []
    for method in methods:
        dims = ADMM_DEFAULTS[method].dims
        solver = AdmmSolver(runtime, b.shape, capture.pattern, (9, 9), dims)
        n_z = len(dims) * x0.size
        for lam in lams:
            for rho in rhos:
                if progress:
                    progress(f"{method} lam={lam:g} rho={rho:g}")
                params = dataclasses.replace(admm_params(method, sigma, lam=lam, rho=rho, iterations=iterations),
                                             x_update="cg")
                expected = admm_reference(b, capture.pattern, (9, 9), dims, params, x0)
                got = solver.solve(b_dev, x0_dev, params)
                x = got.x.get()
                relative = float(np.linalg.norm(x - expected.x) / np.linalg.norm(expected.x))
                scale = float(np.abs(expected.x).max())
                history = history_errors(got.history, expected.history, lam, rho, n_z, scale)
                tolerance = x_tolerance(rho)
                rows.append({"method": method, "lam": lam, "rho": rho, "iterations": got.iterations,
                             "reference_iterations": expected.iterations, "relative_x": relative,
                             "tolerance": tolerance, "history": history,
                             "passed": (relative <= tolerance and max(history.values()) <= 1.0
                                        and got.iterations == expected.iterations)})
    return {"device": runtime.name, "lenses": list(lenses), "lux": lux, "iterations": iterations, "rows": rows,
            "failures": sum(not r["passed"] for r in rows)}


def format_reference(report: dict) -> str:
    headers = ["method", "lambda", "rho", "rel |x - x_ref|", "tolerance", "worst history error / tolerance", "pass"]
    rows = [[r["method"], f"{r['lam']:g}", f"{r['rho']:g}", f"{r['relative_x']:.2e}", f"{r['tolerance']:.0e}",
             f"{max(r['history'].values()):.3f}", "yes" if r["passed"] else "NO"] for r in report["rows"]]
    head = (f"float32 device (CG x-update) vs float64 numpy reference on {report['device']}: "
            f"{report['lenses'][0]}x{report['lenses'][1]} lenses, charts at {report['lux']:g} lux, "
            f"{report['iterations']} iterations.")
    return "\n".join([head, "", format_table(headers, rows, "lrrrrrl")])
