"""`lfcl batch` INPUTS -> the captures to process, each with the name of its output folder (docs/batch.md).

An input is a file (taken whatever its extension), a folder (the raw files directly in it:
:data:`CAPTURE_EXTENSIONS`, hidden files left out) or a glob pattern (``*``, ``?``, ``[``;
``**`` recurses; matched files with a capture extension, matched folders as folders).
The same file given twice is one capture. A capture's name is its file stem; captures whose
stems clash are named by as many of their parent folders as it takes to tell them apart
(``a/c0/raw.dng``, ``a/c1/raw.dng`` -> ``c0_raw``, ``c1_raw``), and a clash that no folder
resolves (``x.dng`` and ``x.tif`` in one folder) is an error naming both files.
"""

from __future__ import annotations

import glob
from pathlib import Path
from typing import NamedTuple

from ..io.raw import IMAGE_EXTENSIONS
from .record import LOCK, SUMMARY

#: Camera raw formats LibRaw reads (DNG included), by extension.
RAW_EXTENSIONS = frozenset({
    ".dng", ".3fr", ".ari", ".arw", ".bay", ".cap", ".cr2", ".cr3", ".crw", ".dcr", ".dcs", ".drf", ".eip",
    ".erf", ".fff", ".gpr", ".iiq", ".k25", ".kdc", ".mdc", ".mef", ".mos", ".mrw", ".nef", ".nrw", ".orf",
    ".pef", ".ptx", ".pxn", ".qtk", ".r3d", ".raf", ".raw", ".rw2", ".rwl", ".rwz", ".sr2", ".srf", ".srw", ".x3f",
})
#: What a folder or a glob contributes: camera raws and the mosaic image files lfcl reads.
CAPTURE_EXTENSIONS = RAW_EXTENSIONS | IMAGE_EXTENSIONS
_GLOB_CHARS = frozenset("*?[")


class Capture(NamedTuple):
    name: str  # the output folder's name
    path: str  # absolute path of the raw


def _is_capture(path: Path) -> bool:
    return path.is_file() and not path.name.startswith(".") and path.suffix.lower() in CAPTURE_EXTENSIONS


def _folder(path: Path) -> list[Path]:
    try:
        entries = sorted(path.iterdir())
    except OSError as e:
        raise ValueError(f"cannot list input folder {str(path)!r}: {e.strerror or e}") from None
    return [p for p in entries if _is_capture(p)]


def expand_inputs(inputs, exclude=(), out_dir=None) -> list[Path]:
    """Files, folders and globs -> absolute paths of the captures, in the order given, each once.

    ``exclude``: files never taken from a folder or glob (the calibration or white image); nor is anything
    inside ``out_dir``, the batch's own output folder (a ``**`` glob over a folder that holds it would take
    the batch's outputs as captures on its next run).
    One-line ``ValueError`` for an input that does not exist, a glob or folder without
    captures, or no captures at all.
    """
    skip = {Path(p).resolve() for p in exclude if p is not None}
    outputs = Path(out_dir).resolve() if out_dir is not None else None
    found: list[Path] = []
    for text in map(str, inputs):
        if any(c in text for c in _GLOB_CHARS) and not Path(text).exists():
            matches = [Path(m) for m in sorted(glob.glob(text, recursive=True))]
            paths = [q for m in matches for q in (_folder(m) if m.is_dir() else [m] if _is_capture(m) else [])]
            if not paths:
                raise ValueError(f"input {text!r} matches no capture files ({', '.join(sorted(CAPTURE_EXTENSIONS))})")
        else:
            path = Path(text)
            if not path.exists():
                raise ValueError(f"input {text!r} does not exist")
            if path.is_dir():
                paths = _folder(path)
                if not paths:
                    raise ValueError(f"input folder {text!r} holds no capture files (raw or mosaic images)")
            else:
                found.append(path.resolve())  # a file named explicitly: taken whatever it is
                continue
        found.extend(p.resolve() for p in paths
                     if p.resolve() not in skip and not (outputs and p.resolve().is_relative_to(outputs)))
    unique = list(dict.fromkeys(found))
    if not unique:
        raise ValueError("no captures to process")
    return unique


def capture_names(paths) -> list[Capture]:
    """Name each capture after its file stem; clashing stems get parent folders (module docstring)."""
    paths = [Path(p) for p in paths]
    groups: dict[str, list[int]] = {}
    for i, p in enumerate(paths):
        groups.setdefault(p.stem.casefold(), []).append(i)  # casefold: some file systems ignore case
    names = [p.stem for p in paths]
    for members in groups.values():
        if len(members) == 1:
            continue
        folders = {i: paths[i].parent.relative_to(paths[i].anchor).parts for i in members}
        for k in range(1, max(len(f) for f in folders.values()) + 1):
            keys = ["_".join([*folders[i][-k:], paths[i].stem]) for i in members]
            if len({key.casefold() for key in keys}) == len(keys):
                for i, key in zip(members, keys):
                    names[i] = key
                break
        else:
            a, b = (str(paths[i]) for i in members[:2])
            raise ValueError(f"captures {a!r} and {b!r} would share the output folder {paths[members[0]].stem!r}: "
                             "rename one or run them in separate batches")
    reserved = {SUMMARY.casefold(), LOCK.casefold()}
    for name, path in zip(names, paths):
        if name.casefold() in reserved:
            raise ValueError(f"capture {str(path)!r} would be written to {name!r}, the batch's own file: rename it")
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        j = seen.setdefault(name.casefold(), i)
        if j != i:
            raise ValueError(f"captures {str(paths[j])!r} and {str(paths[i])!r} would share the output folder "
                             f"{name!r}: rename one or run them in separate batches")
    return [Capture(n, str(p)) for n, p in zip(names, paths)]
