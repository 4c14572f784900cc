"""Run a stage recipe from Python on a simulated capture (docs/stages.md).

    python examples/run_recipe.py [RECIPE]      # default, lowlight, preview or a .toml path; default: lowlight

Simulates a small dim lenslet capture into a temporary folder (lfcl.sim), builds the
recipe's Pipeline (Decode -> Grid -> Demosaic -> Outputs), runs it, and prints what
each stage took and what was written.
"""

import sys
import tempfile
from pathlib import Path

from lfcl.pipeline.recipes import load_recipe, pipeline_from_recipe
from lfcl.sim import simulate, write_capture


def main(recipe_name: str = "lowlight") -> None:
    recipe = load_recipe(recipe_name)
    print(f"recipe {recipe['name']}: {recipe['description']}")
    with tempfile.TemporaryDirectory() as tmp:
        capture = write_capture(simulate("deadleaves", lenses=(16, 20), lux=4, seed=1), Path(tmp) / "capture")
        pipeline = pipeline_from_recipe(recipe, pitch=9)  # overrides: any recipe key, or pitch/pattern/device/...
        summary = pipeline.run(capture / "raw.dng", Path(tmp) / "out")
        print(f"method {summary['method']}, {summary['iterations']} iterations ({summary['stop_reason']}), "
              f"light field {pipeline.lightfield.shape}")
        print("seconds: " + ", ".join(f"{k} {v:.2f}" for k, v in summary["seconds"].items()))
        print("options: " + ", ".join(f"{k}={v}" for k, v in summary["options"].items()))
        print("wrote: " + ", ".join(summary["outputs"] + ["summary.json"]))


if __name__ == "__main__":
    if len(sys.argv) > 2:
        sys.exit(__doc__)
    main(*sys.argv[1:])
