"""`lfcl batch`: many captures through the `lfcl process` pipeline on a Dask cluster (docs/batch.md).

INPUTS (files, folders, globs; lfcl/batch/inputs.py) -> one output folder per capture
in OUTDIR, each exactly what `lfcl process` writes with the same options plus the record
``lfcl-batch.json``; captures whose record matches are skipped (lfcl/batch/record.py).
Each capture is one Dask task (lfcl/batch/worker.py) on a local cluster of worker
processes or on ``--scheduler``'s (lfcl/batch/cluster.py). A bad capture fails alone;
the summary lists every capture, and the exit code is 1 when any failed.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import sys
import threading
import time
from pathlib import Path

import click

from ...batch.record import SUMMARY
from . import PROCESS_SECTIONS, SectionedCommand, user_errors
from .process import DEFAULT_PITCH, process_options, settings_from_options

#: Up to this many captures the summary lists each; above, the failed ones only.
LIST_ALL = 20


def _warm(settings):
    """``(method, pitch)`` to compile for on every worker, when the pitch is known before a raw is read."""
    if settings.white is not None:
        return None
    if settings.calibration is not None:
        from ...grid import load_calibration
        from ...grid.aligned import ALIGNED, fit_grid

        cal = load_calibration(settings.calibration)  # a broken file: one error now, not one per capture
        geo = fit_grid(cal, f"calibration {settings.calibration}")
        # a resampled grid's programs are compiled by each worker's first capture
        return (settings.method, geo["pitch"]) if geo["kind"] == ALIGNED else None
    return settings.method, settings.pitch or DEFAULT_PITCH


def _run(cluster, jobs: list, as_json: bool) -> list:
    """Submit every job, collect the results as they finish (a tqdm bar on a terminal)."""
    from distributed import as_completed
    from tqdm import tqdm

    from ...batch.worker import OpenCLPerWorker, plugin_name, process_one

    settings = jobs[0]["settings"]
    client = cluster.client
    plugin = OpenCLPerWorker(settings.device, cluster.pocl_threads, _warm(settings))
    try:
        client.register_plugin(plugin, name=plugin_name(settings.device))
    except Exception as e:  # no OpenCL on a worker, or no lfcl there: no capture could run
        raise ValueError(f"the Dask workers could not set up OpenCL: {type(e).__name__}: {e}") from None
    futures = {client.submit(process_one, job, pure=False): job for job in jobs}
    counts = {"done": 0, "skipped": 0, "failed": 0}
    results = []
    with tqdm(total=len(jobs), unit="capture", desc="batch", disable=True if as_json else None, file=sys.stderr,
              dynamic_ncols=True) as bar:
        for future in as_completed(futures):
            job = futures[future]
            try:
                result = future.result()
            except Exception as e:  # the worker died on it (e.g. KilledWorker): it fails alone
                text = str(e).splitlines()[0] if str(e) else ""
                result = {"name": job["name"], "input": job["input"], "output": str(Path(job["out_dir"]) / job["name"]),
                          "status": "failed", "reason": None, "error": f"{type(e).__name__}: {text}".rstrip(": "),
                          "seconds": 0.0, "host": None, "pid": None, "runtime": None, "compute_units": None}
            counts[result["status"]] += 1
            results.append(result)
            bar.set_postfix(counts, refresh=False)  # before the update, which draws the bar with it
            bar.update(1)
    order = {job["name"]: i for i, job in enumerate(jobs)}
    return sorted(results, key=lambda r: order[r["name"]])


def _silence_cluster_logs() -> None:
    """No more log lines from the client side of the cluster: its shutdown chatter after a Ctrl-C."""
    for name in ("distributed", "tornado", "asyncio"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


@contextlib.contextmanager
def _quiet_interrupts():
    """Ctrl-C while the batch runs: the cluster's logs silenced before the interrupt unwinds. Raised inside
    distributed's ``sync`` (waiting on a result), the interrupt schedules a cancel on the client's event-loop thread,
    which can run and log at once. In distributed 2026.8 that cancel can fail with a NameError when the interrupt lands
    before its future exists. tornado then logged the traceback before this thread reached its ``except``. One CI run
    in many failed on it (tests/test_batch.py, Ctrl-C)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(*_):
        _silence_cluster_logs()
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _need_dask():
    """A one-line error naming the extra when Dask is not installed (it serves `lfcl batch` alone)."""
    import importlib.util

    if importlib.util.find_spec("distributed") is None:
        raise ValueError("lfcl batch runs on Dask, which is not installed: pip install 'lfcl[batch]'")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def summary_text(summary: dict) -> str:
    c, caps = summary["counts"], summary["captures"]
    head = (f"lfcl batch: {_count(len(caps), 'capture')} -> {summary['out_dir']}: {c['done']} done, "
            f"{c['skipped']} skipped, {c['failed']} failed in {summary['seconds']:.1f} s on "
            f"{_count(summary['cluster']['workers'], 'worker')}")
    lines = [head]
    shown = caps if len(caps) <= LIST_ALL else [r for r in caps if r["status"] == "failed"]
    width = max((len(r["name"]) for r in shown), default=0)
    for r in shown:
        tail = r["error"] if r["status"] == "failed" else (r["reason"] or "")
        lines.append(f"  {r['status']:<7} {r['name']:<{width}}  {r['seconds']:6.1f} s  {tail}")
    if len(shown) < len(caps):
        lines.append(f"  ({len(caps) - len(shown)} captures done or skipped not listed: --json or "
                     f"{Path(summary['out_dir']) / SUMMARY})")
    return "\n".join(lines)


@click.command("batch", cls=SectionedCommand, sections={**PROCESS_SECTIONS, "Batch": ("inputs", "scheduler", "workers", "resume")})
@click.argument("inputs", nargs=-1, required=True)
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: one folder per capture, named after it (created if missing).")
@process_options
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="An existing Dask cluster's scheduler (tcp://host:8786). Default: a local cluster.")
@click.option("--workers", default=None, type=click.IntRange(min=1),
              help="Worker processes of the local cluster; default one per core (at most RAM / 4 GiB).")
@click.option("--resume", is_flag=True,
              help="Finish an interrupted batch: take over its lock, keep its complete captures without "
                   "re-reading their raws, redo the rest (docs/batch.md).")
@click.option("--json", "as_json", is_flag=True, help="Print the batch summary as JSON (no progress bar).")
@user_errors
def command(inputs, out_dir, scheduler, workers, resume, as_json, **options):
    """Process many lenslet raws (files, folders, globs) like `lfcl process`, on Dask; resumable."""
    _need_dask()
    from ...batch.inputs import capture_names, expand_inputs

    if scheduler is not None and workers is not None:
        raise ValueError("--workers sizes the local cluster; with --scheduler the cluster has its own workers")
    for key in ("calibration", "white"):  # the workers may run elsewhere: absolute paths
        if options[key] is not None:
            options[key] = Path(options[key]).resolve()
    settings = settings_from_options(options)
    out_dir = out_dir.resolve()
    captures = capture_names(expand_inputs(inputs, exclude=(settings.calibration, settings.white), out_dir=out_dir))
    if scheduler is None and settings.device is not None:  # local workers see this machine's devices
        from ...device import select_device

        select_device(settings.device)
    made = [p for p in (out_dir, *out_dir.parents) if not p.exists()]  # innermost first
    out_dir.mkdir(parents=True, exist_ok=True)
    try:
        results, cluster, lock, start, leftovers, key, identity = _batch(out_dir, captures, settings, scheduler,
                                                                         workers, resume, as_json)
    except BaseException:
        for folder in made:  # a batch that failed before it wrote anything leaves no empty OUTDIR behind
            with contextlib.suppress(OSError):
                folder.rmdir()
        raise
    counts = {s: sum(r["status"] == s for r in results) for s in ("done", "skipped", "failed")}
    summary = {"out_dir": str(out_dir), "counts": counts, "seconds": time.perf_counter() - start,
               "cluster": {"scheduler": scheduler, "workers": cluster.workers, "pocl_threads": cluster.pocl_threads,
                           "dashboard": cluster.dashboard},
               "resume": resume, "took_over_lock": lock.took_over, "leftovers_removed": leftovers,
               "settings_key": key, "settings": identity, "captures": results}
    from ...io.images import to_json, write_json

    write_json(out_dir / SUMMARY, summary)
    click.echo(to_json(summary, indent=2) if as_json else summary_text(summary))
    if counts["failed"]:
        sys.exit(1)


def _batch(out_dir, captures, settings, scheduler, workers, resume, as_json):
    """The batch proper, under OUTDIR's lock: the captures on the cluster; their results and the run's record."""
    from ...batch.cluster import open_cluster
    from ...batch.record import BatchLock, digest, remove_leftovers, settings_identity

    start = time.perf_counter()
    lock = BatchLock(out_dir, resume)
    release = True
    try:
        leftovers = remove_leftovers(out_dir)
        # the last run's summary no longer describes OUTDIR once this run changes it: only a finished run writes one
        (out_dir / SUMMARY).unlink(missing_ok=True)
        identity = settings_identity(settings)
        key = digest(identity)
        jobs = [{"name": c.name, "input": c.path, "out_dir": str(out_dir), "settings": settings, "settings_key": key,
                 "identity": identity, "resume": resume} for c in captures]
        cluster = open_cluster(scheduler, workers)
        try:
            where = scheduler or (f"a local cluster of {cluster.workers} worker process"
                                  f"{'' if cluster.workers == 1 else 'es'}, POCL_MAX_PTHREAD_COUNT={cluster.pocl_threads}")
            click.echo(f"lfcl batch: {_count(len(jobs), 'capture')} on {where}", err=True)
            if cluster.dashboard:
                click.echo(f"dashboard: {cluster.dashboard}", err=True)
            with _quiet_interrupts():
                results = _run(cluster, jobs, as_json)
        except KeyboardInterrupt:
            release = scheduler is None  # a remote cluster may still run tasks: leave the lock (--resume)
            _silence_cluster_logs()
            raise
        finally:
            cluster.close()
    finally:
        if release:
            lock.release()
    return results, cluster, lock, start, leftovers, key, identity
