"""The ``lfcl`` command line: thin click commands that parse options and call stages.

Each command lives in its own module under ``lfcl/commands`` and exposes ``command``.
Errors that users can cause (bad files, bad parameters, no device) are reported as
one line and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import importlib

import click

from . import __version__

COMMANDS = ("devices", "demosaic", "simulate", "process", "batch", "evaluate", "bench", "calibrate")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="lfcl")
def cli():
    """lfcl: demosaic and denoise plenoptic (light-field) camera raws with OpenCL."""


for _name in COMMANDS:
    cli.add_command(importlib.import_module(f"lfcl.commands.{_name}").command)


def main():
    cli(prog_name="lfcl")
