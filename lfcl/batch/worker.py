"""What runs on a Dask worker for `lfcl batch` (docs/batch.md).

:class:`OpenCLPerWorker` is a ``distributed`` WorkerPlugin: when a worker takes it, it
builds the worker's OpenCL runtime once (``lfcl.device.get_runtime``: context, queue) and
compiles the programs the batch needs by a tiny demosaic, so no task ever builds a context
or compiles; every task then gets the same cached Runtime from ``get_runtime``.
:func:`process_one` is the task: one capture, the same :func:`lfcl.cli.commands.process.run_capture`
as `lfcl process`, into a temporary folder that is renamed into place when complete.
"""

from __future__ import annotations

import asyncio
import importlib
import os
import shutil
import socket
import time
from pathlib import Path

from distributed.diagnostics.plugin import WorkerPlugin

from ..io.images import one_line_error, write_json
from .record import RECORD, decide, make_record, partial_folder, publish

#: Runtimes this process's plugins built (a test reads it through ``client.run``).
BUILT: list = []


def plugin_name(device) -> str:
    return f"lfcl-opencl-{device if device is not None else 'default'}"


class OpenCLPerWorker(WorkerPlugin):
    """Build the OpenCL runtime of ``device`` once per worker, and compile its programs.

    ``pocl_threads``: PoCL's thread count for this worker (``POCL_MAX_PTHREAD_COUNT``, set
    unless the worker's environment sets it already; PoCL reads it when OpenCL starts).
    ``warm``: ``(method, pitch)`` to compile for, or None (the programs are then compiled by
    the worker's first capture, still once per worker).
    """

    idempotent = True  # a second batch on the same cluster keeps the workers' runtimes

    def __init__(self, device=None, pocl_threads: int | None = None, warm: tuple | None = None):
        self.device, self.pocl_threads, self.warm = device, pocl_threads, warm
        self.runtime, self.setup_seconds, self.warm_error = None, None, None

    async def setup(self, worker):
        # off the worker's event loop: compiling takes seconds and the worker must keep talking
        await asyncio.get_running_loop().run_in_executor(None, self._build)

    def _build(self) -> None:
        start = time.perf_counter()
        if self.pocl_threads is not None:
            os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", str(self.pocl_threads))
        from ..device import get_runtime

        self.runtime = get_runtime(self.device)
        BUILT.append(self.runtime)
        try:
            if self.warm is not None:
                _warm_up(self.device, *self.warm)
            importlib.import_module("colour")  # colour-science (previews) imports in ~1 s: not in a capture's time
        except Exception as e:  # the captures will report it, each on its own
            self.warm_error = one_line_error(f"{type(e).__name__}: {e}")
        self.setup_seconds = time.perf_counter() - start


def _warm_up(device, method: str, pitch: int) -> None:
    """A demosaic of 4x4 lenses: compiles every program ``method`` uses at ``pitch``."""
    import numpy as np

    from ..demosaic.driver import demosaic_grid
    from ..grid.model import AlignedGrid

    mosaic = np.random.default_rng(0).uniform(0.2, 0.8, (4 * pitch, 4 * pitch)).astype(np.float32)
    demosaic_grid(mosaic, "GRBG", AlignedGrid((pitch, pitch)), method, lam=0.01, iterations=1, device=device)


def worker_info(dask_worker, device=None) -> dict:
    """This worker's OpenCL state: ``client.run(worker_info)`` asks every worker (and passes ``dask_worker``)."""
    plugin = dask_worker.plugins.get(plugin_name(device))
    runtime = getattr(plugin, "runtime", None)
    return {"pid": os.getpid(), "runtimes_built": len(BUILT), "runtime": None if runtime is None else id(runtime),
            "compute_units": None if runtime is None else runtime.device.max_compute_units,
            "pocl_max_pthread_count": os.environ.get("POCL_MAX_PTHREAD_COUNT"),
            "setup_seconds": getattr(plugin, "setup_seconds", None), "warm_error": getattr(plugin, "warm_error", None)}


def _error_line(exc: BaseException) -> str:
    from ..device import DeviceError

    user = isinstance(exc, (ValueError, OSError, DeviceError, FloatingPointError))
    return one_line_error(str(exc) if user and str(exc) else f"{type(exc).__name__}: {exc}")


def process_one(job: dict) -> dict:
    """One capture: skip, fail or process it into ``job["out_dir"]/job["name"]`` (never raises).

    ``job``: ``name``, ``input`` (absolute path), ``out_dir``, ``settings``
    (ProcessSettings), ``settings_key``, ``identity`` (lfcl.batch.record.settings_identity),
    ``resume``. Returns ``name``, ``input``, ``output``, ``status`` (done, skipped,
    failed), ``reason``, ``error`` (one line or None), ``seconds``, ``host``, ``pid``, and for a
    capture processed ``runtime`` (id of the Runtime it ran on) and ``compute_units`` (its
    device's; PoCL: its thread count).
    """
    start = time.perf_counter()
    out_dir, name, raw = Path(job["out_dir"]), job["name"], job["input"]
    final = out_dir / name
    result = {"name": name, "input": raw, "output": str(final), "status": "failed", "reason": None, "error": None,
              "seconds": 0.0, "host": socket.gethostname(), "pid": os.getpid(), "runtime": None,
              "compute_units": None}
    tmp = None
    try:
        action, reason, input_sha256 = decide(final, raw, job["settings_key"], job["resume"])
        result["reason"] = reason
        if action == "skip":
            result["status"] = "skipped"
        elif action == "fail":
            result["error"] = reason
            result["reason"] = None
        else:
            from ..cli.commands.process import run_capture
            from ..device import get_runtime

            settings = job["settings"]
            tmp = partial_folder(out_dir, name)
            run_capture(settings, raw, tmp)
            write_json(tmp / RECORD, make_record(name, raw, input_sha256, job["settings_key"],
                                                           job["identity"], tmp, time.perf_counter() - start))
            publish(tmp, final)
            tmp = None
            result["status"] = "done"
            runtime = get_runtime(settings.device)  # the worker's cached one: no new context
            result["runtime"], result["compute_units"] = id(runtime), runtime.device.max_compute_units
    except Exception as e:  # a bad capture fails alone; its error is reported
        result["status"], result["error"] = "failed", _error_line(e)
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    result["seconds"] = time.perf_counter() - start
    return result
