"""Score the shipped ``--method auto`` rule on captures it was not fitted on.

``python -m lfcl.bench.auto_rule`` fits the rule on training captures and scores it on
held-out *seeds* of the same built-in scenes. The ``charts`` scene does not depend on
its seed, so there that check meets new noise but not new content. This benchmark
scores the rule as shipped (lfcl/data/auto_rule.json) on any capture the shared
capture options name, e.g. raws simulated from a rendered light field of real
content that nothing in lfcl was fitted on:

    python -m lfcl.bench.auto_check --lightfield ../shared/realdata/hci_epinet/antinous \\
        --lenses 64 --lux 0.25,0.5,1,2,4,8,12,25,50,100,200

For every capture: the noise level, the candidate the rule picks there, its PSNR
(centre view / mean image), the best fixed method on each view (every candidate at
its default strength, either start: the peers of ``auto_rule``) and auto's loss
against them (``--view``: the worse of the two views, or the one view whose rule it
checks), what the best choice among the fixed methods made with the ground truth would
lose (``oracle``: above 0 only for ``both``, where no single method need be best in both
views), the raw's cross-lens ratio and whether the rule's band was fitted on such content
(lfcl/lens_ratio.py), and Malvar's PSNR.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..auto import VIEWS, choose, load_rules, rule_bands
from .auto_rule import DEFAULT_CANDIDATES, candidate_name, held_out_losses, is_fixed, parse_candidates, score_captures
from .timing import add_capture_arguments, captures, format_table


def check_rows(rows: list[dict], rule, view: str = "both") -> list[dict]:
    """Per scored capture (``score_captures``'s rows): what ``rule`` (judged on ``view``) picks and how it
    fares. ``rule``: sigma bands, or a rule file's contents, whose content class the capture's cross-lens
    ratio picks (lfcl.auto.content_class)."""
    bands, rules = (None, rule) if isinstance(rule, dict) else (rule, None)
    out = []
    for row, held_out in zip(rows, held_out_losses(rows, rule, view)):
        picked, results = held_out["candidate"], row["results"]
        fixed = [name for name in results if is_fixed(name)]
        best = {key: max(fixed, key=lambda name: results[name][key]) for key in ("psnr_center", "psnr_mean")}
        out.append({"scene": row["scene"], "lux": row["lux"], "sigma": row["sigma"], "auto": picked,
                    "auto_psnr": [results[picked]["psnr_center"], results[picked]["psnr_mean"]],
                    "best_center": [best["psnr_center"], results[best["psnr_center"]]["psnr_center"]],
                    "best_mean": [best["psnr_mean"], results[best["psnr_mean"]]["psnr_mean"]],
                    "loss_db": held_out["loss_db"], "oracle_loss_db": held_out["oracle_loss_db"],
                    "oracle": held_out["oracle"], "lens_ratio": row.get("lens_ratio"),
                    "seen_content": choose(row["sigma"], bands, lens_ratio=row.get("lens_ratio"), view=view,
                                           rules=rules).seen_content,
                    "malvar_psnr": ([results["malvar"]["psnr_center"], results["malvar"]["psnr_mean"]]
                                    if "malvar" in results else None)})
    return out


def format_check(checked: list[dict]) -> str:
    rows = [[r["scene"], f"{r['lux']:g}", f"{r['sigma']:.4f}", r["auto"],
             f"{r['auto_psnr'][0]:.2f} / {r['auto_psnr'][1]:.2f}",
             f"{r['best_center'][1]:.2f} ({r['best_center'][0]})", f"{r['best_mean'][1]:.2f} ({r['best_mean'][0]})",
             f"{r['loss_db']:.2f}", f"{r['oracle_loss_db']:.2f}", _content(r),
             "n/a" if r["malvar_psnr"] is None else f"{r['malvar_psnr'][0]:.2f} / {r['malvar_psnr'][1]:.2f}"]
            for r in checked]
    return format_table(["scene", "lux", "sigma", "auto picks", "auto dB", "best centre", "best mean", "loss dB",
                         "oracle dB", "cross-lens ratio", "malvar dB"], rows, "lrrlrrrrrrr")


def _progress(line: str) -> None:
    """Each scored capture on stderr as it finishes (a full frame takes minutes), the table on stdout."""
    print(line, file=sys.stderr, flush=True)


def capture_label(scene: str, lenses: int | None, texture: str | None = None) -> str:
    """The scene's name in the tables, with its texture's file name (``--texture``); a light field's
    full frame (``--lenses full``) says so."""
    return (Path(scene).name + (f" + {Path(texture).name}" if texture else "")
            + (" (full frame)" if lenses is None else ""))


def _content(checked: dict) -> str:
    """The raw's cross-lens ratio and whether the rule's band was fitted on such content."""
    if checked["lens_ratio"] is None:
        return "n/a"
    return f"{checked['lens_ratio']:.2f} ({'seen' if checked['seen_content'] else 'not seen'})"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_capture_arguments(parser, DEFAULT_CANDIDATES)
    parser.add_argument("--json", default=None, metavar="PATH", help="also write the scored rows here")
    parser.add_argument("--view", choices=VIEWS, default="both",
                        help="the rule to check and the view its loss is judged on (lfcl.auto.VIEWS)")
    parser.set_defaults(lenses="64", lux="0.25,0.5,1,2,4,8,12,25,50,100,200")
    args = parser.parse_args(argv)
    rules = load_rules()
    candidates = parse_candidates(args.methods)
    names = {candidate_name(*candidate) for candidate in candidates}
    picks = {band["candidate"] for content in ("default", "low-ratio")
             for band in rule_bands(rules, args.view, content) or ()}
    missing = sorted(picks - names)
    if missing:
        parser.error(f"--methods must hold every candidate the rule picks; missing {', '.join(missing)}")
    if not any(is_fixed(name) for name in names):
        parser.error("--methods must hold at least one method at its default strength (the peers)")
    scored = score_captures(((capture_label(scene, lenses, capture.meta["scene"].get("texture")), args.seed, lux,
                              capture)
                             for lenses, scene, lux, capture in captures(args)), candidates, log=_progress)
    checked = check_rows(scored, rules, args.view)
    print(format_check(checked))
    worst = max(checked, key=lambda r: r["loss_db"])
    print(f"\nworst loss {worst['loss_db']:.2f} dB ({worst['scene']}, {worst['lux']:g} lux); "
          f"within 0.2 dB at {sum(r['loss_db'] <= 0.2 for r in checked)} of {len(checked)} captures; "
          f"the best choice among the fixed methods would be within 0.2 dB at "
          f"{sum(r['oracle_loss_db'] <= 0.2 for r in checked)}")
    if args.json:
        from ..imageio import write_json

        write_json(args.json, {"args": vars(args), "rows": scored, "checked": checked})


if __name__ == "__main__":
    main()
