"""The ``lfcl`` command line: thin click commands that parse options and call stages.

Each command lives in its own module under ``lfcl/cli/commands`` and exposes ``command``.
Errors that users can cause (bad files, bad parameters, no device) are reported as
one line and a non-zero exit, never a traceback.

The commands are loaded lazily (:class:`LazyGroup`): ``lfcl --help`` and ``lfcl
--version`` import neither numpy nor pyopencl, and ``lfcl process`` imports only its
own module (tests/test_quiet.py checks both).
"""

from __future__ import annotations

import importlib
import os

import click

from .. import __version__

#: Command name -> the first paragraph of its help (click shortens it for ``lfcl --help`` as it would the
#: command's own; tests/test_quiet.py checks that they agree).
COMMANDS = {
    "devices": "List OpenCL platforms and devices; mark the one lfcl would use.",
    "demosaic": "Demosaic the Bayer mosaic INPUT into the RGB image OUT.",
    "simulate": "Simulate a lenslet (plenoptic) camera capture with exact ground truth.",
    "process": "Demosaic a lenslet RAW (DNG, camera raw, or EXR/TIFF/PNG mosaic) into a 4D light field.",
    "batch": "Process many lenslet raws (files, folders, globs) like `lfcl process`, on Dask; resumable.",
    "evaluate": "Run METHODS on CAPTURE_DIR/raw.dng and score them against CAPTURE_DIR/truth.npy.",
    "bench": "Benchmarks: per-kernel bandwidth, PSNR against run time, ADMM iteration cost (see BENCHMARKS.md).",
    "calibrate": "Estimate the lenslet grid (and per-pixel weights) from a WHITE image, or write one from --pitch.",
}


def load_command(name: str) -> click.Command:
    """The click command of ``lfcl.cli.commands.<name>`` (imports that module and what it needs)."""
    return importlib.import_module(f"lfcl.cli.commands.{name}").command


class _Placeholder(click.Command):
    """A command listed in ``lfcl --help`` by its stored help line, without importing it."""

    def __init__(self, name: str, help_text: str):
        super().__init__(name, help=help_text)


class LazyGroup(click.Group):
    """A group whose commands are imported when they run (or show their own help), not before."""

    def list_commands(self, ctx):
        return sorted(COMMANDS)

    def get_command(self, ctx, cmd_name):
        if cmd_name not in COMMANDS:
            return None
        if ctx.meta.get("lfcl.listing"):  # `lfcl --help` lists the commands: their stored help lines
            return _Placeholder(cmd_name, COMMANDS[cmd_name])
        return load_command(cmd_name)

    def format_commands(self, ctx, formatter):
        ctx.meta["lfcl.listing"] = True
        try:
            super().format_commands(ctx, formatter)
        finally:
            ctx.meta.pop("lfcl.listing", None)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="lfcl")
@click.option("-v", "--verbose", is_flag=True,
              help="Show the OpenCL build logs (compiler warnings) on stderr; same as LFCL_VERBOSE=1.")
def cli(verbose):
    """lfcl: demosaic and denoise plenoptic (light-field) camera raws with OpenCL."""
    if verbose:  # through the environment: batch workers and every build see it
        os.environ["LFCL_VERBOSE"] = "1"


def main():
    cli(prog_name="lfcl")
