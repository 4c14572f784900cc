"""What makes `lfcl batch` resumable: content keys, the record beside each capture's outputs,
the decision to skip or redo, the output folder's lock, and publishing a folder atomically
(docs/batch.md, "Resuming").

A capture's **key** is a SHA-256 over the raw's bytes and the batch's **settings key**: the
resolved options (:class:`lfcl.cli.commands.process.ProcessSettings` without ``device``), the
bytes of the calibration / white image / recipe file when given, and the lfcl version. File
paths are not part of it: moving the inputs does not redo them. Each finished capture
folder holds :data:`RECORD` with both keys and the size of every file it wrote.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import hashlib
import json
import os
import shutil
import socket
import uuid
from pathlib import Path

RECORD = "lfcl-batch.json"
LOCK = ".lfcl-batch.lock"
#: The batch's summary in OUTDIR (lfcl/cli/commands/batch.py); no capture may take its name, nor LOCK's.
SUMMARY = "lfcl-batch-summary.json"
#: Temporary folders beside the captures' folders: one being written, one being replaced.
PARTIAL, OLD = "lfcl-partial", "lfcl-old"


def file_sha256(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def settings_identity(settings) -> dict:
    """What the outputs of these settings depend on, as JSON-friendly values (module docstring)."""
    from .. import __version__

    values = dataclasses.asdict(settings)
    values.pop("device")  # where it runs, not what it computes
    for name in ("calibration", "white"):
        if values[name] is not None:
            values[name] = {"sha256": file_sha256(values[name])}
    recipe = values.get("recipe")
    if recipe is not None:
        path = recipe.get("path")
        values["recipe"] = {k: v for k, v in recipe.items() if k != "path"}
        values["recipe"]["sha256"] = file_sha256(path) if path and Path(path).is_file() else None
    values["outputs"] = list(values["outputs"])
    return {"lfcl": __version__, "settings": values}


def digest(value) -> str:
    return hashlib.sha256(json.dumps(value, sort_keys=True).encode()).hexdigest()


def capture_key(settings_key: str, input_sha256: str) -> str:
    return hashlib.sha256(f"{settings_key}:{input_sha256}".encode()).hexdigest()


def make_record(name: str, raw: str, input_sha256: str, settings_key: str, identity: dict, folder: Path,
                seconds: float) -> dict:
    files = {p.name: p.stat().st_size for p in sorted(folder.iterdir()) if p.name != RECORD}
    return {"lfcl_batch_record": 1, "name": name, "input": raw, "input_sha256": input_sha256,
            "settings_key": settings_key, "key": capture_key(settings_key, input_sha256),
            "lfcl_version": identity["lfcl"], "settings": identity["settings"], "files": files,
            "seconds": seconds, "finished": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}


def folder_state(folder: Path):
    """``(state, record)``: ``missing``, ``foreign`` (exists, not written by lfcl batch), ``incomplete``
    (a record, but a file it lists is gone or changed size) or ``complete``."""
    if not folder.exists():
        return "missing", None
    record_path = folder / RECORD
    if not record_path.is_file():
        return "foreign", None
    try:
        record = json.loads(record_path.read_text())
        files = record["files"]
        complete = all((folder / n).is_file() and (folder / n).stat().st_size == size for n, size in files.items())
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return "incomplete", None
    return ("complete" if complete else "incomplete"), record


def decide(folder: Path, raw: str, settings_key: str, resume: bool):
    """``(action, reason, input_sha256)``: action ``skip``, ``run`` or ``fail`` (docs/batch.md, "Resuming").

    Without ``resume`` a complete output is kept only if its key matches (the raw is read
    and hashed); with ``resume`` a complete output made with the same settings is kept
    without reading the raw again, and one made with other settings is refused.
    """
    state, record = folder_state(folder)
    if state == "foreign":
        return "fail", f"{folder} exists and was not written by lfcl batch (no {RECORD}): remove it", None
    if state == "complete" and resume:
        if record.get("settings_key") == settings_key:
            return "skip", "complete (--resume: input not re-read)", record.get("input_sha256")
        why = f"{folder} was made with other options or another lfcl version: run without --resume to redo it"
        return "fail", why, None
    input_sha256 = file_sha256(raw)
    if state == "missing":
        return "run", "new", input_sha256
    if state == "incomplete":
        return "run", "incomplete output redone", input_sha256
    if record.get("key") == capture_key(settings_key, input_sha256):
        return "skip", "unchanged", input_sha256
    if record.get("settings_key") == settings_key:
        why = "the raw changed"
    elif record.get("lfcl_version") != _version():
        why = f"lfcl {record.get('lfcl_version')} -> {_version()}"
    else:
        why = "options changed"
    return "run", f"redone: {why}", input_sha256


def _version() -> str:
    from .. import __version__

    return __version__


def _temporary_name(name: str, kind: str) -> str:
    """``.NAME.KIND-XXXXXXXXXXXX``, NAME cut (at a character) so the whole stays within a file system's 255 bytes:
    a capture whose own name fits must not fail for its temporary folder's."""
    tail = f".{kind}-{uuid.uuid4().hex[:12]}"
    room = 255 - 1 - len(tail)
    short = name.encode("utf-8", "surrogateescape")[:room].decode("utf-8", "ignore")
    return f".{short}{tail}"


def partial_folder(out_dir: Path, name: str) -> Path:
    return out_dir / _temporary_name(name, PARTIAL)


def publish(tmp: Path, final: Path) -> None:
    """Move the finished folder ``tmp`` to ``final``; an existing ``final`` is replaced.

    Two renames (a folder cannot be renamed onto a non-empty one): ``final`` aside, then
    ``tmp`` in. Interrupted between them, ``final`` is missing and the next run redoes it.
    The files of ``final`` that its record does not list (an editor's sidecars, a user's notes)
    move into the new folder first: a redo replaces what lfcl batch wrote, nothing else.
    """
    if final.exists():
        _carry_others(final, tmp)
        old = final.parent / _temporary_name(final.name, OLD)
        os.rename(final, old)
        os.rename(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.rename(tmp, final)


def _carry_others(final: Path, tmp: Path) -> None:
    """Move into ``tmp`` every entry of ``final`` that ``final``'s record does not list; a one-line ``ValueError``,
    before anything moves, if the new output has one of their names. Without a readable record nothing is
    known to be another's, so nothing moves (such a folder is lfcl's, incomplete: folder_state)."""
    try:
        ours = set(json.loads((final / RECORD).read_text())["files"]) | {RECORD}
    except (OSError, ValueError, KeyError, TypeError):
        return
    others = [p for p in sorted(final.iterdir()) if p.name not in ours]
    for p in others:
        if (tmp / p.name).exists() or (tmp / p.name).is_symlink():
            raise ValueError(f"{p} was not written by lfcl batch, and the new output writes a file of that name: "
                             "move it away")
    for p in others:
        os.rename(p, tmp / p.name)


def remove_leftovers(out_dir: Path) -> list[str]:
    """Remove the temporary folders an interrupted batch left in ``out_dir`` (call with the lock held)."""
    removed = []
    for p in out_dir.iterdir():
        if p.name.startswith(".") and (f".{PARTIAL}-" in p.name or f".{OLD}-" in p.name) and p.is_dir():
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p.name)
    return removed


def _alive(pid: int) -> bool:
    """Is ``pid`` a running lfcl batch on this host (a reused pid of another program is not)?"""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        return b"batch" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return True  # no /proc: assume it runs


class BatchLock:
    """``out_dir/.lfcl-batch.lock`` while a batch writes there: one batch per output folder.

    A lock left by a batch that died (killed, power loss) marks an interrupted batch: a plain
    run refuses it (it cannot tell a dead batch on another host from a live one) and
    ``--resume`` takes it over.
    """

    def __init__(self, out_dir: Path, resume: bool):
        self.path = Path(out_dir) / LOCK
        self.took_over = None
        me = {"host": socket.gethostname(), "pid": os.getpid(),
              "started": datetime.datetime.now().isoformat(timespec="seconds")}
        text = json.dumps(me)
        try:
            fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            self._take_over(resume, text)
        else:
            with os.fdopen(fd, "w") as f:
                f.write(text)

    def _take_over(self, resume: bool, text: str) -> None:
        try:
            other = json.loads(self.path.read_text())
            host, pid, started = other["host"], int(other["pid"]), other.get("started", "?")
        except (OSError, ValueError, KeyError, TypeError):
            host, pid, started = "?", -1, "?"
        here = host == socket.gethostname()
        where = self.path.parent
        if here and pid > 0 and _alive(pid):
            raise ValueError(f"another lfcl batch (pid {pid}, started {started}) is writing into {where}: "
                             "wait for it, or choose another -o")
        if not resume:
            state = "was interrupted" if here else f"runs on {host} or was interrupted"
            raise ValueError(f"{where} holds the lock of a batch that {state} (pid {pid}, started {started}): "
                             f"add --resume to finish it{'' if here else ' once it no longer runs'}")
        tmp = self.path.with_name(f"{LOCK}.{os.getpid()}")
        tmp.write_text(text)
        os.replace(tmp, self.path)
        self.took_over = {"host": host, "pid": pid, "started": started}

    def release(self) -> None:
        with contextlib.suppress(FileNotFoundError):
            self.path.unlink()
