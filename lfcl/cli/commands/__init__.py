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
    help="OpenCL device: an index from `lfcl devices`, gpu or cpu (the first of that type), or a name substring. Default: $LFCL_DEVICE, else the first GPU, else the first device.",
)


class SectionedCommand(click.Command):
    """A command whose --help lists its options in named sections (``sections``: title -> parameter names,
    in order); options in no section come last under "Other options"."""

    def __init__(self, *args, sections: dict[str, tuple[str, ...]] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.sections = sections or {}

    def format_options(self, ctx, formatter):
        records = {p.name: p.get_help_record(ctx) for p in self.get_params(ctx)}
        placed = set()
        for title, names in self.sections.items():
            rows = [records[n] for n in names if records.get(n)]
            placed.update(names)
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)
        rest = [record for name, record in records.items() if record and name not in placed]
        if rest:
            with formatter.section("Other options"):
                formatter.write_dl(rest)


#: The sections of `lfcl process --help` and `lfcl batch --help` (their options are shared).
PROCESS_SECTIONS = {
    "Input and lens grid": ("pitch", "calibration", "white", "pattern"),
    "Method": ("method", "pipeline", "strength", "lam", "iterations", "tolerance_db", "safety_net", "auto_costly",
               "max_memory"),
    "Outputs": ("out_dir", "outputs", "refocus_spec", "fmt", "previews", "as_json"),
    "Device": ("device",),
}
