"""``lfcl devices``: the OpenCL platforms and devices, with their key limits.

The device that commands would use is marked: the one ``--device`` names, else
``$LFCL_DEVICE``, else the first GPU, else the first device. When the selection names no device, the list is
still printed and the error follows on stderr (exit code 1), so a bad
``LFCL_DEVICE`` shows up here before it breaks a long run.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys

import click

from ...device import DeviceError, list_devices, select_device
from . import device_option, user_errors


def _selection(devices, spec):
    """(index of the device a command would use or None, where the choice came from, error or None)."""
    env = os.environ.get("LFCL_DEVICE", "")
    if spec not in (None, ""):
        source = f"--device {spec}"
    elif env.strip():
        source = f"LFCL_DEVICE={env}"
    else:
        source = "default: the first GPU, else the first device"
    try:
        chosen = select_device(spec)
    except DeviceError as exc:
        return None, source, str(exc)
    for info in devices:
        if select_device(str(info.index)) == chosen:
            return info.index, source, None
    return None, source, None


@click.command("devices")
@click.option("--json", "as_json", is_flag=True, help="Print the list as JSON.")
@device_option
@user_errors
def command(as_json: bool, device: str | None):
    """List OpenCL platforms and devices; mark the one lfcl would use."""
    devices = list_devices()  # DeviceError (with the install hint) when there is no platform
    selected, source, error = _selection(devices, device)
    if as_json:
        payload = {
            "devices": [dict(dataclasses.asdict(d), selected=d.index == selected) for d in devices],
            "selected": selected,
            "selected_by": source,
            "error": error,
        }
        click.echo(json.dumps(payload, indent=2))
    else:
        platform = None
        for info in devices:
            if info.platform != platform:
                platform = info.platform
                click.echo(f"Platform: {platform}")
            mark = "*" if info.index == selected else " "
            click.echo(f" {mark} {info.describe()}")
        if selected is not None:
            click.echo(f"* = device used by lfcl commands ({source})")
    if error is not None:
        click.echo(f"lfcl: error: {source}: {error}", err=True)
        sys.exit(1)
