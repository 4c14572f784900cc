"""From a plenoptic raw to darktable: LinearRaw DNGs of the centre view and the mean image (docs/darktable.md).

    python examples/linear_dng_to_darktable.py [RAW OUT_DIR]

Without arguments, a simulated capture (lfcl.sim, 144x144 lenses of 9x9 pixels: views large enough for
RawTherapee, see below) stands in for
the raw and the files go to a temporary folder. The raw is demosaiced once (admm-uv); the
Outputs stage writes the centre view and the mean image as LinearRaw DNGs that carry the
raw's colour matrix, as-shot white balance, make and model. Each DNG is then opened with
rawpy (LibRaw) and, where installed, rendered to PNG by darktable-cli (its plain sRGB
workflow: no exposure boost, no tone mapping) and rawtherapee-cli.
"""

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from lfcl.pipeline.stages import Decode, Demosaic, Grid, Outputs


def render(dng: Path, out_dir: Path) -> None:
    import rawpy

    with rawpy.imread(str(dng)) as raw:
        rgb = raw.postprocess(use_camera_wb=True)
        gains = raw.camera_whitebalance[:3]
    print(f"  {dng.name}: rawpy renders {rgb.shape[1]}x{rgb.shape[0]}, as-shot multipliers "
          f"{', '.join(f'{g:.3f}' for g in gains)}")
    if shutil.which("darktable-cli"):
        png = out_dir / f"{dng.stem}_darktable.png"
        with tempfile.TemporaryDirectory() as conf:
            subprocess.run(["darktable-cli", str(dng), str(png), "--core", "--configdir", conf,
                            "--conf", "plugins/darkroom/workflow=none"], check=True, capture_output=True)
        print(f"    darktable-cli -> {png}")
    else:
        print("    darktable-cli not installed (apt-get install darktable): not rendered")
    if shutil.which("rawtherapee-cli"):
        png = out_dir / f"{dng.stem}_rawtherapee.png"
        done = subprocess.run(["rawtherapee-cli", "-o", str(png), "-n", "-Y", "-c", str(dng)], capture_output=True)
        if done.returncode == 0:
            print(f"    rawtherapee-cli -> {png}")
        elif rgb.shape[0] < 130 or rgb.shape[1] < 130:  # its known limit (docs/darktable.md), not the file's fault
            print(f"    rawtherapee-cli refused it (exit {done.returncode}): it opens no DNG under about 130x130 px")
        else:
            sys.exit(f"rawtherapee-cli failed on {dng} (exit {done.returncode}): {done.stderr.decode().strip()}")


def main(raw: Path, out_dir: Path) -> None:
    demosaiced = Demosaic("admm-uv")(Grid(pitch=9)(Decode()(raw)))
    S, T = demosaiced.lightfield.shape[:2]
    written = Outputs(outputs=["center", "mean"], fmt="dng", previews=False)(demosaiced, out_dir)
    print(f"{raw}: {S}x{T} lenses -> {out_dir}")
    for path in written.paths:
        render(path, out_dir)
    print("open them in darktable (or any raw editor) and go on as with a camera raw")


if __name__ == "__main__":
    if len(sys.argv) == 3:
        main(Path(sys.argv[1]), Path(sys.argv[2]))
    elif len(sys.argv) == 1:
        from lfcl.sim import simulate, write_capture

        out = Path(tempfile.mkdtemp(prefix="lfcl-dng-"))
        write_capture(simulate("charts", lenses=(144, 144), seed=1), out / "capture")
        main(out / "capture" / "raw.dng", out / "dng")
    else:
        sys.exit(__doc__)
