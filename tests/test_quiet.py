"""A quiet, fast command line: no compiler chatter on stderr, `lfcl --help` without numpy or pyopencl."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import uuid
import warnings
from pathlib import Path

import pytest

LFCL = [sys.executable, "-c", "from lfcl.cli import main; main()"]


def _env(tmp_path, **extra) -> dict:
    """The environment of a fresh process: its own empty PoCL kernel cache, pyopencl's cache off."""
    env = {k: v for k, v in os.environ.items() if k not in ("LFCL_VERBOSE", "PYOPENCL_COMPILER_OUTPUT")}
    cache = tmp_path / "pocl-cache"
    cache.mkdir(exist_ok=True)
    env.update(POCL_CACHE_DIR=str(cache), PYOPENCL_NO_CACHE="1", **extra)
    return env


# --------------------------------------------------------------------------- start-up

def test_help_imports_neither_numpy_nor_pyopencl(tmp_path):  # run away from the source tree
    code = ("import sys\nfrom lfcl.cli import cli\n"
            "try:\n    cli(['--help'], prog_name='lfcl')\nexcept SystemExit:\n    pass\n"
            "print('\\nIMPORTED', sorted(m for m in ('numpy', 'pyopencl', 'colour', 'matplotlib', 'dask', 'scipy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    assert "process" in out and "batch" in out  # the commands are listed
    assert out.strip().splitlines()[-1] == "IMPORTED []"


def test_stored_help_lines_match_the_commands():
    from click import Context

    from lfcl.cli import COMMANDS, cli, load_command

    ctx = Context(cli)
    ctx.meta["lfcl.listing"] = True  # as while `lfcl --help` lists them
    for name in COMMANDS:
        listed, real = cli.get_command(ctx, name), load_command(name)
        for limit in (30, 45, 70, 1000):
            assert listed.get_short_help_str(limit) == real.get_short_help_str(limit), (name, limit)
    ctx = Context(cli)
    assert cli.get_command(ctx, "process") is load_command("process")  # a run gets the real command
    assert cli.get_command(ctx, "nope") is None


def test_process_imports_no_plotting_or_dask(tmp_path):
    """A process run without previews imports neither matplotlib nor dask (nor colour-science)."""
    cap = _capture(tmp_path)
    code = ("import sys\nfrom lfcl.cli import cli\n"
            f"try:\n    cli(['process', {str(cap / 'raw.dng')!r}, '--pitch', '9', '--method', 'malvar', "
            f"'--no-previews', '-o', {str(tmp_path / 'out')!r}], prog_name='lfcl')\n"
            "except SystemExit as e:\n    assert not e.code, e.code\n"
            "print('\\nIMPORTED', sorted(m for m in ('colour', 'matplotlib', 'dask') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path).stdout
    assert out.strip().splitlines()[-1] == "IMPORTED []"


# --------------------------------------------------------------------------- quiet builds

_WARNING_SOURCE = "#warning a warning on purpose\n__kernel void k(__global float *x) { x[0] = 1.0f; }\n"


def test_build_warnings_stay_off_stderr(runtime, capfd, monkeypatch):
    """A program whose build warns: no CompilerWarning, nothing on stderr (PoCL prints "N warnings
    generated." straight to file descriptor 2); LFCL_VERBOSE=1 shows the log."""
    import pyopencl as cl

    from lfcl.device import build_program

    monkeypatch.delenv("LFCL_VERBOSE", raising=False)
    monkeypatch.delenv("PYOPENCL_COMPILER_OUTPUT", raising=False)
    source = f"// {uuid.uuid4()}: never in a cache\n" + _WARNING_SOURCE
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        program = build_program(runtime.context, source, ["-cl-std=CL1.2"], "test.cl")
    assert program.k is not None
    assert not [w for w in caught if issubclass(w.category, cl.CompilerWarning)]
    out, err = capfd.readouterr()
    assert err == "" and out == ""

    monkeypatch.setenv("LFCL_VERBOSE", "1")
    source = f"// {uuid.uuid4()}: never in a cache\n" + _WARNING_SOURCE
    build_program(runtime.context, source, ["-cl-std=CL1.2"], "test.cl")
    err = capfd.readouterr().err
    assert "lfcl: built test.cl with -cl-std=CL1.2" in err and "a warning on purpose" in err


def test_failed_build_still_raises_with_its_log(runtime, capfd):
    """A refused build raises one line (DeviceError: the device, the first error) with the whole log behind it."""
    import pyopencl as cl

    from lfcl.device import DeviceError, build_program

    source = f"// {uuid.uuid4()}\n__kernel void k(__global float *x) {{ x[0] = undeclared; }}\n"
    with pytest.raises(DeviceError, match="could not build broken.cl .*undeclared") as caught:
        build_program(runtime.context, source, ["-cl-std=CL1.2"], "broken.cl")
    assert isinstance(caught.value.__cause__, cl.RuntimeError) and "undeclared" in str(caught.value.__cause__)
    assert "errors generated" not in capfd.readouterr().err


def _capture(tmp_path) -> Path:
    from lfcl.sim import simulate, write_capture

    cap = tmp_path / "cap"
    write_capture(simulate("charts", lenses=(8, 8), seed=3), cap)
    return cap


def test_process_prints_nothing_on_stderr(tmp_path):
    """`lfcl process` in a fresh process with an empty kernel cache: the summary on stdout, stderr empty.

    The ADMM progress bar is tqdm's with ``disable=None``: drawn on terminals only, so a
    run whose stderr is a pipe (this one, a log file, CI) has none.
    """
    cap = _capture(tmp_path)
    # malvar: few programs to build (every program starts with common.cl, where PoCL's notes come from)
    args = [*LFCL, "process", str(cap / "raw.dng"), "--pitch", "9", "--method", "malvar", "--outputs", "center",
            "--no-previews", "--json"]
    run = subprocess.run([*args, "-o", str(tmp_path / "out")], capture_output=True, text=True, env=_env(tmp_path),
                         cwd=tmp_path)  # `python -c` puts the working folder first on sys.path: not the source tree
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""
    assert json.loads(run.stdout)["outputs"] == ["center.exr"]

    verbose = subprocess.run([*LFCL, "--verbose", *args[3:], "-o", str(tmp_path / "out2")],
                             capture_output=True, text=True, env=_env(tmp_path / "out"), cwd=tmp_path)
    assert verbose.returncode == 0, verbose.stderr
    assert "lfcl: built kernels/" in verbose.stderr
