"""Python values <-> ``ecmxf.v1.Value`` and ``DataType``."""

from __future__ import annotations

from typing import Optional, Union

from .v1 import common_pb2

PyValue = Union[bool, int, float, str, bytes]

# Names a user may give for a type, as in ecmxfctl (`--type u32`) and CiA's.
_TYPES = {
    "bool": common_pb2.DATA_TYPE_BOOLEAN,
    "boolean": common_pb2.DATA_TYPE_BOOLEAN,
    "i8": common_pb2.DATA_TYPE_INTEGER8,
    "int8": common_pb2.DATA_TYPE_INTEGER8,
    "i16": common_pb2.DATA_TYPE_INTEGER16,
    "int16": common_pb2.DATA_TYPE_INTEGER16,
    "i32": common_pb2.DATA_TYPE_INTEGER32,
    "int32": common_pb2.DATA_TYPE_INTEGER32,
    "i64": common_pb2.DATA_TYPE_INTEGER64,
    "int64": common_pb2.DATA_TYPE_INTEGER64,
    "u8": common_pb2.DATA_TYPE_UNSIGNED8,
    "uint8": common_pb2.DATA_TYPE_UNSIGNED8,
    "u16": common_pb2.DATA_TYPE_UNSIGNED16,
    "uint16": common_pb2.DATA_TYPE_UNSIGNED16,
    "u32": common_pb2.DATA_TYPE_UNSIGNED32,
    "uint32": common_pb2.DATA_TYPE_UNSIGNED32,
    "u64": common_pb2.DATA_TYPE_UNSIGNED64,
    "uint64": common_pb2.DATA_TYPE_UNSIGNED64,
    "f32": common_pb2.DATA_TYPE_REAL32,
    "real32": common_pb2.DATA_TYPE_REAL32,
    "float": common_pb2.DATA_TYPE_REAL32,
    "f64": common_pb2.DATA_TYPE_REAL64,
    "real64": common_pb2.DATA_TYPE_REAL64,
    "double": common_pb2.DATA_TYPE_REAL64,
    "string": common_pb2.DATA_TYPE_VISIBLE_STRING,
    "str": common_pb2.DATA_TYPE_VISIBLE_STRING,
    "bytes": common_pb2.DATA_TYPE_OCTET_STRING,
    "octets": common_pb2.DATA_TYPE_OCTET_STRING,
}


def data_type(t: Optional[Union[str, int]]) -> int:
    """A DataType from a name (``"u32"``, ``"int16"``, ``"DATA_TYPE_REAL32"``) or its number."""
    if t is None:
        return common_pb2.DATA_TYPE_UNSPECIFIED
    if isinstance(t, int):
        return t
    key = t.strip().lower()
    if key in _TYPES:
        return _TYPES[key]
    try:
        return common_pb2.DataType.Value(t.strip().upper())
    except ValueError:
        names = ", ".join(sorted(_TYPES))
        raise ValueError(f"unknown type {t!r}: one of {names}") from None


def to_python(v: common_pb2.Value) -> Optional[PyValue]:
    """The Python value of a ``Value`` (None when it carries none)."""
    kind = v.WhichOneof("kind")
    return None if kind is None else getattr(v, kind)


def to_value(x: PyValue) -> common_pb2.Value:
    """A ``Value`` for a Python value; the daemon checks it against the type."""
    if isinstance(x, bool):
        return common_pb2.Value(boolean=x)
    if isinstance(x, int):
        return common_pb2.Value(integer=x) if x < 0 else common_pb2.Value(unsigned=x)
    if isinstance(x, float):
        return common_pb2.Value(real=x)
    if isinstance(x, str):
        return common_pb2.Value(text=x)
    if isinstance(x, (bytes, bytearray, memoryview)):
        return common_pb2.Value(raw=bytes(x))
    raise TypeError(f"cannot send a {type(x).__name__} as an EtherCAT value: bool, int, float, str or bytes")
