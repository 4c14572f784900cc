"""Load an existing 4D light field (``--lightfield PATH``) as linear ``[S, T, U, V, 3]``.

Two forms:

* a folder of views in the HCI 4D light-field benchmark layout:
  ``input_Cam000.png ... input_Cam{N-1}.png``, ``N = U * V`` a square (9x9 = 81
  in the benchmark), numbered row-major over ``(u, v)`` so ``Cam040`` is the
  centre of 9x9. Every view is an ``S x T`` image; 8/16-bit files are decoded
  from sRGB to linear (:func:`lfcl.sim.texture.read_linear`).
* a folder of views named by their (row, column) place, 1-based:
  ``NAME_UU_VV.png`` with ``UU, VV = 01 .. n`` (the layout of the decoded Lytro
  Illum captures that EPINET ships, e.g. ``2067_05_05.png`` is the centre of 9x9);
  every other rule as above.
* a ``.npy`` file holding ``[S, T, U, V, 3]`` linear values (any real dtype,
  finite, non-negative after clipping tiny negatives to 0).

``lenses=(S', T')`` crops the centre ``S' x T'`` lenses (from every view);
asking for more lenses than the light field has is an error.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .texture import read_linear

HCI_VIEW = re.compile(r"^input_Cam(\d{3})\.png$", re.IGNORECASE)
GRID_VIEW = re.compile(r"^(.+)_(\d{2})_(\d{2})\.png$", re.IGNORECASE)


def _centre_crop(S, T, lenses, path):
    if lenses is None:
        return slice(0, S), slice(0, T)
    s, t = (int(n) for n in lenses)
    if s > S or t > T:
        raise ValueError(f"--lenses {s}x{t} is larger than the light field {path} ({S}x{T} lenses)")
    s0, t0 = (S - s) // 2, (T - t) // 2
    return slice(s0, s0 + s), slice(t0, t0 + t)


def hci_views(folder: Path) -> list[Path]:
    """The view files of a view folder (either layout), row-major over (u, v); ``ValueError`` if the
    set is incomplete."""
    numbered = {}
    for entry in folder.iterdir():
        m = HCI_VIEW.match(entry.name)
        if m:
            numbered[int(m.group(1))] = entry
    if not numbered:
        return _grid_views(folder)
    n = len(numbered)
    side = round(float(np.sqrt(n)))
    if side * side != n or side < 2:
        raise ValueError(f"light-field folder {folder} holds {n} views, not a square number (e.g. 81 = 9x9)")
    if sorted(numbered) != list(range(n)):
        raise ValueError(f"light-field folder {folder}: views are not numbered input_Cam000..{n - 1:03d}")
    return [numbered[i] for i in range(n)]


def _grid_views(folder: Path) -> list[Path]:
    """The ``NAME_UU_VV.png`` layout (1-based row and column of the view), row-major."""
    placed: dict[str, dict[tuple[int, int], Path]] = {}
    for entry in folder.iterdir():
        m = GRID_VIEW.match(entry.name)
        if m:
            placed.setdefault(m.group(1), {})[int(m.group(2)), int(m.group(3))] = entry
    if not placed:
        raise ValueError(f"light-field folder {folder} holds no input_CamNNN.png or NAME_UU_VV.png views")
    if len(placed) > 1:
        raise ValueError(f"light-field folder {folder} holds views of {len(placed)} captures "
                         f"({', '.join(sorted(placed))}): keep one per folder")
    (name, views), = placed.items()
    side = max(max(place) for place in views)
    wanted = [(u, v) for u in range(1, side + 1) for v in range(1, side + 1)]
    if side < 2 or sorted(views) != wanted:
        raise ValueError(f"light-field folder {folder}: the {name}_UU_VV.png views do not fill a square grid "
                         f"{name}_01_01 .. {name}_{side:02d}_{side:02d}")
    return [views[place] for place in wanted]


def load_hci_folder(folder, lenses=None) -> np.ndarray:
    folder = Path(folder)
    views = hci_views(folder)
    side = round(float(np.sqrt(len(views))))
    out = None
    for k, view_path in enumerate(views):
        view = read_linear(view_path)
        if out is None:
            S, T = view.shape[:2]
            rows, cols = _centre_crop(S, T, lenses, folder)
            out = np.empty((rows.stop - rows.start, cols.stop - cols.start, side, side, 3), dtype=np.float32)
        elif view.shape[:2] != (S, T):
            raise ValueError(f"view {view_path.name} is {view.shape[1]}x{view.shape[0]}, the first view is {T}x{S}")
        out[:, :, k // side, k % side] = view[rows, cols]
    return out


def load_npy(path, lenses=None) -> np.ndarray:
    path = Path(path)
    try:
        data = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise ValueError(f"cannot read light field {path}: {exc}") from None
    if data.ndim != 5 or data.shape[4] != 3 or min(data.shape) < 1:
        raise ValueError(f"light field {path} must have shape [S, T, U, V, 3], got {list(data.shape)}")
    if not (np.issubdtype(data.dtype, np.floating) or np.issubdtype(data.dtype, np.integer)):
        raise ValueError(f"light field {path} has non-numeric dtype {data.dtype}")
    rows, cols = _centre_crop(data.shape[0], data.shape[1], lenses, path)
    out = np.asarray(data[rows, cols], dtype=np.float32)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"light field {path} holds NaN or Inf values")
    return np.ascontiguousarray(np.clip(out, 0.0, None))


def load_lightfield(path, lenses=None) -> np.ndarray:
    """A light field from an HCI-layout folder or a ``.npy``; see the module docstring."""
    path = Path(path)
    if path.is_dir():
        lf = load_hci_folder(path, lenses)
    elif path.is_file() and path.suffix.lower() == ".npy":
        lf = load_npy(path, lenses)
    elif path.exists():
        raise ValueError(f"light field {path} is neither a folder of views nor a .npy file")
    else:
        raise ValueError(f"light field {path} does not exist")
    if lf.shape[2] < 2 or lf.shape[3] < 2:
        raise ValueError(f"light field {path} has {lf.shape[2]}x{lf.shape[3]} views: the pitch must be at least 2")
    return lf
