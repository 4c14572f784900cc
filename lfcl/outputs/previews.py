"""Camera RGB -> sRGB for 8-bit previews, from the raw's own colour metadata (docs/outputs.md).

The light field is linear *camera* RGB (the normalised raw's units). A preview is

1. **White balance** in camera space: multiply by the as-shot gains (LibRaw's
   camera multipliers, ``1 / AsShotNeutral`` for a DNG, normalised to G = 1), so
   the scene's neutral becomes camera (1, 1, 1). A file without as-shot gains is
   balanced for daylight (D65) when it has a colour matrix, else left as it is.
2. **Camera -> CIE XYZ** with a 3x3 matrix that takes white-balanced camera RGB
   (1, 1, 1) to the D65 white (Y = 1). In order of preference:

   * ``xyz`` from LibRaw's ``cam_xyz`` (rawpy ``rgb_xyz_matrix``, the DNG/Adobe
     ColorMatrix: camera from XYZ): ``camera_to_xyz = inv(cam_xyz) @ diag(cam_xyz @ XYZ_D65)``.
     The diagonal is dcraw/LibRaw's row normalisation: the chromatic adaptation
     happens in camera space, by the white balance (a von Kries transform in
     camera primaries), the convention of dcraw and LibRaw.
   * ``rgb_cam`` from rawpy's ``color_matrix`` (LibRaw's ``rgb_cam``: linear sRGB
     from white-balanced camera RGB) when ``cam_xyz`` is absent (the simulator's
     DNGs: it is the identity there): ``camera_to_xyz = M_sRGB->XYZ @ rgb_cam``.
   * neither: camera RGB is taken as linear sRGB (``camera_to_xyz = M_sRGB->XYZ``)
     and the metadata says so.

3. **XYZ -> linear sRGB** with colour-science's ``colour.XYZ_to_sRGB`` (IEC
   61966-2-1 primaries, illuminant D65, no adaptation needed: the white is
   already D65).
4. **Exposure**: one scale per run, ``0.9 / p99(Y)`` with ``Y`` the luminance
   (0.2126 R + 0.7152 G + 0.0722 B of linear sRGB) of the light field's samples
   (all views; at most ~1 M of them, evenly strided) so that the 99th percentile
   maps to 0.9 and every preview of a run shares one exposure.
5. **Clip** to [0, 1], **encode** with the sRGB transfer function
   (``colour.cctf_encoding(..., function="sRGB")``) and write 8 bits.
"""

from __future__ import annotations

import dataclasses

import numpy as np

#: The 99th percentile of the luminance maps to this.
TARGET = 0.9
PERCENTILE = 99.0
#: Luminance weights of linear sRGB (the Y row of its RGB -> XYZ matrix).
LUMA = np.array([0.2126, 0.7152, 0.0722])
MAX_SAMPLES = 1_000_000


def _colour():
    import colour  # colour-science; imported lazily (slow import)

    return colour


def d65_xy() -> np.ndarray:
    return np.asarray(_colour().CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"], np.float64)


def d65_xyz() -> np.ndarray:
    """The D65 white, Y = 1."""
    return np.asarray(_colour().xy_to_XYZ(d65_xy()), np.float64)


def srgb_to_xyz_matrix() -> np.ndarray:
    return np.asarray(_colour().RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ, np.float64)


@dataclasses.dataclass
class ColourPipeline:
    """How camera RGB becomes sRGB: white-balance gains, then a camera -> XYZ (D65) matrix."""

    wb_gains: np.ndarray  # (3,), applied to camera RGB
    wb_source: str  # "as shot", "daylight (D65, from the colour matrix)", "none"
    camera_to_xyz: np.ndarray  # (3, 3): XYZ (D65 white at Y = 1) from white-balanced camera RGB
    matrix_source: str  # "xyz", "rgb_cam" or "none"
    notes: list[str] = dataclasses.field(default_factory=list)

    @classmethod
    def from_camera(cls, as_shot_wb=None, xyz_to_camera=None, color_matrix=None) -> ColourPipeline:
        """From a raw's metadata (:class:`lfcl.io.raw.Mosaic` fields; see the module docstring)."""
        notes: list[str] = []
        white = d65_xyz()
        matrix, source, daylight = None, "none", None
        if xyz_to_camera is not None:
            cam_xyz = np.asarray(xyz_to_camera, np.float64)[:3, :3]
            k = cam_xyz @ white  # camera response to the D65 white
            if np.all(np.isfinite(cam_xyz)) and abs(np.linalg.det(cam_xyz)) > 1e-12 and np.all(k > 0):
                matrix = np.linalg.inv(cam_xyz) @ np.diag(k)
                source = "xyz"
                daylight = k[1] / k  # dcraw's pre_mul, G = 1
            else:
                notes.append("the raw's XYZ -> camera matrix is singular or maps D65 outside the camera's "
                             "positive octant: not used")
        if matrix is None and color_matrix is not None:
            rgb_cam = np.asarray(color_matrix, np.float64)[:3, :3]
            if np.all(np.isfinite(rgb_cam)) and abs(np.linalg.det(rgb_cam)) > 1e-12:
                matrix = srgb_to_xyz_matrix() @ rgb_cam
                source = "rgb_cam"
            else:
                notes.append("the raw's camera -> sRGB matrix is singular: not used")
        if matrix is None:
            matrix = srgb_to_xyz_matrix()
            notes.append("no colour matrix in the raw: camera RGB treated as linear sRGB")
        if as_shot_wb is not None and all(np.isfinite(g) and g > 0 for g in as_shot_wb):
            gains = np.asarray(as_shot_wb, np.float64)[:3]
            wb_source = "as shot"
        elif daylight is not None:
            gains = daylight
            wb_source = "daylight (D65, from the colour matrix)"
            notes.append("no as-shot white balance in the raw: balanced for daylight")
        else:
            gains = np.ones(3)
            wb_source = "none"
            notes.append("no white balance in the raw: none applied")
        return cls(np.asarray(gains, np.float64), wb_source, np.asarray(matrix, np.float64), source, notes)

    @classmethod
    def from_mosaic(cls, mosaic) -> ColourPipeline:
        return cls.from_camera(mosaic.as_shot_wb, mosaic.xyz_to_camera, mosaic.color_matrix)

    # --- conversions -----------------------------------------------------------
    def to_xyz(self, rgb: np.ndarray) -> np.ndarray:
        """CIE XYZ (D65 white at Y = 1) of camera RGB ``[..., 3]`` (float64)."""
        rgb = np.asarray(rgb, np.float64)
        balanced = rgb * self.wb_gains
        return balanced @ self.camera_to_xyz.T

    def to_linear_srgb(self, rgb: np.ndarray) -> np.ndarray:
        """Linear sRGB (not clipped, not scaled) of camera RGB ``[..., 3]``."""
        colour = _colour()
        return np.asarray(colour.XYZ_to_sRGB(self.to_xyz(rgb), illuminant=d65_xy(), apply_cctf_encoding=False),
                          np.float64)

    def exposure(self, samples: np.ndarray) -> float:
        """The preview scale: ``TARGET / p99(luminance)`` over ``samples`` ``[..., 3]`` (1 if that is not positive)."""
        flat = np.asarray(samples).reshape(-1, 3)
        stride = max(1, flat.shape[0] // MAX_SAMPLES)
        luminance = self.to_linear_srgb(flat[::stride]) @ LUMA
        p = float(np.percentile(luminance, PERCENTILE)) if luminance.size else 0.0
        return TARGET / p if np.isfinite(p) and p > 0 else 1.0

    def preview(self, rgb: np.ndarray, scale: float) -> np.ndarray:
        """sRGB-encoded preview in [0, 1] (float32, ``[..., 3]``): balance, matrix, ``* scale``, clip, encode."""
        linear = np.clip(self.to_linear_srgb(rgb) * float(scale), 0.0, 1.0)
        return np.asarray(_colour().cctf_encoding(linear, function="sRGB"), np.float32)

    def metadata(self, scale: float | None = None) -> dict:
        meta = {
            "white_balance": {"gains": [float(g) for g in self.wb_gains], "source": self.wb_source},
            "camera_to_xyz": np.round(self.camera_to_xyz, 6).tolist(),
            "matrix_source": {"xyz": "inv(rawpy rgb_xyz_matrix) normalised so camera (1,1,1) -> D65",
                              "rgb_cam": "sRGB->XYZ @ rawpy color_matrix",
                              "none": "none: camera RGB taken as linear sRGB"}[self.matrix_source],
            "xyz_to_rgb": "colour.XYZ_to_sRGB, illuminant D65 (white already D65: no adaptation)",
            "exposure": f"x {TARGET:g} / p{PERCENTILE:g} of linear-sRGB luminance over the light field",
            "encoding": "clipped to [0, 1], sRGB transfer function (IEC 61966-2-1), 8 bits",
        }
        if scale is not None:
            meta["scale"] = float(scale)
        if self.notes:
            meta["notes"] = list(self.notes)
        return meta
