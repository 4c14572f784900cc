"""`lfcl bench process`: `lfcl process` end to end per method, in one run, against a peer method.

Each method runs as a user runs it, ``lfcl process RAW --method M --outputs center --no-previews --json`` (or the
``outputs`` given), each run in a fresh process, so the wall time holds the start-up, the decode, the lens grid,
the demosaic stage and the writing, and the peak resident memory is that process's own (``os.wait4``). The kernels
are built and cached beforehand (:func:`run`). Reported per method: the median wall and demosaic-stage seconds
over ``repeats`` runs, the largest peak RSS, the iterations (and, for a solve in bands that each stopped on their
own, their mean over the lens rows, which the time follows), the centre view's PSNR against ``truth`` (the CLI takes a folder of
`lfcl simulate` and its truth), and both times as ratios against the ``peer`` method of the same run: issue 20 asks
admm-epi for at most 2x admm-uv's end-to-end time and 4 GB at 500x500 lenses (BENCHMARKS.md has the figures and the commands).

Example::

    lfcl bench process --lenses 64x64 --lux 2 --methods admm-uv,auto,admm-epi --peer admm-uv
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: How a child process runs the command-line interface (no console script needed on PATH).
CLI = ("-c", "import sys; from lfcl.cli import main; sys.argv[0] = 'lfcl'; main()")


def run_once(raw: Path, method: str, pitch: int, out: Path, device=None, outputs: str = "center") -> dict:
    """One ``lfcl process`` run into ``out``: wall seconds, the summary's stage seconds, peak RSS (bytes)."""
    command = [sys.executable, *CLI, "process", str(raw), "--pitch", str(pitch), "--method", method,
               "--outputs", outputs, "--no-previews", "--json", "-o", str(out / "process")]
    if device is not None:
        command += ["--device", str(device)]
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "stdout.json", "w") as stdout, open(out / "stderr.txt", "w") as stderr:
        began = time.perf_counter()
        child = subprocess.Popen(command, stdout=stdout, stderr=stderr)
        _, status, usage = os.wait4(child.pid, 0)  # this child's own resource use, its peak RSS among them
        wall = time.perf_counter() - began
        child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode != 0:
        tail = "\n".join((out / "stderr.txt").read_text().strip().splitlines()[-5:])
        raise RuntimeError(f"lfcl process --method {method} failed (exit {child.returncode}): {tail}")
    summary = json.loads((out / "stdout.json").read_text())
    return {"wall_seconds": wall, "seconds": summary["seconds"], "peak_rss_bytes": usage.ru_maxrss * 1024,
            "iterations": summary.get("iterations"), "mean_iterations": _mean_iterations(summary),
            "center": out / "process" / "center.exr"}


def _mean_iterations(summary: dict) -> float | None:
    """The iterations averaged over the lens rows, where the solve ran in bands that each stopped on their own
    (admm-epi: ``parameters.bands``); else the summary's iterations. The time of a banded run follows this mean."""
    bands = (summary.get("parameters") or {}).get("bands") or {}
    if bands.get("iterations") and bands.get("lens_rows"):
        return float(np.average(bands["iterations"], weights=bands["lens_rows"]))
    iterations = summary.get("iterations")
    return None if iterations is None else float(iterations)


def _demosaic_stage(seconds: dict) -> float:
    """The whole demosaic stage of a summary's ``seconds``: admm-epi's disparity is reported apart from it."""
    return seconds["demosaic"] + seconds.get("disparity", 0.0)


def centre_psnr(image_path: Path, truth: np.ndarray) -> float:
    """PSNR of a written centre view against the centre view of ``truth`` [S, T, U, V, 3]."""
    from ..evaluation.metrics import psnr
    from ..io.images import read_image

    U, V = truth.shape[2:4]
    return psnr(read_image(image_path)[..., :3], truth[:, :, U // 2, V // 2, :])


def run(raw: Path, methods, peer: str, *, pitch: int = 9, truth: np.ndarray | None = None, repeats: int = 1,
        device=None, progress=None, label: str | None = None, outputs: str = "center") -> dict:
    """Every method (and the peer) ``repeats`` times through `lfcl process`; rows and ratios (module docstring).

    First each method runs once, untimed, on a 16x16-lens capture of the same pitch: the OpenCL kernels are built
    and cached then, so that no timed run pays for building them (a user's first run does, once).
    """
    from ..demosaic.names import parse_method_spec
    from ..sim import simulate, write_capture

    if repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {repeats}")
    if "center" not in outputs.split(","):
        raise ValueError(f"--outputs must include center (the view the PSNR is of), got {outputs!r}")
    names = list(dict.fromkeys([peer, *methods]))
    for name in names:
        parse_method_spec(name)  # an unknown method: one line before anything runs
    rows = []
    with tempfile.TemporaryDirectory(prefix="lfcl_bench_process_") as tmp:
        small = write_capture(simulate("charts", lenses=(16, 16), pitch=pitch, lux=2.0, seed=0), Path(tmp) / "warm")
        for name in names:
            if progress is not None:
                progress(f"{name}: building its kernels on a 16x16-lens capture")
            run_once(small / "raw.dng", name, pitch, Path(tmp) / f"warm_{len(rows)}", device, outputs)
        for name in names:
            runs = []
            for k in range(repeats):
                if progress is not None:
                    progress(f"{name} run {k + 1} of {repeats}")
                runs.append(run_once(raw, name, pitch, Path(tmp) / f"{len(rows)}_{k}", device, outputs))
            row = {"method": name, "runs": repeats,
                   "wall_seconds": statistics.median(r["wall_seconds"] for r in runs),
                   "demosaic_seconds": statistics.median(_demosaic_stage(r["seconds"]) for r in runs),
                   "disparity_seconds": statistics.median(r["seconds"].get("disparity", 0.0) for r in runs),
                   "peak_rss_gb": max(r["peak_rss_bytes"] for r in runs) / 1e9,
                   "iterations": runs[-1]["iterations"], "mean_iterations": runs[-1]["mean_iterations"],
                   "psnr_center": None if truth is None else centre_psnr(runs[-1]["center"], truth)}
            rows.append(row)
    base = rows[0]
    for row in rows:
        row["wall_ratio"] = row["wall_seconds"] / base["wall_seconds"]
        row["demosaic_ratio"] = row["demosaic_seconds"] / base["demosaic_seconds"]
    return {"raw": label or str(raw), "peer": peer, "repeats": repeats, "outputs": outputs, "rows": rows}


def format_report(report: dict) -> str:
    lines = [f"{report['raw']}: `lfcl process RAW --method M --outputs {report['outputs']} --no-previews`, median of "
             f"{report['repeats']}; ratios against {report['peer']} of the same run", "",
             "| method | wall s | x peer | demosaic stage s | x peer | of it disparity s | peak RSS GB | iterations "
             "(mean over lens rows) | centre view dB |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in report["rows"]:
        centre = "-" if r["psnr_center"] is None else f"{r['psnr_center']:.3f}"
        iterations = "-" if r["iterations"] is None else str(r["iterations"])
        if r.get("mean_iterations") is not None and r["mean_iterations"] != r["iterations"]:
            iterations += f" ({r['mean_iterations']:.1f})"  # bands that stopped apart
        lines.append(f"| {r['method']} | {r['wall_seconds']:.2f} | {r['wall_ratio']:.2f}x | "
                     f"{r['demosaic_seconds']:.2f} | {r['demosaic_ratio']:.2f}x | "
                     f"{r['disparity_seconds']:.2f} | {r['peak_rss_gb']:.2f} | {iterations} | {centre} |")
    return "\n".join(lines)
