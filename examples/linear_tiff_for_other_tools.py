"""Process a lenslet raw into a linear 16-bit TIFF and a float EXR that other tools open.

    python examples/linear_tiff_for_other_tools.py [RAW OUT_DIR]

Without arguments, a small simulated capture (lfcl.sim) stands in for the raw and the files go
to a temporary folder. The stages run once up to the demosaic; the Outputs stage then writes
the centre view and the mean image twice: as 16-bit TIFF (linear camera RGB clipped to [0, 1])
and as EXR (float32, scene-linear, unclipped), no previews. Each file is read back with
OpenImageIO to show what another tool sees: size, channels, pixel type and lfcl's metadata.
"""

import json
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from lfcl.pipeline.stages import Decode, Demosaic, Grid, Outputs


def show(path: Path) -> None:
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(f"OpenImageIO cannot open {path}: {oiio.geterror()}")
    spec = inp.spec()
    pixels = inp.read_image(oiio.FLOAT)
    inp.close()
    note = spec.get_string_attribute("ImageDescription") or ""
    try:
        method = json.loads(note)["lfcl"]["method"]  # lfcl's metadata, in every format (lfcl.io.images)
    except (ValueError, KeyError, TypeError):
        method = "?"
    print(f"  {path.name}: {spec.width}x{spec.height}, {spec.nchannels} channels ({','.join(spec.channelnames)}), "
          f"{spec.format}, range {pixels.min():.4f}..{pixels.max():.4f}, method in metadata: {method}")


def main(raw: Path, out_dir: Path) -> None:
    mosaic = Decode()(raw)
    demosaiced = Demosaic("admm-uv")(Grid(pitch=9)(mosaic))
    print(f"{raw}: {demosaiced.lightfield.shape[0]}x{demosaiced.lightfield.shape[1]} lenses, "
          f"{demosaiced.result.iterations} ADMM iterations")
    for fmt in ("tiff", "exr"):
        written = Outputs(outputs=["center", "mean"], fmt=fmt, previews=False)(demosaiced, out_dir)
        for path in written.paths:
            show(path)
    tif = oiio.ImageBuf(str(out_dir / "center.tif"))
    exr = oiio.ImageBuf(str(out_dir / "center.exr"))
    diff = np.abs(tif.get_pixels(oiio.FLOAT) - np.clip(exr.get_pixels(oiio.FLOAT), 0, 1)).max()
    print(f"  TIFF vs clipped EXR: largest difference {diff:.2e} (16-bit quantisation: {0.5 / 65535:.2e})")


if __name__ == "__main__":
    if len(sys.argv) == 3:
        main(Path(sys.argv[1]), Path(sys.argv[2]))
    elif len(sys.argv) == 1:
        from lfcl.sim import simulate, write_capture

        with tempfile.TemporaryDirectory() as tmp:
            capture = write_capture(simulate("charts", lenses=(16, 20), lux=8, seed=2), Path(tmp) / "capture")
            main(capture / "raw.dng", Path(tmp) / "out")
    else:
        sys.exit(__doc__)
