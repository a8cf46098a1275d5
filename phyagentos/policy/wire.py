"""The openpi wire format: msgpack with numpy arrays, as ``openpi-client`` frames it.

openpi's policy servers and ``openpi_client`` exchange msgpack messages in which a
numpy array is a map with *binary* keys::

    {b"__ndarray__": True, b"data": <raw bytes, C order>, b"dtype": <dtype.str, e.g. "<f4">,
     b"shape": [d0, d1, ...]}

and a numpy scalar is ``{b"__npgeneric__": True, b"data": <item>, b"dtype": <dtype.str>}``.
Strings are msgpack ``str`` and raw bytes ``bin`` (msgpack >= 1.0 defaults:
``use_bin_type=True`` when packing, ``raw=False`` when unpacking). Object, void and
complex dtypes are refused, so nothing is ever pickled. This module implements that
format from its description (``openpi-client`` 0.1.2 pins numpy < 2, so it is not a
dependency); ``tests/test_policy_wire.py`` pins the byte layout.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

__all__ = ["packb", "unpackb", "WireError"]

_REFUSED_KINDS = ("V", "O", "c")


class WireError(ValueError):
    """A message could not be encoded or decoded in the openpi wire format."""


def _encode(obj: Any) -> Any:
    if isinstance(obj, (np.ndarray, np.generic)) and obj.dtype.kind in _REFUSED_KINDS:
        raise WireError(f"dtype {obj.dtype} cannot be sent (object, void and complex arrays are refused)")
    if isinstance(obj, np.ndarray):
        return {b"__ndarray__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": list(obj.shape)}
    if isinstance(obj, np.generic):
        return {b"__npgeneric__": True, b"data": obj.item(), b"dtype": obj.dtype.str}
    raise WireError(f"cannot encode {type(obj).__name__} (send numbers, strings, lists, dicts and numpy arrays)")


def _decode(obj: dict) -> Any:
    if b"__ndarray__" in obj:
        try:
            dtype = np.dtype(obj[b"dtype"])
            shape = tuple(int(s) for s in obj[b"shape"])
            data = obj[b"data"]
        except (KeyError, TypeError, ValueError) as exc:
            raise WireError(f"malformed ndarray map: {exc}") from None
        if dtype.kind in _REFUSED_KINDS:
            raise WireError(f"dtype {dtype} is refused")
        expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if not isinstance(data, bytes) or len(data) != expected:
            raise WireError(f"ndarray payload of {len(data) if isinstance(data, bytes) else '?'} bytes does not match "
                            f"shape {shape} of {dtype} ({expected} bytes)")
        return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
    if b"__npgeneric__" in obj:
        try:
            return np.dtype(obj[b"dtype"]).type(obj[b"data"])
        except (KeyError, TypeError, ValueError) as exc:
            raise WireError(f"malformed numpy scalar map: {exc}") from None
    return obj


def packb(obj: Any) -> bytes:
    """Encode ``obj`` (dicts, lists, str, numbers, numpy arrays and scalars) to bytes.

    Raises:
        WireError: an unsupported type or dtype.
    """
    try:
        return msgpack.packb(obj, default=_encode, use_bin_type=True)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, WireError):
            raise
        raise WireError(str(exc)) from None


def unpackb(data: bytes) -> Any:
    """Decode bytes from :func:`packb` (or any openpi peer); arrays come back writable.

    Raises:
        WireError: not msgpack, or a malformed array map.
    """
    try:
        return msgpack.unpackb(data, object_hook=_decode, raw=False, strict_map_key=False)
    except WireError:
        raise
    except (msgpack.exceptions.ExtraData, msgpack.exceptions.FormatError, msgpack.exceptions.StackError,
            ValueError, TypeError) as exc:
        raise WireError(f"not a valid msgpack message: {exc}") from None
