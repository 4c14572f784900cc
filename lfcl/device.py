"""The one place that finds OpenCL devices, builds programs and caches kernels.

Nothing else in lfcl creates contexts or queues. A :class:`Runtime` wraps one
device: its context, one in-order queue, the programs built from ``lfcl/kernels/*.cl``
(each built once per context) and the kernel objects fetched from them (each
fetched once).

Device choice, in order: an explicit ``spec`` argument (the CLI's ``--device``),
the ``LFCL_DEVICE`` environment variable, then the first GPU found, then the first device
(:func:`default_device`). A spec is an index into :func:`list_devices`, a type (``gpu``,
``cpu``, ``accelerator``: the first device of it), or a case-insensitive substring of the
device or platform name.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.resources
import os
import re
import sys
import tempfile
import threading
import warnings

import numpy as np
import pyopencl as cl

INSTALL_HINT = (
    "No OpenCL platform was found. lfcl needs an OpenCL runtime: on Debian/Ubuntu "
    "install the CPU runtime with `sudo apt-get install pocl-opencl-icd` (or your GPU "
    "vendor's OpenCL ICD), then check with `lfcl devices`."
)

# Every program is prefixed with common.cl (Bayer colour lookup, index helpers).
_COMMON_SOURCE = "common"


def memory_text(size: float) -> str:
    """A memory size for messages: GiB from 1 GiB up, else MiB (0.0 GiB would tell a user nothing)."""
    return f"{size / 2**30:.1f} GiB" if size >= 2**30 else f"{size / 2**20:.1f} MiB"


class DeviceError(RuntimeError):
    """No usable OpenCL device, or the requested one does not exist."""


@dataclasses.dataclass(frozen=True)
class DeviceInfo:
    index: int
    platform: str
    name: str
    type: str
    compute_units: int
    global_mem_mib: int
    max_alloc_mib: int
    max_work_group_size: int
    opencl_version: str

    def describe(self) -> str:
        return (
            f"[{self.index}] {self.name} ({self.type}) on {self.platform}: "
            f"{self.compute_units} compute units, {self.global_mem_mib} MiB global memory, "
            f"{self.max_alloc_mib} MiB max allocation, work-group <= {self.max_work_group_size}, "
            f"{self.opencl_version}"
        )


@functools.cache
def _all_devices() -> tuple[cl.Device, ...]:
    """Every device of every platform, enumerated once per process: a `lfcl process` run selects its device
    several times (the solver, the outputs' metadata, auto's checks), and each enumeration took about 70 ms on an
    H200 machine with two platforms, 10 ms on one PoCL."""
    try:
        platforms = cl.get_platforms()
    except cl.LogicError as exc:  # pyopencl raises this when the ICD loader finds nothing
        raise DeviceError(INSTALL_HINT) from exc
    devices = tuple(d for p in platforms for d in p.get_devices())
    if not devices:
        raise DeviceError(INSTALL_HINT)
    return devices


def list_devices() -> list[DeviceInfo]:
    """Every OpenCL device of every platform, with its key limits."""
    return [
        DeviceInfo(
            index=i,
            platform=d.platform.name.strip(),
            name=d.name.strip(),
            type=cl.device_type.to_string(d.type),
            compute_units=d.max_compute_units,
            global_mem_mib=d.global_mem_size // 2**20,
            max_alloc_mib=d.max_mem_alloc_size // 2**20,
            max_work_group_size=d.max_work_group_size,
            opencl_version=d.version.strip(),
        )
        for i, d in enumerate(_all_devices())
    ]


#: Specs that choose a device by its OpenCL type (the first of that type) rather than by name or index.
DEVICE_KINDS = {"gpu": cl.device_type.GPU, "cpu": cl.device_type.CPU, "accelerator": cl.device_type.ACCELERATOR}


def default_device(devices) -> cl.Device:
    """The device used when none is named: the first GPU, else the first device.

    At 500x500 lenses the default `lfcl process` ran its demosaic stage in 2.9 s on an NVIDIA H200 and in about 70 s on
    2 CPU cores' PoCL (BENCHMARKS.md, "On a GPU"), and the platforms' order is only the ICD loader's: a machine with
    a GPU and a CPU runtime gets the GPU whichever lists first. A GPU smaller than a frame needs does not stop the
    default: admm-epi and the (u, v) methods solve in bands sized to the device's memory.
    """
    return next((d for d in devices if d.type & cl.device_type.GPU), devices[0])


def select_device(spec: str | int | None = None) -> cl.Device:
    """The device named by ``spec`` (or ``LFCL_DEVICE``), else :func:`default_device`."""
    devices = _all_devices()
    if spec is None or spec == "":
        spec = os.environ.get("LFCL_DEVICE", "")
    spec = str(spec).strip()
    if spec == "":
        return default_device(devices)
    if spec.isdigit():
        index = int(spec)
        if index >= len(devices):
            raise DeviceError(
                f"device index {index} does not exist: {len(devices)} device(s) found (see `lfcl devices`)"
            )
        return devices[index]
    kind = DEVICE_KINDS.get(spec.lower())
    if kind is not None:  # `--device cpu` on a machine whose default is its GPU, and the other way round
        of_kind = [d for d in devices if d.type & kind]
        if not of_kind:
            raise DeviceError(f"no OpenCL device of type {spec.upper()} (see `lfcl devices`)")
        return of_kind[0]
    matches = [
        d for d in devices if spec.lower() in d.name.lower() or spec.lower() in d.platform.name.lower()
    ]
    if not matches:
        raise DeviceError(f"no OpenCL device matches {spec!r} (see `lfcl devices`)")
    return matches[0]


def kernel_source(name: str) -> str:
    """The OpenCL C source ``lfcl/kernels/<name>.cl`` from the installed package."""
    return importlib.resources.files("lfcl.kernels").joinpath(f"{name}.cl").read_text()


class Runtime:
    """One device: context, queue, and the programs and kernels built for it."""

    def __init__(self, device: cl.Device):
        self.device = device
        self.context = cl.Context([device])
        self.queue = cl.CommandQueue(self.context)
        self._side_queues: list[cl.CommandQueue] = []
        self._programs: dict[tuple, cl.Program] = {}
        self._kernels: dict[tuple, cl.Kernel] = {}
        self._lock = threading.Lock()

    @property
    def name(self) -> str:
        return self.device.name.strip()

    def side_queues(self, n: int) -> list[cl.CommandQueue]:
        """``n`` more in-order queues on this device (made once), for work that overlaps: transfers on one,
        kernels on another (lfcl.ops.malvar streams a GPU's uploads, filters and downloads so)."""
        with self._lock:
            while len(self._side_queues) < n:
                self._side_queues.append(cl.CommandQueue(self.context, self.device))
            return self._side_queues[:n]

    def program(self, name: str, defines: tuple = ()) -> cl.Program:
        """``lfcl/kernels/<name>.cl`` (after common.cl), built once per set of ``defines``.

        ``defines`` are ``(NAME, value)`` pairs passed as ``-DNAME=value``: sizes the
        compiler should see as constants (the lens pitch).
        """
        key = (name, tuple(defines))
        with self._lock:
            program = self._programs.get(key)
            if program is None:
                source = kernel_source(_COMMON_SOURCE) + "\n" + kernel_source(name)
                options = ["-cl-std=CL1.2", *(f"-D{k}={int(v)}" for k, v in defines)]
                program = build_program(self.context, source, options, f"kernels/{name}.cl")
                self._programs[key] = program
            return program

    def kernel(self, program: str, kernel: str, defines: tuple = ()) -> cl.Kernel:
        """The kernel object ``kernel`` of ``program``, fetched once and reused."""
        key = (program, kernel, tuple(defines))
        cached = self._kernels.get(key)
        if cached is None:
            cached = getattr(self.program(program, defines), kernel)
            self._kernels[key] = cached
        return cached

    def launch(self, program: str, kernel: str, global_size, *args, local_size=None, defines: tuple = ()) -> cl.Event:
        """Enqueue a kernel over ``global_size`` work-items (the kernels bound-check)."""
        return self.kernel(program, kernel, defines)(self.queue, tuple(global_size), local_size, *args)

    def empty(self, shape, dtype=np.float32):
        import pyopencl.array as cla

        return cla.empty(self.queue, shape, dtype)

    def zeros(self, shape, dtype=np.float32):
        import pyopencl.array as cla

        return cla.zeros(self.queue, shape, dtype)

    def through_device(self, source: np.ndarray, shape, launch) -> np.ndarray:
        """A new host float32 array of ``shape`` that ``launch(queue, source_buffer, target_buffer)`` fills from the
        host array ``source``. On a CPU device both buffers lie over the host memory itself, no copies in or out
        (3000x3000 Malvar on PoCL through lfcl.malvar: 216 -> ~120 ms, the copies were ~45 % of it); elsewhere
        the source goes up and the result comes down."""
        flags = cl.mem_flags
        source = np.ascontiguousarray(source, dtype=np.float32)
        out = np.empty(shape, np.float32)
        if not self.device.type & cl.device_type.CPU:
            source_buffer = cl.Buffer(self.context, flags.READ_ONLY | flags.COPY_HOST_PTR, hostbuf=source)
            target = cl.Buffer(self.context, flags.WRITE_ONLY, max(out.nbytes, 1))
            launch(self.queue, source_buffer, target)
            cl.enqueue_copy(self.queue, out, target)  # blocking: waits for the kernel
            return out
        source_buffer = cl.Buffer(self.context, flags.READ_ONLY | flags.USE_HOST_PTR, hostbuf=source)
        target = cl.Buffer(self.context, flags.WRITE_ONLY | flags.USE_HOST_PTR, hostbuf=out)
        launch(self.queue, source_buffer, target)
        mapped, _ = cl.enqueue_map_buffer(self.queue, target, cl.map_flags.READ, 0, out.shape, np.float32)
        mapped.base.release(self.queue)  # the map waits for the kernel and makes its writes visible in ``out``
        return out

    def to_device(self, array: np.ndarray):
        import pyopencl.array as cla

        return cla.to_device(self.queue, np.ascontiguousarray(array))


def verbose() -> bool:
    """Whether ``LFCL_VERBOSE`` is set (``lfcl --verbose`` sets it): then build logs go to stderr."""
    return os.environ.get("LFCL_VERBOSE", "").strip().lower() not in ("", "0", "false", "no", "off")


# What a compiler prints straight to the process's stderr while it builds (PoCL's clang:
# "2 warnings generated."), next to the build log it hands back.
_BUILD_CHATTER = re.compile(r"^\d+ (warning|error)s? generated\.$")


def _build_failure(context: cl.Context, what: str, log: str) -> str:
    """One line for a build the device's compiler refused: the device, the compiler's first error, the way out."""
    lines = [line.strip() for line in log.splitlines() if line.strip()]
    first = next((line for line in lines if "error" in line.lower() and "clBuildProgram" not in line),
                 lines[0] if lines else "no build log")
    devices = ", ".join(f"{d.name.strip()} on {d.platform.name.strip()}" for d in context.devices)
    return (f"the OpenCL compiler of {devices} could not build {what} ({first}); choose another device with "
            "--device or LFCL_DEVICE (`lfcl devices` lists them)")


def build_program(context: cl.Context, source: str, options: list[str], what: str) -> cl.Program:
    """Build ``source`` quietly: the build log (warnings) only with ``LFCL_VERBOSE`` (docs/outputs.md, Quiet runs).

    Compilers report warnings twice: in the build log, which pyopencl turns into a
    ``CompilerWarning``, and on the process's stderr (PoCL's clang prints "N warnings
    generated." to file descriptor 2 directly). Both are caught here. On CPUs without
    AVX-512, PoCL's clang notes that passing float16/int16 to the helpers of common.cl
    "changes the ABI" (-Wpsabi; PoCL builds with ``-Dinline=``, so they are ordinary
    calls to it): nothing a user can act on. Anything else the compiler prints on stderr
    is passed on. A build the compiler refuses raises :class:`DeviceError` in one line: the device, the
    compiler's first error, and how to choose another device (the default is the first GPU, which may be one
    whose OpenCL compiler is incomplete).
    """
    caught_warnings: list = []
    printed: list[str] = []
    sys.stderr.flush()
    with tempfile.TemporaryFile() as captured:
        try:
            saved = os.dup(2)
        except OSError:  # no stderr to protect
            saved = None
        if saved is not None:
            os.dup2(captured.fileno(), 2)
        try:
            with warnings.catch_warnings(record=True) as caught_warnings:
                warnings.simplefilter("always")
                try:
                    program = cl.Program(context, source).build(options=options)
                except cl.RuntimeError as exc:  # the device's compiler refused it: say which device, and the way out
                    raise DeviceError(_build_failure(context, what, str(exc))) from exc
        finally:
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
            captured.seek(0)
            printed = captured.read().decode(errors="replace").splitlines()
            # what is not the compiler's count line (another thread's output, a driver's message) goes on
            other = [line for line in printed if line.strip() and not _BUILD_CHATTER.match(line.strip())]
            if other:
                print("\n".join(other), file=sys.stderr)
    for w in caught_warnings:  # warnings other than the compiler's own go on as they were
        if not issubclass(w.category, cl.CompilerWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    chatter = [line for line in printed if _BUILD_CHATTER.match(line.strip())]
    if verbose():
        logs = [str(program.get_build_info(d, cl.program_build_info.LOG)).strip() for d in context.devices]
        text = "\n".join(log for log in logs if log) or "(empty build log)"
        print(f"lfcl: built {what} with {' '.join(options)}: {text}"
              + ("".join(f"\n{line}" for line in chatter)), file=sys.stderr)
    return program


def device_metadata(spec: str | int | None = None) -> dict:
    """The device ``spec`` selects, as the outputs record it: name, OpenCL type and platform."""
    device = get_runtime(spec).device
    return {"name": device.name.strip(), "type": cl.device_type.to_string(device.type),
            "platform": device.platform.name.strip()}


def grid_defines(pitch, dims_mask: int) -> tuple:
    """Build-time constants for programs that walk the 4D grid: lens pitch and dims mask."""
    U, V = (int(p) for p in pitch)
    return (("PITCH_U", U), ("PITCH_V", V), ("DIMS", int(dims_mask)))


_runtimes: dict[str, Runtime] = {}
_runtimes_lock = threading.Lock()


def get_runtime(spec: str | int | None = None) -> Runtime:
    """The shared :class:`Runtime` of the chosen device (created on first use)."""
    device = select_device(spec)
    key = f"{device.platform.name}/{device.name}/{device.int_ptr}"
    with _runtimes_lock:
        runtime = _runtimes.get(key)
        if runtime is None:
            runtime = Runtime(device)
            _runtimes[key] = runtime
        return runtime
