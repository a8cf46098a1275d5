"""The openpi wire format, byte for byte: msgpack maps with binary keys for numpy arrays."""

from __future__ import annotations

import msgpack
import numpy as np
import pytest

from phyagentos.policy.wire import WireError, packb, unpackb


def test_an_array_is_the_documented_map_with_binary_keys():
    a = np.arange(6, dtype=np.float32).reshape(2, 3)
    raw = msgpack.unpackb(packb({"actions": a}), raw=False)  # no hooks: the frame as any peer sees it
    enc = raw["actions"]
    assert set(enc) == {b"__ndarray__", b"data", b"dtype", b"shape"}
    assert enc[b"__ndarray__"] is True
    assert enc[b"dtype"] == "<f4" and enc[b"shape"] == [2, 3]
    assert enc[b"data"] == a.tobytes()


def test_frames_built_the_way_openpi_client_builds_them_decode_to_arrays():
    # openpi_client.msgpack_numpy: msgpack.packb(obj, default=pack_array) with tuple shapes,
    # numpy scalars as __npgeneric__ maps.
    a = np.linspace(0, 1, 8, dtype=np.float64).reshape(4, 2)
    frame = msgpack.packb({
        "observation/state": {b"__ndarray__": True, b"data": a.tobytes(), b"dtype": a.dtype.str, b"shape": a.shape},
        "step": {b"__npgeneric__": True, b"data": 7, b"dtype": np.dtype(np.int64).str},
        "prompt": "pick up the cube",
    })
    out = unpackb(frame)
    assert out["prompt"] == "pick up the cube"
    assert out["step"] == 7 and isinstance(out["step"], np.int64)
    assert out["observation/state"].dtype == np.float64 and np.array_equal(out["observation/state"], a)
    out["observation/state"][0, 0] = 5.0  # decoded arrays are writable copies


@pytest.mark.parametrize("value", [
    np.array([1, 2, 3], dtype=np.int32), np.array([[True, False]]), np.zeros((224, 224, 3), dtype=np.uint8),
    np.array(["asdf", "qwer"]), np.array([np.nan, np.inf, -np.inf]), np.float32(1.5), np.array(2.0),
])
def test_round_trip_keeps_dtype_shape_and_values(value):
    out = unpackb(packb({"x": value}))["x"]
    if isinstance(value, np.ndarray):
        assert out.dtype == value.dtype and out.shape == value.shape
        assert np.array_equal(out, value, equal_nan=value.dtype.kind == "f")
    else:
        assert out == value and type(out) is type(value)


def test_object_and_complex_arrays_are_refused_never_pickled():
    with pytest.raises(WireError, match="refused"):
        packb({"x": np.array([object()], dtype=object)})
    with pytest.raises(WireError):
        packb({"x": np.array([1j])})


def test_a_payload_that_does_not_match_its_shape_is_malformed():
    bad = msgpack.packb({"a": {b"__ndarray__": True, b"data": b"\x00" * 7, b"dtype": "<f4", b"shape": [2]}})
    with pytest.raises(WireError, match="does not match"):
        unpackb(bad)
    with pytest.raises(WireError):
        unpackb(b"\xc1not msgpack")
