"""`lfcl batch` on Dask (docs/batch.md): a 2-worker local cluster, a corrupt capture, one OpenCL
runtime per worker, byte equality with `lfcl process`, skips, redos, an interruption and a resume."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from lfcl.batch.inputs import capture_names, expand_inputs
from lfcl.batch.record import LOCK, RECORD, BatchLock
from lfcl.cli import cli

GOOD = [f"cap{i}" for i in range(5)]
FAST = ["--method", "admm-uv", "--iterations", "3"]  # the same options in every batch below compared with another run
PROCESS_FILES = {"center.exr", "center.png", "mean.exr", "mean.png", "lightfield.npy", "summary.json"}


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """Five simulated captures of 16x16 lenses (pitch 9) and a corrupt one, in one folder."""
    from lfcl.sim import simulate, write_capture

    root = tmp_path_factory.mktemp("batch")
    folder = root / "caps"
    folder.mkdir()
    for i, name in enumerate(GOOD):
        capture = write_capture(simulate("deadleaves", lenses=(16, 16), lux=4, seed=i), root / f"sim{i}")
        shutil.copy(capture / "raw.dng", folder / f"{name}.dng")
    (folder / "bad.dng").write_bytes(b"II*\x00 not really a raw " * 40)
    return folder


@pytest.fixture(scope="module")
def cluster():
    """A local Dask cluster of 2 worker processes, shared by the batches that pass --scheduler."""
    from distributed import Client, LocalCluster

    local = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address=":0")
    client = Client(local)
    yield client
    client.close()
    local.close()


def batch(*args):
    return CliRunner().invoke(cli, ["batch", *map(str, args)])


@pytest.fixture(scope="module")
def first_batch(captures, cluster, tmp_path_factory):
    out = tmp_path_factory.mktemp("first") / "out"
    result = batch(captures, "-o", out, "--scheduler", cluster.scheduler.address, *FAST, "--json")
    return out, result


def by_name(summary: dict) -> dict:
    return {r["name"]: r for r in summary["captures"]}


def test_a_corrupt_capture_fails_alone(first_batch):
    out, result = first_batch
    assert result.exit_code == 1, result.output  # something failed
    summary = json.loads(result.stdout)
    results = by_name(summary)
    assert summary["counts"] == {"done": 5, "skipped": 0, "failed": 1}
    assert results["bad"]["status"] == "failed" and "bad.dng" in results["bad"]["error"]
    assert "\n" not in results["bad"]["error"]
    for name in GOOD:
        assert results[name]["status"] == "done" and results[name]["error"] is None
        assert {p.name for p in (out / name).iterdir()} == PROCESS_FILES | {RECORD}
    assert sorted(p.name for p in out.iterdir()) == sorted([*GOOD, "lfcl-batch-summary.json"])  # no lock, no temp
    assert json.loads((out / "lfcl-batch-summary.json").read_text()) == summary


def test_one_opencl_runtime_per_worker(first_batch, cluster):
    from lfcl.batch.worker import worker_info

    _, result = first_batch
    info = {w["pid"]: w for w in cluster.run(worker_info).values()}
    assert len(info) == 2
    for pid, w in info.items():
        assert w["runtimes_built"] == 1 and w["warm_error"] is None, w
        ran_here = {r["runtime"] for r in json.loads(result.stdout)["captures"] if r["pid"] == pid and r["runtime"]}
        assert ran_here <= {w["runtime"]}, (pid, ran_here, w)  # every capture ran on the plugin's runtime


def test_outputs_equal_lfcl_process_byte_for_byte(first_batch, captures, tmp_path):
    out, _ = first_batch
    ref = tmp_path / "process"
    result = CliRunner().invoke(cli, ["process", str((captures / "cap1.dng").resolve()), "-o", str(ref), *FAST])
    assert result.exit_code == 0, result.output
    assert {p.name for p in ref.iterdir()} == PROCESS_FILES
    for name in PROCESS_FILES - {"summary.json"}:
        assert (ref / name).read_bytes() == (out / "cap1" / name).read_bytes(), name
    ours, theirs = (json.loads((d / "summary.json").read_text()) for d in (out / "cap1", ref))
    for summary in (ours, theirs):
        assert summary.pop("seconds") and summary.pop("output_seconds")
    assert ours == theirs


def test_unchanged_captures_are_skipped_and_changed_options_redone(first_batch, captures, cluster):
    out, _ = first_batch
    lightfield = out / "cap0" / "lightfield.npy"
    before = (lightfield.stat().st_ino, lightfield.stat().st_mtime_ns, lightfield.read_bytes())
    address = cluster.scheduler.address
    result = batch(captures, "-o", out, "--scheduler", address, *FAST, "--json")
    assert result.exit_code == 1, result.output
    results = by_name(json.loads(result.stdout))
    assert all(results[n]["status"] == "skipped" and results[n]["reason"] == "unchanged" for n in GOOD)
    assert (lightfield.stat().st_ino, lightfield.stat().st_mtime_ns) == before[:2]

    (out / "cap0" / "center.exr.xmp").write_text("an editor's sidecar")  # not lfcl's: a redo keeps it
    result = batch(captures / "cap0.dng", "-o", out, "--scheduler", address, *FAST, "--strength", "3", "--json")
    assert result.exit_code == 0, result.output
    (changed,) = json.loads(result.stdout)["captures"]
    assert changed["status"] == "done" and changed["reason"] == "redone: options changed"
    assert lightfield.read_bytes() != before[2]
    assert (out / "cap0" / "center.exr.xmp").read_text() == "an editor's sidecar"
    assert "center.exr.xmp" not in json.loads((out / "cap0" / RECORD).read_text())["files"]
    assert json.loads((out / "cap0" / "summary.json").read_text())["options"]["strength"] == 3.0
    # --resume trusts complete outputs, but not ones made with other options
    result = batch(captures / "cap0.dng", "-o", out, "--scheduler", address, *FAST, "--resume", "--json")
    assert result.exit_code == 1
    (refused,) = json.loads(result.stdout)["captures"]
    assert refused["status"] == "failed" and "other options" in refused["error"]


def _complete(out: Path) -> list:
    """The capture folders published (the hidden temporary ones hold a record just before their rename)."""
    if not out.exists():
        return []
    return sorted(p.name for p in out.iterdir() if not p.name.startswith(".") and (p / RECORD).is_file())


def _group_gone(pgid: int, seconds: float = 20) -> bool:
    """Killed processes linger until reaped (orphans: by init): wait for the whole group to go."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


def test_an_interrupted_batch_resumes(captures, tmp_path):
    out = tmp_path / "out"
    slow = ["--iterations", "200"]  # long enough that the batch is still busy when the first capture is done
    code = "import sys; from lfcl.cli import main; sys.argv[0] = 'lfcl'; main()"
    # cwd: with `-c`, Python puts the working directory first on sys.path, which in a checkout would
    # import the source tree instead of the installed lfcl
    proc = subprocess.Popen([sys.executable, "-c", code, "batch", str(captures), "-o", str(out), "--workers", "2",
                             *slow], start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not _complete(out) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:  # the batch, its nanny and worker processes: all in the session it started
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert _group_gone(proc.pid), "processes of the killed batch are still alive"
    finished = _complete(out)
    assert 1 <= len(finished) < len(GOOD), f"the interruption came too late to test a resume: {finished}"
    assert (out / LOCK).is_file()

    result = batch(captures, "-o", out, "--workers", "2", *slow)
    assert result.exit_code == 1 and "--resume" in result.output and "interrupted" in result.output
    assert _complete(out) == finished

    result = batch(captures, "-o", out, "--workers", "2", *slow, "--resume", "--json")
    assert result.exit_code == 1, result.output  # bad.dng
    summary = json.loads(result.stdout)
    results = by_name(summary)
    assert summary["took_over_lock"]["pid"] == proc.pid
    for name in GOOD:
        expected = "skipped" if name in finished else "done"
        assert results[name]["status"] == expected, results[name]
    # PoCL's threads: the cores shared between the two local workers
    from lfcl.batch.cluster import local_size

    threads = local_size(2)[1]
    assert summary["cluster"]["pocl_threads"] == threads
    assert {r["compute_units"] for r in summary["captures"] if r["status"] == "done"} == {threads}
    assert sorted(p.name for p in out.iterdir()) == sorted([*GOOD, "lfcl-batch-summary.json"])


def test_ctrl_c_stops_a_local_batch_quietly(captures, tmp_path):
    """SIGINT to the batch's whole process group, as a terminal's Ctrl-C sends it: the batch stops with the lock
    released, no summary of an earlier run left describing the folder, and no worker's traceback on stderr."""
    # twelve good captures on two workers, each solved with admm-uvst for 300 iterations: the batch runs about 4 s
    # after the first is published, time for the interrupt to land in on a loaded machine (with auto, which runs
    # Malvar on frames this small, the rest took 0.5 s, and under a full CI run the batch finished first)
    many = tmp_path / "many"
    many.mkdir()
    for i in range(12):
        shutil.copy(captures / f"{GOOD[i % len(GOOD)]}.dng", many / f"c{i:02d}.dng")
    out = tmp_path / "out"
    out.mkdir()
    (out / "lfcl-batch-summary.json").write_text("{}")  # an earlier run's
    code = "import sys; from lfcl.cli import main; sys.argv[0] = 'lfcl'; main()"
    # SIGINT's default in the child, as a terminal's foreground job has it: a test run started in the background
    # (`cmd &` in a script) inherits SIGINT ignored, and Python keeps an inherited SIG_IGN, so the batch would
    # never see the interrupt (two CI runs started so failed here)
    proc = subprocess.Popen([sys.executable, "-c", code, "batch", str(many), "-o", str(out), "--workers", "2",
                             "--method", "admm-uvst", "--iterations", "300"], start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 120
        while not _complete(out) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode != 0  # every capture is good: a batch that finished would exit 0
    assert len(_complete(out)) < 12
    assert _group_gone(proc.pid), "processes of the interrupted batch are still alive"
    assert "Traceback" not in stderr.decode(), stderr.decode()[-2000:]
    assert not (out / LOCK).exists() and not (out / "lfcl-batch-summary.json").exists()


def test_inputs_and_names(tmp_path):
    for sub in ("a/c0", "a/c1", "b"):
        (tmp_path / sub).mkdir(parents=True)
    for rel in ("a/c0/raw.dng", "a/c1/raw.dng", "b/x.dng", "b/x.tif", "b/white.dng", "b/notes.txt", "b/.hidden.dng"):
        (tmp_path / rel).write_bytes(b"x")
    names = capture_names(expand_inputs([tmp_path / "a/*/raw.dng"]))
    assert [c.name for c in names] == ["c0_raw", "c1_raw"]
    found = expand_inputs([tmp_path / "b"], exclude=[tmp_path / "b/white.dng"])
    assert [p.name for p in found] == ["x.dng", "x.tif"]  # captures only: not the white image, notes, hidden
    with pytest.raises(ValueError, match="share the output folder 'x'"):
        capture_names(found)
    assert [c.name for c in capture_names(expand_inputs([tmp_path / "b/x.dng", tmp_path / "b/x.dng"]))] == ["x"]
    with pytest.raises(ValueError, match="does not exist"):
        expand_inputs([tmp_path / "nope.dng"])
    with pytest.raises(ValueError, match="matches no capture"):
        expand_inputs([tmp_path / "*.cr2"])
    # a ** glob over a folder that holds the batch's own output folder: nothing of the outputs is a capture
    (tmp_path / "b/out/x").mkdir(parents=True)
    (tmp_path / "b/out/x/center.tif").write_bytes(b"x")
    found = expand_inputs([tmp_path / "b/**"], exclude=[tmp_path / "b/white.dng"], out_dir=tmp_path / "b/out")
    assert [p.name for p in found] == ["x.dng", "x.tif"]
    (tmp_path / "b/QT100.QTK").write_bytes(b"x")  # QuickTake: LibRaw reads it
    assert "QT100.QTK" in [p.name for p in expand_inputs([tmp_path / "b"])]
    for name in ("lfcl-batch-summary.json.dng", ".lfcl-batch.lock.dng"):  # OUTDIR's own files
        with pytest.raises(ValueError, match="the batch's own file: rename it"):
            capture_names([tmp_path / name])


def test_bad_options_fail_before_any_work(captures, tmp_path):
    out = tmp_path / "out"
    for args, message in ((["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers sizes"),
                          (["--outputs", "center,nope"], "unknown outputs nope"),
                          (["--pitch", "9", "--white", captures / "cap0.dng"], "give the lens grid once"),
                          (["--device", "99"], "device index 99 does not exist")):
        result = batch(captures, "-o", out, *args)
        assert result.exit_code == 1 and message in result.output, result.output
        assert len(result.output.strip().splitlines()) == 1 and not out.exists()


def test_a_batch_that_cannot_reach_its_scheduler_leaves_no_outdir(captures, tmp_path):
    out = tmp_path / "new" / "out"
    result = batch(captures, "-o", out, "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 1 and "cannot reach the Dask scheduler" in result.output
    assert not (tmp_path / "new").exists()


def test_temporary_folders_of_long_names_fit_a_file_system(tmp_path):
    """A capture name of up to 255 bytes works in lfcl process; its batch's hidden folders must fit too."""
    from lfcl.batch.record import partial_folder, publish, remove_leftovers

    for name in ("a" * 250, "é" * 127, "x"):
        tmp = partial_folder(tmp_path, name)
        assert len(tmp.name.encode()) <= 255 and ".lfcl-partial-" in tmp.name
        tmp.mkdir()
        (tmp / "f").write_text("new")
        final = tmp_path / name
        final.mkdir(exist_ok=True)
        publish(tmp, final)  # through the hidden .lfcl-old- folder
        assert (final / "f").read_text() == "new"
    assert remove_leftovers(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["a" * 250, "é" * 127, "x"])


def test_a_stale_lock_needs_resume(tmp_path):
    dead = subprocess.Popen(["true"])
    dead.wait()
    (tmp_path / LOCK).write_text(json.dumps({"host": socket.gethostname(), "pid": dead.pid, "started": "then"}))
    with pytest.raises(ValueError, match="was interrupted .*add --resume"):
        BatchLock(tmp_path, resume=False)
    lock = BatchLock(tmp_path, resume=True)
    assert lock.took_over["pid"] == dead.pid and json.loads((tmp_path / LOCK).read_text())["pid"] == os.getpid()
    lock.release()
    assert not (tmp_path / LOCK).exists()


def test_batch_without_dask_names_the_extra(tmp_path, monkeypatch):
    import importlib.util

    real_find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == "distributed" else real_find_spec(name, *a))
    from click.testing import CliRunner

    from lfcl.cli import cli

    result = CliRunner().invoke(cli, ["batch", str(tmp_path), "-o", str(tmp_path / "out")])
    assert result.exit_code == 1
    assert result.output.strip() == "lfcl: error: lfcl batch runs on Dask, which is not installed: pip install 'lfcl[batch]'"
    assert not (tmp_path / "out").exists()


def test_a_ctrl_c_while_the_cluster_closes_waits_for_the_close_then_raises():
    """Both closes run to their end before the KeyboardInterrupt: an interrupted close left the local cluster to
    distributed's exit handler, and a Ctrl-C as the last captures finished took 10 s to end the batch."""
    from lfcl.batch.cluster import Cluster

    closed = []

    class Part:
        def __init__(self, name, interrupt=False):
            self.name, self.interrupt = name, interrupt

        def close(self):
            if self.interrupt:
                os.kill(os.getpid(), signal.SIGINT)  # delivered here, in the main thread, before close returns
                time.sleep(0.05)
            closed.append(self.name)

    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        Cluster(Part("client", interrupt=True), Part("local"), 1, None, None).close()
    assert closed == ["client", "local"]
    assert signal.getsignal(signal.SIGINT) is before
    Cluster(Part("client"), None, 1, None, None).close()  # without a Ctrl-C: nothing raised
    assert closed == ["client", "local", "client"]
