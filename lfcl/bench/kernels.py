"""Per-kernel timings and effective bandwidth (``lfcl bench kernels``).

For a sensor of ``H x W`` pixels (``N = H*W``; a light field of ``P = 3N`` plane
elements, docs/layout.md), every OpenCL kernel the methods use is run on random
float32 data and timed: a warm-up call, then ``repeats`` calls each bracketed by
``queue.finish()``; the median is reported. Beside it:

* the effective bandwidth, ``bytes / median``, where ``bytes`` is the traffic the
  kernel must at least move: every element it has to read plus every element it
  writes, 4 bytes each, counted once (cache hits for neighbours assumed; see the
  ``traffic`` column, e.g. ``read P + write 2P``);
* the fraction of the device's own copy bandwidth, measured in the same run by a
  device-to-device ``cl.enqueue_copy`` of a ``P``-float buffer (read P + write P);
* the numpy twin (``lfcl.ops.*_np``) on the same host data (one untimed warm-up call,
  then ``numpy_repeats`` timed ones: the first call into fresh memory pays the page
  faults of its output, up to 30x the steady time), its median and the speed-up
  ``numpy / device``. The twins allocate their outputs, as numpy code does.

Element-wise kernels and reductions run on ``P`` floats (one light field), the
gradient kernels on ``[k, 3, H, W]`` for ``k`` = 2 (uv) or 4 (uvst) dims. The ADMM
kernels of ``lfcl/kernels/admm.cl`` are launched as ``AdmmSolver`` launches them;
``build_rhs`` and ``lens_solve`` are included when the installed admm.cl has them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pyopencl as cl

from ..ops.cfa import CfaSampling, cfa_adjoint_np, cfa_gram_np, cfa_sample_np
from ..ops.gradient import Gradient, gradient_adjoint_np, gradient_gram_np, gradient_np
from ..ops.linalg import VectorOps, axpby_np
from ..ops.malvar import Malvar, malvar_np
from ..ops.reduce import Reductions, abs_sum_np, diff_norm2_np, dot_np, norm2_np
from ..ops.shrink import Shrinkage, soft_threshold_np, zu_update_np
from ..solvers.reference import neighbour_count
from .timing import format_table, gb_per_s, time_calls

FLOAT = 4  # bytes
PATTERN = "GRBG"
RHO = 0.3
KAPPA = 0.05
DIM_SETS = ("uv", "uvst")

# OpenCL error codes that mean "the device could not hold the buffers".
_ALLOCATION_ERRORS = {
    cl.status_code.MEM_OBJECT_ALLOCATION_FAILURE,
    cl.status_code.OUT_OF_RESOURCES,
    cl.status_code.OUT_OF_HOST_MEMORY,
}


@dataclasses.dataclass
class Case:
    """One benchmarked kernel: what it runs, on which buffers, and its minimum traffic."""

    name: str  # row label, e.g. "D^T uvst"
    kernel: str  # OpenCL source file and kernel, e.g. "gradient.cl:grad_adjoint"
    traffic: str  # minimum traffic in elements, e.g. "read P + write P"
    floats: int  # the same, in floats
    buffers: tuple[str, ...]  # pool keys it uses
    device: Callable[[dict], object]  # pool of device arrays -> runs once (may be asynchronous)
    numpy: Callable[[dict], object] | None  # pool of host arrays -> runs the numpy twin


class _Pool:
    """Host and device arrays by key, created when first needed and dropped after their last use."""

    def __init__(self, runtime, specs: dict, seed: int = 0):
        self.runtime = runtime
        self.specs = specs  # key -> (shape, low, high) ; low None: device-only output
        self.rng = np.random.default_rng(seed)
        self.host: dict[str, np.ndarray] = {}
        self.device: dict = {}

    def ensure(self, keys, want_host: bool):
        for key in keys:
            shape, low, _ = self.specs[key]
            if key not in self.device:
                if low is None:
                    self.device[key] = self.runtime.empty(shape)
                else:
                    data = self._host_data(key)
                    self.device[key] = self.runtime.to_device(data)
            if want_host and low is not None:
                self._host_data(key)

    def _host_data(self, key):
        if key not in self.host:
            shape, low, high = self.specs[key]
            data = self.rng.random(shape, dtype=np.float32)
            if (low, high) != (0.0, 1.0):
                data *= np.float32(high - low)
                data += np.float32(low)
            self.host[key] = data
        return self.host[key]

    def release(self, keep):
        """Drop every array whose key is not in ``keep`` (device memory freed at once)."""
        for key in [k for k in self.device if k not in keep]:
            self.device.pop(key).data.release()
        for key in [k for k in self.host if k not in keep]:
            del self.host[key]


def lens_solve_np(rhs: np.ndarray, blocks: np.ndarray, pitch) -> np.ndarray:
    """numpy twin of ``lens_solve``: x[lens, c] = inverse[parity, c] @ rhs[lens, c], lens by lens.

    ``blocks`` [4, 3, UV, UV] from ``lfcl.solvers.admm.lens_block_inverses``; the parity of
    lens (s, t) is ``2 * ((s*U) & 1) + ((t*V) & 1)``.
    """
    C, H, W = rhs.shape
    U, V = pitch
    S, T = H // U, W // V
    lenses = rhs.reshape(C, S, U, T, V).transpose(0, 1, 3, 2, 4).reshape(C, S, T, U * V)
    out = np.empty_like(lenses)
    s_parity, t_parity = (np.arange(S) * U) & 1, (np.arange(T) * V) & 1
    for ps in (0, 1):
        for pt in (0, 1):
            rows, cols = np.flatnonzero(s_parity == ps), np.flatnonzero(t_parity == pt)
            if rows.size and cols.size:
                index = np.ix_(np.arange(C), rows, cols)
                out[index] = lenses[index] @ blocks[2 * ps + pt].transpose(0, 2, 1)[:, None]
    return np.ascontiguousarray(out.reshape(C, S, T, U, V).transpose(0, 1, 3, 2, 4).reshape(C, H, W))


def buffer_specs(height: int, width: int, pitch=None) -> dict:
    """Every buffer the cases use: key -> (shape, low, high); low None = an output, no host copy."""
    planes, mosaic = (3, height, width), (height, width)
    specs = {
        "x": (planes, 0.0, 1.0),
        "x2": (planes, 0.0, 1.0),
        "y": (planes, None, None),
        "z": (planes, -0.1, 0.1),
        "u": (planes, -0.1, 0.1),
        "b": (mosaic, 0.0, 1.0),
        "m": (mosaic, None, None),
    }
    for dims in DIM_SETS:
        specs[f"g_{dims}"] = ((len(dims), *planes), -0.5, 0.5)
        specs[f"g2_{dims}"] = ((len(dims), *planes), -0.5, 0.5)
    if pitch is not None and height % pitch[0] == 0 and width % pitch[1] == 0:  # the disparity's (depth_cases)
        lenses, ND = (height // pitch[0], width // pitch[1]), DEPTH_CANDIDATES.size
        specs["cost"] = ((5, 2, ND, *lenses), None, None)
        specs["cost_aperture"] = ((2 * ND, *lenses), -1.0, 1.0)
        specs["window_weights"] = (((2 * DEPTH_RADIUS + 1) ** 2, *lenses), 0.0, 1.0)
        specs["cost_sums"] = ((2 * ND, *lenses), None, None)
    return specs


def linear4d_cases(runtime, sensor, pitch) -> list[Case]:
    """The learned 4D linear demosaic with its shipped coefficients (the 12-lux set), where they fit the pitch."""
    from ..ops.linear4d import Linear4d, linear4d_np, load_model

    model = load_model()
    if tuple(pitch) != model.pitch:
        return []
    coefficients = model.coefficients[model.metadata["lux"].index(12.0)] if 12.0 in model.metadata["lux"] \
        else model.coefficients[0]
    op = Linear4d(runtime, sensor, PATTERN, pitch, model.taps, coefficients)
    N = sensor[0] * sensor[1]
    return [Case("linear4d", "linear4d.cl:linear4d", "read N + write 3N", 4 * N, ("b", "y"),
                 lambda d: op.forward(d["b"], out=d["y"]),
                 lambda h: linear4d_np(h["b"], PATTERN, pitch, model.taps, coefficients))]


def lens_guard_cases(runtime, sensor, pitch) -> list[Case]:
    """The guarded start's two kernels: the per-lens disagreement of two starts, and the swap of a
    checkerboard of lenses (half of them) from one start into the other."""
    from ..ops.lensguard import LensGuard, lens_disagreement_np, take_lenses_np

    guard = LensGuard(runtime, sensor, pitch)
    S, T = guard.lenses
    checkerboard = (np.add.outer(np.arange(S), np.arange(T)) % 2).astype(bool)
    N, P = sensor[0] * sensor[1], 3 * sensor[0] * sensor[1]
    return [
        Case("lens disagreement", "lensguard.cl:lens_disagreement", "read 2P + N", 2 * P + N, ("x", "x2", "b"),
             lambda d: guard.disagreement(d["x"], d["x2"], d["b"], 1e-3, 1e-6),
             lambda h: lens_disagreement_np(h["x"], h["x2"], h["b"], pitch, gain=1e-3, floor=1e-6)),
        Case("lens swap (half the lenses)", "lensguard.cl:take_lenses", "read P/2 + write P/2", P,
             ("x", "x2", "y"), lambda d: guard.take(d["y"], d["x"], checkerboard),
             lambda h: take_lenses_np(h["x2"], h["x"], checkerboard, pitch)),
    ]


def lens_copy_cases(runtime, sensor, pitch) -> list[Case]:
    """The flat lenses' two kernels (lfcl/demosaic/methods.py): putting solved lenses back (a checkerboard of
    half the lenses, each to its own place) and setting lenses to their colour means (the other half)."""
    from ..ops.lenscopy import LensCopy, copy_lenses_np, fill_lenses_np

    copy = LensCopy(runtime, pitch)
    S, T = sensor[0] // pitch[0], sensor[1] // pitch[1]
    board = (np.add.outer(np.arange(S), np.arange(T)) % 2).astype(bool).ravel()
    solved, flat = np.flatnonzero(board), np.flatnonzero(~board)
    pairs = np.stack([solved, solved], axis=1)
    table = copy.upload(pairs)
    means = np.random.default_rng(0).random((flat.size, 3)).astype(np.float32)
    P = 3 * sensor[0] * sensor[1]
    return [
        Case("lens copy (half the lenses)", "lenscopy.cl:copy_lenses", "read P/2 + write P/2", P, ("x", "x2", "y"),
             lambda d: copy(d["x"], d["y"], table), lambda h: copy_lenses_np(h["x"], h["x2"], pairs, pitch)),
        Case("lens fill (half the lenses)", "lenscopy.cl:fill_lenses", "write P/2", P // 2, ("x2", "y"),
             lambda d: copy.fill(d["y"], flat, means), lambda h: fill_lenses_np(h["x2"], flat, means, pitch)),
    ]


def epi_cases(runtime, sensor, pitch) -> list[Case]:
    """admm-epi's prior along the epipolar lines (lfcl/ops/epi.py): the forward with the colour mix, as the solver's
    normal operator runs it, and the adjoint, on a disparity that ramps from -1.2 to +1.2 lenses per view step down
    the frame and by 0.3 across it (fractional everywhere: every ray interpolates over 4 lenses)."""
    from ..ops.epi import EpiGradient, epi_adjoint_np, epi_matrix_np, epi_mixed_gradient_np

    S, T = sensor[0] // pitch[0], sensor[1] // pitch[1]
    disparity = (np.linspace(-1.2, 1.2, S)[:, None] + np.linspace(0.0, 0.3, T)[None, :]).astype(np.float32)
    op = EpiGradient(runtime, (3, *sensor), pitch)
    op.set_maps(disparity)
    matrix = {}

    def twin_matrix():  # untimed set-up of the twin's sparse matrix, built once per map as the solver's twin does
        if "M" not in matrix:
            matrix["M"] = epi_matrix_np(disparity, pitch)
        return matrix["M"]

    P = 3 * sensor[0] * sensor[1]
    return [
        Case("D_epi, colour-mixed", "epi.cl:epi_forward", "read P + write 2P", 3 * P, ("x", "g_uv"),
             lambda d: op.forward(d["x"], out=d["g_uv"], mixed=True),
             lambda h: epi_mixed_gradient_np(h["x"], disparity, pitch, matrix=twin_matrix())),
        Case("D_epi^T", "epi.cl:epi_adjoint", "read 2P + write P", 3 * P, ("g_uv", "y"),
             lambda d: op.adjoint(d["g_uv"], out=d["y"]),
             lambda h: epi_adjoint_np(h["g_uv"], disparity, pitch, matrix=twin_matrix())),
    ]


DEPTH_CANDIDATES = np.round(np.arange(-2.0, 2.0 + 1e-9, 0.2), 6)  # admm-epi's disparity search at 2 lux
DEPTH_RADIUS = 4  # the window of lfcl.depth.estimate's defaults


def depth_cases(runtime, sensor, pitch) -> list[Case]:
    """The disparity's two heavy kernels (lfcl/depth/cost.py), as admm-epi's search at 2 lux runs them: the cost
    volume of the full and the four half apertures in one gather (no sample saturated, so the lenses away from the
    frame's edge take the interior kernel) and the window sums of one aperture. The cost volume has no numpy
    column: its twin (``cost_volume_np``, per lens and colour in float64) takes minutes at this size;
    tests/test_depth.py checks the kernels against it."""
    from ..depth.cost import CostVolume, WindowAggregate, aggregate_window_np, window_offsets

    S, T = sensor[0] // pitch[0], sensor[1] // pitch[1]
    ND, L = DEPTH_CANDIDATES.size, S * T
    volume = CostVolume(runtime, sensor, PATTERN, pitch, DEPTH_CANDIDATES, halves=True)
    window = WindowAggregate(runtime, 2 * ND, (S, T), DEPTH_RADIUS)
    offsets = window_offsets(DEPTH_RADIUS)
    return [
        Case("depth cost, 5 apertures", "depth.cl:depth_cost_interior + depth_cost", f"read N + write {10 * ND}L",
             sensor[0] * sensor[1] + 10 * ND * L, ("b", "cost"),
             lambda d: volume.forward(d["b"], (1e-4, 1e-6), np.inf, out=d["cost"]), None),
        Case("depth window sums", "depth_aggregate.cl:depth_aggregate", f"read {2 * ND + 81}L + write {2 * ND}L",
             (4 * ND + 81) * L, ("cost_aperture", "window_weights", "cost_sums"),
             lambda d: window.forward(d["cost_aperture"], d["window_weights"], out=d["cost_sums"]),
             lambda h: aggregate_window_np(h["cost_aperture"], offsets, h["window_weights"])),
    ]


def build_cases(runtime, height: int, width: int, pitch) -> list[Case]:
    """The benchmarked kernels, in run order (big gradient buffers last but one group)."""
    N, P = height * width, 3 * height * width
    sensor, planes = (height, width), (3, height, width)
    queue = runtime.queue
    A = CfaSampling(runtime, sensor, PATTERN)
    malvar = Malvar(runtime, sensor, PATTERN)
    vec, red, shrink = VectorOps(runtime), Reductions(runtime), Shrinkage(runtime)
    U, V = pitch

    cases = [
        Case("copy (reference)", "clEnqueueCopyBuffer", "read P + write P", 2 * P, ("x", "y"),
             lambda d: cl.enqueue_copy(queue, d["y"].data, d["x"].data, byte_count=d["x"].nbytes),
             lambda h: np.copy(h["x"])),
        Case("CFA A", "cfa.cl:cfa_sample", "read N + write N", 2 * N, ("x", "m"),
             lambda d: A.forward(d["x"], out=d["m"]), lambda h: cfa_sample_np(h["x"], PATTERN)),
        Case("CFA A^T", "cfa.cl:cfa_adjoint", "read N + write 3N", 4 * N, ("b", "y"),
             lambda d: A.adjoint(d["b"], out=d["y"]), lambda h: cfa_adjoint_np(h["b"], PATTERN)),
        Case("CFA A^T A", "cfa.cl:cfa_gram", "read N + write 3N", 4 * N, ("x", "y"),
             lambda d: A.gram(d["x"], out=d["y"]), lambda h: cfa_gram_np(h["x"], PATTERN)),
        Case("Malvar", "malvar.cl:malvar", "read N + write 3N", 4 * N, ("b", "y"),
             lambda d: malvar.forward(d["b"], out=d["y"]), lambda h: malvar_np(h["b"], PATTERN)),
    ]
    if height % U == 0 and width % V == 0:  # the lens-bounded start needs whole lenses
        lens_malvar = Malvar(runtime, sensor, PATTERN, lens=pitch)
        cases.append(Case("Malvar, lens-bounded", "malvar.cl:malvar", "read N + write 3N", 4 * N, ("b", "y"),
                          lambda d: lens_malvar.forward(d["b"], out=d["y"]),
                          lambda h: malvar_np(h["b"], PATTERN, lens=pitch)))
    try:  # the published peer, where installed (lfcl[test])
        from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004
    except ImportError:
        demosaicing_CFA_Bayer_Malvar2004 = None
    if demosaicing_CFA_Bayer_Malvar2004 is not None:
        cases.append(Case("Malvar vs colour-demosaicing", "malvar.cl:malvar", "read N + write 3N", 4 * N, ("b", "y"),
                          lambda d: malvar.forward(d["b"], out=d["y"]),
                          lambda h: demosaicing_CFA_Bayer_Malvar2004(h["b"], PATTERN)))
    cases += linear4d_cases(runtime, sensor, pitch)
    if height % U == 0 and width % V == 0:
        cases += lens_guard_cases(runtime, sensor, pitch)
        cases += lens_copy_cases(runtime, sensor, pitch)

    def admm_cases(dims):
        from ..solvers.admm import AdmmSolver, lens_block_inverses

        k, g, g2 = len(dims), f"g_{dims}", f"g2_{dims}"
        solver = AdmmSolver(runtime, (height, width), PATTERN, pitch, dims)
        inverse = {}

        def inverse_diagonal():  # untimed set-up of the Jacobi twin, as in admm_reference
            if "d" not in inverse:
                diagonal = cfa_gram_np(np.ones(planes, np.float32), PATTERN) + RHO * neighbour_count(planes, pitch, dims)
                inverse["d"] = np.divide(1.0, diagonal, out=np.zeros_like(diagonal), where=diagonal > 0).astype(np.float32)
            return inverse["d"]

        cases = [
            Case(f"normal_apply {dims}", "admm.cl:normal_apply", "read P + write P", 2 * P, ("x", "y"),
                 lambda d: solver.normal(d["x"], d["y"], RHO),
                 lambda h: cfa_gram_np(h["x"], PATTERN) + RHO * gradient_gram_np(h["x"], pitch, dims)),
            Case(f"jacobi_apply {dims}", "admm.cl:jacobi_apply", "read P + write P", 2 * P, ("x", "y"),
                 lambda d: solver.precondition(d["x"], d["y"], RHO), lambda h: h["x"] * inverse_diagonal()),
            Case(f"build_rhs {dims}", "admm.cl:build_rhs", f"read N + {2 * k}P + write P", N + (2 * k + 1) * P,
                 ("b", g, g2, "y"),
                 lambda d: solver.right_hand_side(d["b"], d[g], d[g2], d["y"], RHO),
                 lambda h: cfa_adjoint_np(h["b"], PATTERN) + RHO * gradient_adjoint_np(h[g] - h[g2], pitch, dims)),
        ]
        if dims == "uv":
            blocks = lens_block_inverses(PATTERN, (0, 0), (U, V), RHO)
            cases.append(Case("lens_solve uv", "admm.cl:lens_solve", "read P + write P", 2 * P, ("x", "y"),
                              lambda d: solver.lens_solve(d["x"], d["y"], RHO),
                              lambda h: lens_solve_np(h["x"], blocks, (U, V))))
        return cases

    for dims in DIM_SETS:
        k, g = len(dims), f"g_{dims}"
        D = Gradient(runtime, planes, pitch, dims)
        cases += [
            Case(f"D {dims}", "gradient.cl:grad_forward", f"read P + write {k}P", (1 + k) * P, ("x", g),
                 lambda d, D=D, g=g: D.forward(d["x"], out=d[g]),
                 lambda h, dims=dims: gradient_np(h["x"], pitch, dims)),
            Case(f"D^T {dims}", "gradient.cl:grad_adjoint", f"read {k}P + write P", (1 + k) * P, (g, "y"),
                 lambda d, D=D, g=g: D.adjoint(d[g], out=d["y"]),
                 lambda h, dims=dims, g=g: gradient_adjoint_np(h[g], pitch, dims)),
            Case(f"D^T D {dims}", "gradient.cl:grad_gram", "read P + write P", 2 * P, ("x", "y"),
                 lambda d, D=D: D.gram(d["x"], out=d["y"]),
                 lambda h, dims=dims: gradient_gram_np(h["x"], pitch, dims)),
        ]
        cases += admm_cases(dims)
        if dims == "uv" and height % U == 0 and width % V == 0:  # the same [2, 3, H, W] buffers
            cases += epi_cases(runtime, sensor, pitch)
    if height % U == 0 and width % V == 0:
        cases += depth_cases(runtime, sensor, pitch)

    cases += [
        Case("dot", "reduce.cl:dot_partials", "read 2P", 2 * P, ("x", "x2"),
             lambda d: red.dot(d["x"], d["x2"]), lambda h: dot_np(h["x"], h["x2"])),
        Case("norm2", "reduce.cl:norm2_partials", "read P", P, ("x",),
             lambda d: red.norm2(d["x"]), lambda h: norm2_np(h["x"])),
        Case("diff_norm2", "reduce.cl:diff_norm2_partials", "read 2P", 2 * P, ("x", "x2"),
             lambda d: red.diff_norm2(d["x"], d["x2"]), lambda h: diff_norm2_np(h["x"], h["x2"])),
        Case("abs_sum", "reduce.cl:abs_sum_partials", "read P", P, ("x",),
             lambda d: red.abs_sum(d["x"]), lambda h: abs_sum_np(h["x"])),
        Case("soft_threshold", "shrink.cl:soft_threshold", "read P + write P", 2 * P, ("z", "y"),
             lambda d: shrink.soft_threshold(d["z"], KAPPA, out=d["y"]), lambda h: soft_threshold_np(h["z"], KAPPA)),
        # dx = x, in place on z and u, dz into y
        Case("zu_update", "shrink.cl:zu_update", "read 3P + write 3P", 6 * P, ("x", "z", "u", "y"),
             lambda d: shrink.zu_update(d["x"], d["z"], d["u"], d["y"], KAPPA),
             lambda h: zu_update_np(h["x"], h["z"], h["u"], KAPPA)),
        Case("axpby", "linalg.cl:axpby", "read 2P + write P", 3 * P, ("x", "x2", "y"),
             lambda d: vec.axpby(0.5, d["x"], -0.25, d["x2"], out=d["y"]),
             lambda h: axpby_np(0.5, h["x"], -0.25, h["x2"])),
    ]
    return cases


def _check_memory(runtime, specs: dict, cases: list[Case], size) -> None:
    """A ``ValueError`` before allocating when the buffers cannot fit the device."""
    device = runtime.device
    nbytes = {k: int(np.prod(shape)) * FLOAT for k, (shape, _, _) in specs.items()}
    largest_key = max(nbytes, key=nbytes.get)
    peak = 0
    for i in range(len(cases)):  # live buffers: used by this case or a later one, and already made
        made = {k for c in cases[: i + 1] for k in c.buffers}
        later = {k for c in cases[i:] for k in c.buffers}
        peak = max(peak, sum(nbytes[k] for k in made & later))
    name = device.name.strip()
    hint = f"try a smaller --size than {size[0]}x{size[1]}"
    if nbytes[largest_key] > device.max_mem_alloc_size:
        raise ValueError(
            f"size {size[0]}x{size[1]} needs a {nbytes[largest_key] / 2**20:.0f} MiB buffer (gradient {largest_key}) "
            f"but {name} allocates at most {device.max_mem_alloc_size / 2**20:.0f} MiB at once; {hint}"
        )
    if peak > device.global_mem_size:
        raise ValueError(
            f"size {size[0]}x{size[1]} needs {peak / 2**20:.0f} MiB of device memory at once "
            f"but {name} has {device.global_mem_size / 2**20:.0f} MiB; {hint}"
        )


def _allocation_error(exc, case: Case, size) -> ValueError | None:
    """A ``ValueError`` for an OpenCL error that means "out of device memory", else None."""
    if isinstance(exc, cl.MemoryError) or getattr(exc, "code", None) in _ALLOCATION_ERRORS:
        return ValueError(f"the device could not allocate the buffers of {case.name} at size "
                          f"{size[0]}x{size[1]} ({exc}); try a smaller --size")
    return None


def run(runtime, size, pitch=(9, 9), repeats: int = 5, numpy_repeats: int = 1, only=None, progress=None) -> dict:
    """Benchmark every kernel at sensor ``size`` (H, W); see the module docstring.

    ``only``: substrings of case names to keep (default: all). ``progress(name)``
    is called before each case. Returns a JSON-ready dict.
    """
    height, width = (int(n) for n in size)
    U, V = (int(p) for p in pitch)
    if height % U or width % V:
        raise ValueError(f"--size {height}x{width} is not a whole number of {U}x{V} microlenses")
    if repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {repeats}")
    if numpy_repeats < 0:
        raise ValueError(f"--numpy-repeats must be >= 0, got {numpy_repeats}")
    cases = build_cases(runtime, height, width, (U, V))
    if only:
        wanted = [c for c in cases if any(s.lower() in c.name.lower() for s in only)]
        if not wanted:
            raise ValueError(f"no kernel matches {', '.join(only)}; kernels: {', '.join(c.name for c in cases)}")
        cases = [cases[0]] + [c for c in wanted if c is not cases[0]]  # the copy reference always runs
    specs = buffer_specs(height, width, pitch)
    _check_memory(runtime, specs, cases, (height, width))
    pool = _Pool(runtime, specs)
    queue = runtime.queue
    rows = []
    try:
        for i, case in enumerate(cases):
            if progress is not None:
                progress(case.name)
            try:
                pool.ensure(case.buffers, want_host=numpy_repeats > 0 and case.numpy is not None)
                device = time_calls(lambda: case.device(pool.device), repeats, warmup=1, sync=queue.finish)
            except cl.Error as exc:
                error = _allocation_error(exc, case, (height, width))
                if error is None:
                    raise
                raise error from exc
            nbytes = case.floats * FLOAT
            row = {
                "name": case.name, "kernel": case.kernel, "traffic": case.traffic, "bytes": nbytes,
                "seconds": device.median, "times": device.times, "gb_per_s": gb_per_s(nbytes, device.median),
                "numpy_seconds": None, "numpy_times": None, "speedup": None, "numpy_error": None,
            }
            if numpy_repeats > 0 and case.numpy is not None:
                try:
                    twin = time_calls(lambda: case.numpy(pool.host), numpy_repeats, warmup=1)
                    row.update(numpy_seconds=twin.median, numpy_times=twin.times,
                               speedup=twin.median / device.median if device.median > 0 else None)
                except MemoryError:
                    row["numpy_error"] = "out of host memory"
            rows.append(row)
            pool.release({k for c in cases[i + 1:] for k in c.buffers})
    finally:
        pool.release(set())
        queue.finish()
    copy = rows[0]
    for row in rows:
        row["copy_fraction"] = row["gb_per_s"] / copy["gb_per_s"]
    info = runtime.device
    return {
        "device": runtime.name,
        "platform": info.platform.name.strip(),
        "compute_units": info.max_compute_units,
        "size": [height, width],
        "pitch": [U, V],
        "lenses": [height // U, width // V],
        "pattern": PATTERN,
        "elements": {"N": height * width, "P": 3 * height * width},
        "light_field_bytes": 3 * height * width * FLOAT,
        "repeats": repeats,
        "numpy_repeats": numpy_repeats,
        "copy_gb_per_s": copy["gb_per_s"],
        "kernels": rows,
    }


def format_report(report: dict) -> str:
    """The results as a Markdown table with a one-line header."""
    H, W = report["size"]
    head = (f"{report['device']} ({report['platform']}, {report['compute_units']} compute units): "
            f"sensor {H}x{W} = {report['lenses'][0]}x{report['lenses'][1]} lenses of "
            f"{report['pitch'][0]}x{report['pitch'][1]}, N = {report['elements']['N']:,} pixels, "
            f"P = 3N = {report['elements']['P']:,} floats ({report['light_field_bytes'] / 1e6:.0f} MB); "
            f"median of {report['repeats']} (numpy: {report['numpy_repeats']}); "
            f"copy bandwidth {report['copy_gb_per_s']:.2f} GB/s")
    rows = []
    for r in report["kernels"]:
        numpy_ms = f"{r['numpy_seconds'] * 1e3:.1f}" if r["numpy_seconds"] is not None else (r["numpy_error"] or "-")
        speedup = f"{r['speedup']:.1f}x" if r["speedup"] is not None else "-"
        rows.append([r["name"], f"{r['seconds'] * 1e3:.2f}", f"{r['gb_per_s']:.2f}", f"{100 * r['copy_fraction']:.0f}%",
                     numpy_ms, speedup, r["traffic"], r["kernel"]])
    table = format_table(["kernel", "ms", "GB/s", "of copy", "numpy ms", "speed-up", "min. traffic", "source"],
                         rows, align="lrrrrrll")
    return head + "\n\n" + table
