"""One module per CLI command; each exposes a click ``command``."""

from __future__ import annotations

import functools
import sys

import click

from ...device import DeviceError


def user_errors(func):
    """Turn errors a user can cause into one line on stderr and exit code 1.

    ValueError (bad input, bad parameters), OSError (files), DeviceError (no
    OpenCL runtime) and FloatingPointError (a solver that diverged) are the
    user-facing failures; anything else is a bug and keeps its traceback.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except (ValueError, OSError, DeviceError, FloatingPointError) as exc:
            click.echo(f"lfcl: error: {exc}", err=True)
            sys.exit(1)

    return wrapper


device_option = click.option(
    "--device", "device", default=None, metavar="SPEC",
    help="OpenCL device: an index from `lfcl devices` or a name substring. Default: $LFCL_DEVICE, else the first device.",
)
