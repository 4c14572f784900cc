"""The device's planes -> exchange-layout copy against its numpy twin (lfcl.layout.planes_to_exchange)."""

from __future__ import annotations

import numpy as np
import pytest

from lfcl.device import get_runtime
from lfcl.layout import LightFieldShape, exchange_to_planes, planes_to_exchange
from lfcl.ops.exchange import PlanesToExchange


@pytest.fixture(scope="module")
def runtime():
    return get_runtime()


@pytest.mark.parametrize("S, T, U, V", [(1, 1, 1, 1), (2, 3, 9, 9), (5, 4, 3, 7), (3, 2, 10, 2)])
def test_device_matches_numpy_twin(runtime, S, T, U, V):
    shape = LightFieldShape(S, T, U, V)
    planes = np.random.default_rng(S * T + U * V).standard_normal(shape.planes_shape).astype(np.float32)
    got = PlanesToExchange(runtime, shape).forward(runtime.to_device(planes)).get()
    assert got.shape == (S, T, U, V, 3)
    np.testing.assert_array_equal(got, planes_to_exchange(planes, shape))
    # Every sample lands where the definition of the layout says: lens (s, t), pixel (u, v), colour c.
    s, t, u, v, c = S - 1, T - 1, U // 2, V - 1, 2
    assert got[s, t, u, v, c] == planes[c, s * U + u, t * V + v]
    np.testing.assert_array_equal(exchange_to_planes(got), planes)


def test_writes_into_out_and_checks_shapes(runtime):
    shape = LightFieldShape(2, 2, 3, 3)
    planes = np.arange(np.prod(shape.planes_shape), dtype=np.float32).reshape(shape.planes_shape)
    op = PlanesToExchange(runtime, shape)
    out = runtime.zeros((2, 2, 3, 3, 3))
    assert op.forward(runtime.to_device(planes), out=out) is out
    np.testing.assert_array_equal(out.get(), planes_to_exchange(planes, shape))
    with pytest.raises(ValueError, match="planes must be float32 of shape"):
        op.forward(runtime.to_device(planes[:, :-1]))
    with pytest.raises(ValueError, match="out must be float32 of shape"):
        op.forward(runtime.to_device(planes), out=runtime.zeros((2, 2, 3, 3)))


@pytest.mark.parametrize("S, T, U, V", [(1, 1, 2, 2), (4, 3, 9, 9)])
def test_from_host_planes_matches_numpy_twin(runtime, S, T, U, V):
    from lfcl.ops.exchange import exchange_from_host_planes

    shape = LightFieldShape(S, T, U, V)
    planes = np.random.default_rng(U + S).random(shape.planes_shape, dtype=np.float32)
    before = planes.copy()
    np.testing.assert_array_equal(exchange_from_host_planes(runtime, planes, shape), planes_to_exchange(planes, shape))
    np.testing.assert_array_equal(planes, before)  # the host planes are read, not written
    with pytest.raises(ValueError, match="planes must have shape"):
        exchange_from_host_planes(runtime, planes[:, 1:], shape)


@pytest.mark.parametrize("device_type", ["this device", "a GPU"])
def test_through_device_on_either_kind_of_device(runtime, device_type):
    """Runtime.through_device: host memory itself on a CPU device, copies up and down elsewhere (a GPU is
    played here by the same device under another type); both give the twins' answers."""
    import copy
    import types

    import pyopencl as cl

    from lfcl.ops.exchange import exchange_from_host_planes
    from lfcl.ops.malvar import malvar_np, malvar_planes

    rt = runtime
    if device_type == "a GPU":
        rt = copy.copy(runtime)
        rt.device = types.SimpleNamespace(type=cl.device_type.GPU)
    shape = LightFieldShape(3, 2, 9, 9)
    planes = np.random.default_rng(5).random(shape.planes_shape, dtype=np.float32)
    np.testing.assert_array_equal(exchange_from_host_planes(rt, planes, shape), planes_to_exchange(planes, shape))
    mosaic = planes[1]
    np.testing.assert_allclose(malvar_planes(rt, mosaic, "GRBG"), malvar_np(mosaic, "GRBG"), rtol=0, atol=1e-6)
