"""The disparity cost's colour penalty (lfcl/depth/cost.py): fit its weight on training captures only; report the
held-out periodic scene, the in-focus checker and the real light fields.

The penalty charges a disparity candidate for colour its lens does not have. Its purpose is content the training
captures lack: a grey checkerboard of 2-lens squares in focus, which the per-colour fits explain exactly at d = 0
(grey) and at d = +-2 (coloured), so that noise chose and admm-epi painted false colour (docs/auto.md, "Periodic
content"). On the training captures it can only cost (coloured texture off the focal plane pays a little at its
true disparity). So the weight is the largest of ``WEIGHTS`` whose worst change on the training captures, against
no penalty (centre view or mean image, admm-epi as `lfcl process` runs it), stays within ``TOLERANCE`` dB.

    python research/fit_colour_penalty.py fit --lenses 48 --shared ../shared
    python research/fit_colour_penalty.py held-out --lenses 48 --real-lenses 256 --shared ../shared

Regenerates: lfcl.depth.estimate.DEFAULTS["colour"] (by hand, from the printed choice; docs/depth.md, "The colour
penalty").
"""

from __future__ import annotations

import argparse
from pathlib import Path

from epi_start_guard import summary
from fit_auto import training_captures  # the same training captures as auto's rule (research/fit_auto.py)

import lfcl.solvers.epi as epi
from lfcl.evaluation.evaluate import run_method, simulated_capture, simulation_capture

WEIGHTS = (0.0, 0.01, 0.03, 0.1, 0.3)
TOLERANCE = 0.05


def checker_capture(lenses: int, lux: float, seed: int):
    """The periodic scene's checker quadrant alone, over the whole frame: grey squares of 2 lenses at d = 0."""
    from lfcl.sim import simulate
    from lfcl.sim.periodic import Checker
    from lfcl.sim.planes import Plane

    plane = Plane("checker", 0.0, Checker(2.0, (0.05,) * 3, (0.95,) * 3, (0.3, 0.7)))
    return simulation_capture(simulate(planes=[plane], lenses=(lenses, lenses), lux=lux, seed=seed))


def table(captures, lux_levels) -> dict:
    """{(label, lux): {"w=...": (centre gain, mean gain) over Malvar}}, printed as it goes."""
    rows = {}
    for label, make in captures:
        for lux in lux_levels:
            capture = make(lux)
            malvar = run_method(capture, "malvar")
            cell = {}
            for weight in WEIGHTS:
                epi.EPI_DEPTH_OPTIONS["colour"] = weight
                result = run_method(capture, "admm-epi")
                cell[f"w={weight:g}"] = (result["psnr_center"] - malvar["psnr_center"],
                                         result["psnr_mean"] - malvar["psnr_mean"])
            rows[label, lux] = cell
            print(f"{label} {lux:g} lux: " + " | ".join(f"{name}: {c:+.2f}/{m:+.2f}" for name, (c, m) in cell.items()),
                  flush=True)
    epi.EPI_DEPTH_OPTIONS.pop("colour", None)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=("fit", "held-out"))
    parser.add_argument("--lenses", type=int, default=48)
    parser.add_argument("--real-lenses", type=int, default=256)
    parser.add_argument("--lux", default="0.5,2,12,50")
    parser.add_argument("--shared", type=Path, default=Path("../shared"))
    args = parser.parse_args(argv)
    lux_levels = [float(v) for v in args.lux.split(",")]
    names = [f"w={w:g}" for w in WEIGHTS]
    if args.part == "fit":
        captures = [(label, lambda lux, source=source: simulated_capture(args.lenses, lux, **source))
                    for label, source in training_captures(args.shared)]
        scores = summary(table(captures, lux_levels), names, names[0])
        chosen = max(w for w in WEIGHTS if scores[f"w={w:g}"][0] >= -TOLERANCE)
        print(f"\nchosen: colour = {chosen:g} (the largest weight whose worst change is within {TOLERANCE} dB)")
        return
    realdata = args.shared / "realdata"
    captures = [("periodic 7", lambda lux: simulated_capture(args.lenses, lux, seed=7, scene="periodic")),
                ("checker 3", lambda lux: checker_capture(24, lux, 3))]
    for name, folder in (("antinous", "hci_epinet/antinous"), ("lytro 2067", "lytro_epinet/2067")):
        if (realdata / folder).is_dir():
            captures.append((name, lambda lux, p=str(realdata / folder): simulated_capture(args.real_lenses, lux,
                                                                                         seed=7, lightfield=p)))
    summary(table(captures, lux_levels), names, names[0])


if __name__ == "__main__":
    main()
