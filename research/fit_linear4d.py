"""Fit the linear4d coefficients (lfcl/ops/linear4d.py) by ridge-regularised least squares.

    python research/fit_linear4d.py -o lfcl/data/linear4d.npz

Training data: the procedural scenes of research/training_scenes.py (never
the evaluation scenes ``charts`` and ``deadleaves``), seeds ``--seed-base`` ..
``--seed-base + --scenes - 1``, each rendered once and exposed by the simulator's
sensor at every ``--lux`` level (:func:`lfcl.sim.simulate` with the rendered light
field, noise seed = scene seed). One coefficient set is fitted per lux level; the
sets are tagged with their relative noise (sigma of the DNG noise profile at the
mosaic's mean level, divided by that level, averaged over the scenes), which is what
:func:`lfcl.ops.linear4d.select_coefficients` interpolates on.

Per set and per phase ``(u, v, CFA class)`` the fit minimises, over the taps that
stay inside the lens at that ``(u, v)``,

    sum over training pixels of the phase  ||truth RGB - w^T taps||^2 + ridge * tr(G)/n ||w||^2

(``G`` the phase's Gram matrix of taps, ``n`` its number of taps): the normal
equations are accumulated in float64 scene by scene and solved once.
Everything is deterministic for fixed arguments.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np
from training_scenes import training_planes

from lfcl import __version__
from lfcl.layout import exchange_to_planes
from lfcl.noise.model import from_noise_profile
from lfcl.ops.linear4d import (
    CLASSES,
    Linear4dModel,
    cfa_classes,
    check_taps,
    save_model,
    tap_colours,
    tap_samples,
    valid_taps,
)

DEFAULT_LUX = (0.5, 1.0, 2.0, 4.0, 8.0, 12.0, 25.0, 50.0)
PATTERN = "GRBG"  # the simulator's default; coefficients are stored per CFA class, pattern-free


def tap_layout(in_lens_radius: int = 3, cross_radius: int = 0, diagonal_lenses: bool = True) -> np.ndarray:
    """Taps ``(ds, dt, du, dv)``: a ``(2r+1)^2`` window in the lens, and a ``(2q+1)^2`` window
    around the same ``(u, v)`` in each of the 4 (or 8, with the diagonals) neighbouring lenses."""
    r, q = int(in_lens_radius), int(cross_radius)
    taps = [(0, 0, du, dv) for du in range(-r, r + 1) for dv in range(-r, r + 1)]
    lenses = [(ds, dt) for ds in (-1, 0, 1) for dt in (-1, 0, 1)
              if (ds, dt) != (0, 0) and (diagonal_lenses or ds == 0 or dt == 0)]
    if q >= 0:
        taps += [(ds, dt, du, dv) for ds, dt in lenses for du in range(-q, q + 1) for dv in range(-q, q + 1)]
    return np.array(taps, dtype=np.int64)


@dataclasses.dataclass
class NormalEquations:
    """Per phase ``(u, v, class)``: Gram ``[U, V, 4, NT, NT]``, right-hand sides ``[U, V, 4, NT, 3]``."""

    gram: np.ndarray
    rhs: np.ndarray
    samples: np.ndarray  # [U, V, 4] pixels accumulated

    @classmethod
    def zeros(cls, pitch, n_taps: int) -> NormalEquations:
        U, V = pitch
        return cls(np.zeros((U, V, len(CLASSES), n_taps, n_taps)), np.zeros((U, V, len(CLASSES), n_taps, 3)),
                   np.zeros((U, V, len(CLASSES)), np.int64))


def phase_blocks(array: np.ndarray, pitch) -> np.ndarray:
    """``[..., H, W]`` -> ``[2, 2, U, V, ..., n]`` (contiguous, for BLAS): pixels grouped by lens-row
    parity, lens-column parity, u and v, which with the Bayer pattern fix the phase. H and W must be
    even numbers of lenses."""
    U, V = pitch
    *lead, H, W = array.shape
    S, T = H // U, W // V
    if S % 2 or T % 2:
        raise ValueError(f"training needs an even number of lens rows and columns, got {S}x{T}")
    blocks = array.reshape(*lead, S // 2, 2, U, T // 2, 2, V)
    k = len(lead)
    order = [k + 1, k + 4, k + 2, k + 5, *range(k), k, k + 3]
    return np.ascontiguousarray(blocks.transpose(order)).reshape(2, 2, U, V, *lead, -1)


def accumulate(equations: NormalEquations, mosaic: np.ndarray, truth_planes: np.ndarray, pitch, taps,
               pattern: str = PATTERN) -> None:
    """Add one mosaic ``[H, W]`` and its truth ``[3, H, W]`` to the normal equations (in place)."""
    U, V = pitch
    X = phase_blocks(tap_samples(mosaic, pitch, taps), pitch)  # [2, 2, U, V, NT, n]
    Y = phase_blocks(truth_planes.astype(np.float64), pitch)  # [2, 2, U, V, 3, n]
    classes = cfa_classes(pattern)
    for ps in range(2):
        for pt in range(2):
            gram = np.matmul(X[ps, pt], X[ps, pt].swapaxes(-1, -2))  # [U, V, NT, NT]
            rhs = np.matmul(X[ps, pt], Y[ps, pt].swapaxes(-1, -2))  # [U, V, NT, 3]
            for u in range(U):
                for v in range(V):
                    cls = classes[(ps * U + u) % 2, (pt * V + v) % 2]
                    equations.gram[u, v, cls] += gram[u, v]
                    equations.rhs[u, v, cls] += rhs[u, v]
                    equations.samples[u, v, cls] += X.shape[-1]


def solve(equations: NormalEquations, pitch, taps, ridge: float, keep_flat_colours: bool = True) -> np.ndarray:
    """Coefficients ``[U, V, 4, 3, NT]`` (0 for dropped taps) from the normal equations.

    ``keep_flat_colours``: constrain each output colour's taps of input colour j to sum to
    1 if j is that colour, else 0 (as Malvar's filters do), so a flat colour field comes
    back exactly; solved through the KKT system of the equality-constrained ridge problem.
    """
    U, V = pitch
    valid = valid_taps(pitch, taps)
    colours = tap_colours(pitch, taps)
    out = np.zeros((U, V, len(CLASSES), 3, len(taps)))
    for u in range(U):
        for v in range(V):
            keep = np.flatnonzero(valid[u, v])
            for cls in range(len(CLASSES)):
                if equations.samples[u, v, cls] == 0:
                    raise ValueError(f"no training pixel of class {CLASSES[cls]!r} at (u, v) = ({u}, {v})")
                gram = equations.gram[u, v, cls][np.ix_(keep, keep)]
                rhs = equations.rhs[u, v, cls][keep]
                n = len(keep)
                system = gram + ridge * (np.trace(gram) / n) * np.eye(n)
                if keep_flat_colours:
                    present = [j for j in range(3) if np.any(colours[cls, keep] == j)]
                    constraint = np.array([colours[cls, keep] == j for j in present], dtype=np.float64)
                    m = len(present)
                    kkt = np.block([[system, constraint.T], [constraint, np.zeros((m, m))]])
                    targets = np.eye(3)[present]  # [m, 3]: input colour j feeds output j alone
                    solution = np.linalg.solve(kkt, np.vstack([rhs, targets]))[:n]
                else:
                    solution = np.linalg.solve(system, rhs)
                out[u, v, cls][:, keep] = solution.T
    return out


def render_training_scenes(lenses, pitch, seeds):
    """Yield ``(seed, light field [S, T, U, V, 3])`` of the training scenes (noise-free, relative units)."""
    from lfcl.sim import render_planes

    for seed in seeds:
        yield seed, render_planes(training_planes(lenses, seed, pitch), lenses, pitch)


DEFAULT_LAYOUT = {"in_lens_radius": 3, "cross_radius": 0, "diagonal_lenses": True}


def fit(lenses=(64, 64), pitch=(9, 9), lux_levels=DEFAULT_LUX, scenes: int = 48, seed_base: int = 1000,
        layout=None, ridge: float = 1e-4, progress=None) -> Linear4dModel:
    """Fit one coefficient set per lux level on ``scenes`` training scenes; see the module docstring.

    ``layout``: the arguments of :func:`tap_layout` (default :data:`DEFAULT_LAYOUT`).
    """
    from lfcl.sim import simulate

    pitch = tuple(int(p) for p in pitch)
    lenses = tuple(int(n) for n in lenses)
    layout = dict(DEFAULT_LAYOUT if layout is None else layout)
    taps = check_taps(tap_layout(**layout), pitch)
    lux_levels = sorted((float(x) for x in lux_levels), reverse=True)  # increasing noise
    if scenes < 1 or not lux_levels:
        raise ValueError("fitting needs at least one scene and one lux level")
    seeds = list(range(seed_base, seed_base + scenes))
    equations = [NormalEquations.zeros(pitch, len(taps)) for _ in lux_levels]
    noise_sums = np.zeros(len(lux_levels))
    for seed, radiance in render_training_scenes(lenses, pitch, seeds):
        for i, lux in enumerate(lux_levels):
            capture = simulate(lightfield=radiance, lux=lux, seed=seed, pattern=PATTERN)
            mosaic = capture.normalised_raw()
            sigma = from_noise_profile(list(capture.sensor.noise_profile()) * 3, mosaic).sigma
            noise_sums[i] += sigma / float(np.mean(mosaic, dtype=np.float64))
            accumulate(equations[i], mosaic, exchange_to_planes(capture.truth), pitch, taps)
            if progress is not None:
                progress(f"scene {seed} at {lux:g} lux")
    coefficients = np.stack([solve(eq, pitch, taps, ridge) for eq in equations]).astype(np.float32)
    metadata = {
        "lfcl_version": __version__,
        "generator": "python research/fit_linear4d.py",
        "training_scenes": {"generator": "research/training_scenes.py training_planes", "seeds": seeds,
                            "lenses": list(lenses), "pattern": PATTERN},
        "lux": lux_levels,
        "noise_seed": "the scene seed (lfcl.sim.simulate seed)",
        "pitch": list(pitch),
        "tap_layout": "rows (ds, dt, du, dv): offsets in lenses (s, t) and in-lens pixels (u, v)",
        "tap_layout_arguments": layout,
        "n_taps": len(taps),
        "ridge": ridge,
        "constraint": "per output colour, the taps of each input colour sum to 1 (same colour) or 0: flat colours kept",
        "classes": list(CLASSES),
        "coefficients": "[set, u, v, class, colour R/G/B, tap]; 0 for taps outside the lens",
        "relative_noise": "sigma (DNG noise profile at the mosaic mean) / mosaic mean, averaged over the scenes",
    }
    return Linear4dModel(pitch, taps, coefficients, noise_sums / len(seeds), metadata)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-o", "--output", required=True, help="the .npz to write (lfcl/data/linear4d.npz ships)")
    parser.add_argument("--lenses", default="64x64", help="lenses per training scene, SxT (even)")
    parser.add_argument("--pitch", type=int, default=9)
    parser.add_argument("--lux", default=",".join(f"{x:g}" for x in DEFAULT_LUX), help="one coefficient set per level")
    parser.add_argument("--scenes", type=int, default=48)
    parser.add_argument("--seed-base", type=int, default=1000)
    parser.add_argument("--in-lens-radius", type=int, default=DEFAULT_LAYOUT["in_lens_radius"])
    parser.add_argument("--cross-radius", type=int, default=DEFAULT_LAYOUT["cross_radius"],
                        help="-1: no cross-lens taps")
    parser.add_argument("--no-diagonal-lenses", action="store_true")
    parser.add_argument("--ridge", type=float, default=1e-4)
    args = parser.parse_args(argv)
    from lfcl.sim import parse_lenses

    layout = {"in_lens_radius": args.in_lens_radius, "cross_radius": args.cross_radius,
              "diagonal_lenses": not args.no_diagonal_lenses}
    start = time.perf_counter()
    model = fit(parse_lenses(args.lenses), (args.pitch, args.pitch), [float(x) for x in args.lux.split(",")],
                args.scenes, args.seed_base, layout, args.ridge, progress=lambda m: print(m, flush=True))
    model.metadata["command"] = "python research/fit_linear4d.py " + " ".join(argv or __import__("sys").argv[1:])
    save_model(args.output, model)
    print(f"wrote {args.output}: {len(model.relative_noise)} sets x {len(model.taps)} taps "
          f"in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
