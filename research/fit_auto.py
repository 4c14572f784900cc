"""Fit `--method auto`'s rule (lfcl/data/auto_rule.json) on training captures only, never worse than Malvar.

Two steps:

    python research/fit_auto.py rows -o research/auto_rows.json      # run every candidate (minutes)
    python research/fit_auto.py rule research/auto_rows.json -o lfcl/data/auto_rule.json

``rows --candidates C --update research/auto_rows.json`` reruns only the candidates C (one whose defaults
changed) and keeps the others' gains; ``--captures L`` runs only the training captures labelled L (e.g. ``charts
1,charts 2``), whose rows ``--update`` replaces or adds.

``rows`` simulates every training capture (charts, deadleaves and finetexture at seeds 1 and 2; charts
planes carrying the four training photographs of docs/auto.md at seed 1) at each light level, runs
Malvar and every candidate through lfcl.evaluation.evaluate.run_method (as `lfcl process` runs them: the safety
net on, every lens solved) and keeps, per capture and level, the raw's noise level and cross-lens
ratio as auto sees them and each candidate's PSNR gain over Malvar (centre view, mean image) and
seconds. ``rule`` calls :func:`lfcl.demosaic.auto.fit_rules` on those rows (the selection lives in the package
so that tests/test_auto.py can check that the shipped file is what these rows give).

Regenerates: lfcl/data/auto_rule.json (and research/auto_rows.json, the rows it was fitted on).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

CANDIDATES = ("admm-uvst@1", "admm-uv@1", "admm-uv-xc@1", "admm-uv-xc@2", "linear4d", "admm-epi@1")
LUX = "0.25,0.5,1,2,4,8,12,25,50,100"
SCENES = ("charts", "deadleaves", "finetexture")
#: Stress families whose training seeds join the fits of the cheaper band's method (research/fit_uv_xc.py) and of
#: the safety net (research/fit_safety_net.py), not auto's rule: with them, one capture would move admm-epi's upper
#: bound by the costly margin alone (docs/auto.md, "Lens-scale gratings").
STRESS_SCENES = ("gratings",)
SEEDS = (1, 2)
TRAINING_PHOTOS = ("realdata/imageio_test_images/Blackmagic.dng", "realdata/digicam_corpus/Canon_PowerShot_G2_CRW_0304.CRW",
                   "realdata/digicam_corpus/Kodak_DC120_P003908_uncompressed.KDC", "realdata/a2tools_quicktake/QT150_TEST150.QTK")


def training_captures(shared: Path, stress: bool = False):
    """(label, simulated_capture kwargs) of every training capture; ``stress``: with :data:`STRESS_SCENES`."""
    for scene in SCENES + (STRESS_SCENES if stress else ()):
        for seed in SEEDS:
            yield f"{scene} {seed}", {"scene": scene, "seed": seed}
    for photo in TRAINING_PHOTOS:
        path = shared / photo
        if path.is_file():
            yield f"photo {path.name}", {"scene": "charts", "seed": 1, "texture": str(path)}


def make_rows(args) -> list[dict]:
    from lfcl.demosaic.auto import parse_candidate
    from lfcl.demosaic.lens_ratio import cross_lens_ratio
    from lfcl.evaluation.evaluate import run_method, simulated_capture
    from lfcl.noise.model import from_noise_profile

    rows = []
    only = {c.strip() for c in args.captures.split(",") if c.strip()} if args.captures else None
    for label, source in training_captures(args.shared):
        if only is not None and label not in only:
            continue
        for lux in (float(v) for v in args.lux.split(",")):
            capture = simulated_capture(args.lenses, lux, **source)
            noise = from_noise_profile(capture.noise_profile, capture.mosaic)
            malvar = run_method(capture, "malvar")
            row = {"capture": label, "lux": lux, "sigma": noise.sigma,
                   "lens_ratio": cross_lens_ratio(capture.mosaic, capture.pitch, noise),
                   "malvar": {"center": malvar["psnr_center"], "mean": malvar["psnr_mean"],
                              "seconds": malvar["seconds"]}, "gains": {}}
            for name in args.candidates.split(","):
                method, strength, start = parse_candidate(name)
                began = time.perf_counter()
                result = run_method(capture, method, strength=strength,
                                    **({"start": start} if start not in ("malvar", None) else {}))
                row["gains"][name] = {"center": result["psnr_center"] - malvar["psnr_center"],
                                      "mean": result["psnr_mean"] - malvar["psnr_mean"],
                                      "seconds": time.perf_counter() - began}
            rows.append(row)
            worst = min(row["gains"].items(), key=lambda item: min(item[1]["center"], item[1]["mean"]))
            print(f"{label} {lux:g} lux: sigma {noise.sigma:.4g}, ratio {row['lens_ratio']}, worst "
                  f"{worst[0]} {min(worst[1]['center'], worst[1]['mean']):+.2f} dB", file=sys.stderr, flush=True)
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="step", required=True)
    rows_parser = sub.add_parser("rows")
    rows_parser.add_argument("-o", "--output", type=Path, required=True)
    rows_parser.add_argument("--lenses", type=int, default=48)
    rows_parser.add_argument("--lux", default=LUX)
    rows_parser.add_argument("--candidates", default=",".join(CANDIDATES))
    rows_parser.add_argument("--shared", type=Path, default=Path("../shared"))
    rows_parser.add_argument("--captures", default="", metavar="LABELS",
                             help="only these training captures (comma-separated labels, e.g. 'gratings 1')")
    rows_parser.add_argument("--update", type=Path, metavar="ROWS",
                             help="rows to keep, with only --candidates rerun (their gains replaced) and the rows of "
                                  "captures they lack added: the output")
    rule_parser = sub.add_parser("rule")
    rule_parser.add_argument("rows", type=Path)
    rule_parser.add_argument("-o", "--output", type=Path, required=True)
    rule_parser.add_argument("--drop", default="", metavar="CANDIDATES",
                             help="candidates of the rows to leave out of the rule (measured and not wanted)")
    args = parser.parse_args(argv)
    if args.step == "rows":
        rows = make_rows(args)
        if args.update:  # the other candidates' gains as they were
            fresh = {(r["capture"], r["lux"]): r for r in rows}
            rows = json.loads(args.update.read_text())["rows"]
            for row in rows:
                key = (row["capture"], row["lux"])
                if key in fresh:
                    row["gains"].update(fresh.pop(key)["gains"])
                elif args.captures == "":
                    raise SystemExit(f"no fresh row for {key}")
            rows.extend(fresh.values())  # captures the kept rows lacked
        args.output.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows},
                                          indent=1))
        return
    from lfcl.demosaic.auto import fit_rules

    rows = json.loads(args.rows.read_text())["rows"]
    dropped = {c for c in args.drop.split(",") if c}
    for row in rows:
        row["gains"] = {c: g for c, g in row["gains"].items() if c not in dropped}
    rules = fit_rules(rows)
    rules["generator"] = f"research/fit_auto.py rule {args.rows.as_posix()}" + (f" --drop {args.drop}" if dropped else "")
    rules["dropped"] = sorted(dropped)
    args.output.write_text(json.dumps(rules, indent=1) + "\n")
    for view, bands in rules["rules"].items():
        picks = ", ".join(f"{b['sigma_from']:.2g}-{b['sigma_to']:.2g}: {b['candidate']} "
                          f"({b['worst_gain_db']:+.2f} worst, {b['median_gain_db']:+.2f} median)" for b in bands)
        print(f"{view}: {picks}")


if __name__ == "__main__":
    main()
