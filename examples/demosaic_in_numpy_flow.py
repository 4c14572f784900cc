"""Embed lfcl's OpenCL demosaic in your own numpy flow.

Reads a Bayer mosaic with OpenImageIO (any EXR/TIFF/PNG), demosaics it on the default
OpenCL device, and writes a linear EXR that other tools open.

    python examples/demosaic_in_numpy_flow.py mosaic.exr GRBG out.exr
"""

import sys

import numpy as np

import lfcl
from lfcl.io.images import read_image, write_image


def main(source: str, pattern: str, target: str) -> None:
    mosaic = read_image(source)[:, :, 0]           # one channel: the CFA samples
    rgb = lfcl.malvar(mosaic, pattern)             # (H, W, 3) float32, not clipped
    print(f"{source}: {mosaic.shape[1]}x{mosaic.shape[0]} -> RGB, range {rgb.min():.3f}..{rgb.max():.3f}")
    write_image(target, np.clip(rgb, 0, None), {"method": "malvar", "pattern": pattern})


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
