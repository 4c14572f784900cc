"""``lfcl devices`` and device selection errors."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from lfcl.cli.commands import devices as devices_module
from lfcl.cli.commands.devices import command
from lfcl.device import INSTALL_HINT, DeviceError, list_devices, select_device


@pytest.fixture(autouse=True)
def no_env_device(monkeypatch):
    monkeypatch.delenv("LFCL_DEVICE", raising=False)


def run(*args):
    return CliRunner().invoke(command, list(args))


def test_lists_devices():
    result = run()
    assert result.exit_code == 0, result.output
    infos = list_devices()
    assert len(infos) >= 1
    for info in infos:
        assert info.name in result.stdout
        assert f"[{info.index}]" in result.stdout
    marked = [line for line in result.stdout.splitlines() if line.startswith(" * ")]
    expected = next((i.index for i in infos if "GPU" in i.type), 0)  # the first GPU, else the first device
    assert len(marked) == 1 and f"[{expected}]" in marked[0]
    assert "compute units" in result.stdout and "max allocation" in result.stdout
    assert result.stderr == ""


def test_json():
    result = run("--json")
    assert result.exit_code == 0, result.output
    payload = json.loads(result.stdout)
    assert len(payload["devices"]) >= 1
    first = payload["devices"][0]
    for key in ("index", "platform", "name", "type", "compute_units", "global_mem_mib",
                "max_alloc_mib", "max_work_group_size", "opencl_version", "selected"):
        assert key in first
    assert payload["selected"] == next((d["index"] for d in payload["devices"] if "GPU" in d["type"]), 0)
    assert [d["selected"] for d in payload["devices"]].count(True) == 1
    assert payload["error"] is None


def test_device_option_and_env_select(monkeypatch):
    last = str(len(list_devices()) - 1)
    payload = json.loads(run("--json", "--device", last).stdout)
    assert payload["selected"] == int(last) and payload["selected_by"] == f"--device {last}"
    monkeypatch.setenv("LFCL_DEVICE", last)
    payload = json.loads(run("--json").stdout)
    assert payload["selected"] == int(last) and payload["selected_by"] == f"LFCL_DEVICE={last}"
    name = list_devices()[0].name
    assert json.loads(run("--json", "--device", name.lower()).stdout)["selected"] is not None


def test_select_device_bogus_name(monkeypatch):
    with pytest.raises(DeviceError, match="no OpenCL device matches 'bogus-gpu'"):
        select_device("bogus-gpu")
    monkeypatch.setenv("LFCL_DEVICE", "bogus-gpu")
    with pytest.raises(DeviceError, match="bogus-gpu"):
        select_device()
    with pytest.raises(DeviceError, match="does not exist"):
        select_device(str(len(list_devices()) + 5))


def test_bogus_env_device_is_reported(monkeypatch):
    monkeypatch.setenv("LFCL_DEVICE", "bogus-gpu")
    result = run()
    assert result.exit_code == 1
    assert list_devices()[0].name in result.stdout  # the list is still shown
    assert " * " not in result.stdout
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "LFCL_DEVICE=bogus-gpu" in lines[0] and "no OpenCL device matches" in lines[0]


def test_bogus_device_option():
    result = run("--json", "--device", "bogus-gpu")
    assert result.exit_code == 1
    assert json.loads(result.stdout)["error"].startswith("no OpenCL device matches 'bogus-gpu'")
    assert "bogus-gpu" in result.stderr


def test_no_platform(monkeypatch):
    def no_devices():
        raise DeviceError(INSTALL_HINT)

    monkeypatch.setattr(devices_module, "list_devices", no_devices)
    result = run()
    assert result.exit_code == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "pocl-opencl-icd" in lines[0]
    assert result.stdout == ""


class _FakeDevice:
    def __init__(self, name, kind):
        self.name, self.type = name, kind


def test_default_prefers_the_first_gpu(monkeypatch):
    import pyopencl as cl

    from lfcl import device as device_module

    cpu, gpu, gpu2 = (_FakeDevice("cpu", cl.device_type.CPU), _FakeDevice("gpu", cl.device_type.GPU),
                      _FakeDevice("gpu2", cl.device_type.GPU | cl.device_type.DEFAULT))
    for listed, expected in (([cpu, gpu, gpu2], gpu), ([gpu2, cpu], gpu2), ([cpu], cpu),
                             ([_FakeDevice("acc", cl.device_type.ACCELERATOR), cpu], None)):
        monkeypatch.setattr(device_module, "_all_devices", lambda listed=listed: listed)
        assert select_device() is (expected or listed[0])
    # a named device still wins over the default
    monkeypatch.setattr(device_module, "_all_devices", lambda: [_FakeDevice("cpu", cl.device_type.CPU), gpu])
    monkeypatch.setenv("LFCL_DEVICE", "0")
    assert select_device().name == "cpu"


def test_a_refused_build_is_one_line_naming_the_device(monkeypatch):
    """A device whose compiler refuses a kernel (the default GPU may have an incomplete one): a DeviceError in one
    line with the device, the compiler's first error and the way to choose another; nothing is cached."""
    from lfcl import device as device_module
    from lfcl.device import Runtime

    real = device_module.kernel_source
    monkeypatch.setattr(device_module, "kernel_source",
                        lambda name: "__kernel void broken(__global float *x) { x[0] = undeclared_thing; }"
                        if name == "malvar" else real(name))
    runtime = Runtime(select_device())  # a fresh context: nothing built yet
    with pytest.raises(DeviceError) as caught:
        runtime.kernel("malvar", "broken")
    text = str(caught.value)
    assert "\n" not in text
    assert runtime.device.name.strip() in text and "kernels/malvar.cl" in text
    assert "undeclared_thing" in text and "--device or LFCL_DEVICE" in text
    assert not runtime._programs
    monkeypatch.setattr(device_module, "kernel_source", real)
    assert runtime.kernel("malvar", "malvar") is not None  # the real source builds on the same runtime


def test_device_by_type(monkeypatch):
    """`--device gpu` / `cpu` / `accelerator`: the first device of that type, whatever the names; none is an error."""
    import pyopencl as cl

    from lfcl import device as device_module

    cpu, gpu, gpu2 = (_FakeDevice("cpu-one", cl.device_type.CPU), _FakeDevice("card", cl.device_type.GPU),
                      _FakeDevice("card2", cl.device_type.GPU))
    monkeypatch.setattr(device_module, "_all_devices", lambda: [gpu, cpu, gpu2])
    assert select_device("gpu") is gpu and select_device("GPU") is gpu and select_device("cpu") is cpu
    monkeypatch.setenv("LFCL_DEVICE", "cpu")
    assert select_device() is cpu
    with pytest.raises(DeviceError, match="no OpenCL device of type ACCELERATOR"):
        select_device("accelerator")


def test_device_by_type_on_this_machine():
    infos = list_devices()
    for kind in ("cpu", "gpu"):
        first = next((i.index for i in infos if kind.upper() in i.type), None)
        payload = json.loads(run("--json", "--device", kind).stdout)
        if first is None:
            assert payload["selected"] is None and f"type {kind.upper()}" in payload["error"]
        else:
            assert payload["selected"] == first and payload["error"] is None
