"""The Dask cluster `lfcl batch` runs on: a local one sized to this machine, or an existing one
(docs/batch.md, "Running on a cluster").

Local: worker processes (not threads: each worker holds its own OpenCL context, and the
numpy/LibRaw parts of a capture hold the GIL), one task at a time per worker, and PoCL
(whose CPU device otherwise starts a thread per core in every process) limited to
``cores // workers`` threads per worker, so that workers x threads ~ cores.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
from typing import NamedTuple

#: Memory a local worker is given room for (the default worker count keeps to RAM / this).
WORKER_MEMORY = 4 * 2**30


class Cluster(NamedTuple):
    client: object  # distributed.Client
    local: object  # distributed.LocalCluster, or None with --scheduler
    workers: int  # worker count when the batch started
    pocl_threads: int | None  # POCL_MAX_PTHREAD_COUNT given to local workers (None: the workers' own)
    dashboard: str | None  # the Dask dashboard's address, when the scheduler serves one

    def close(self) -> None:
        """Close the client and the local cluster. A Ctrl-C meanwhile is held until both are closed, then raised: an
        interrupted close left the cluster to distributed's exit handler, which took 10 s to give up on it (a Ctrl-C
        as the last captures finished, measured)."""
        held = []
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, lambda *_: held.append(True)) if main_thread else None
        try:
            self.client.close()
            if self.local is not None:
                self.local.close()
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, previous)
        if held:
            raise KeyboardInterrupt


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def local_size(workers: int | None) -> tuple[int, int]:
    """``(workers, PoCL threads per worker)``: default one worker per core, at most RAM / 4 GiB."""
    import psutil

    cores = usable_cores()
    if workers is None:
        workers = max(1, min(cores, psutil.virtual_memory().total // WORKER_MEMORY))
    return workers, max(1, cores // workers)


def open_cluster(scheduler: str | None, workers: int | None) -> Cluster:
    """Connect to ``scheduler`` (``tcp://host:8786``), or start a local cluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as e:
            raise ValueError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
        pocl_threads = None
        local = None
    else:
        workers, pocl_threads = local_size(workers)
        # The worker processes start with SIGINT ignored (Python keeps an inherited SIG_IGN): Ctrl-C in a terminal
        # reaches the whole process group, and the workers would each print a KeyboardInterrupt traceback; this
        # process takes it alone and closes the cluster, which ends them
        main_thread = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main_thread else None
        try:
            local = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                 dashboard_address=":0", silence_logs=logging.ERROR)
        finally:
            if main_thread:
                signal.signal(signal.SIGINT, previous)
        client = Client(local)
    return Cluster(client, local, len(client.nthreads()), pocl_threads, _dashboard(client))


def _dashboard(client) -> str | None:
    """The dashboard's address if it serves one (without bokeh it answers "Dask needs bokeh" only)."""
    import urllib.request

    if "dashboard" not in client.scheduler_info(n_workers=0).get("services", {}):
        return None
    link = client.dashboard_link
    try:
        with urllib.request.urlopen(link, timeout=2) as response:
            return link if response.status == 200 and b"needs bokeh" not in response.read(4096) else None
    except (OSError, ValueError):
        return None
