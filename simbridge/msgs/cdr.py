"""ROS 2 CDR serialization of canonical messages, made by rosbags (for ``cbor-raw``).

The bytes are what an rclpy raw subscription delivers: the 4-byte encapsulation header
(``00 01 00 00``, little-endian CDR) followed by the CDR body. The canonical ``dict`` form
(see :mod:`simbridge.msgs.convert`) is turned into rosbags message objects by a builder compiled
once per type.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from simbridge.msgs.convert import NUMPY_DTYPES
from simbridge.msgs.registry import TypeRegistry, normalize_type


__all__ = ["CdrWriter", "to_dict"]

Builder = Callable[[Any], Any]
_PLACEHOLDER = "structure_needs_at_least_one_member"
_BYTES = {"uint8": np.uint8, "char": np.uint8, "byte": np.uint8, "octet": np.uint8}


class CdrWriter:
    """Serializes canonical messages of the types a registry knows."""

    def __init__(self, registry: TypeRegistry) -> None:
        #: Where the definitions and rosbags classes come from.
        self.registry = registry
        self._builders: dict[str, Builder] = {}

    def serialize(self, typename: str, msg: Any) -> bytes:
        """Return the CDR bytes (with encapsulation header) of a canonical message."""
        canonical = normalize_type(typename)
        obj = self._builder(canonical)(msg)
        return bytes(self.registry.store.serialize_cdr(obj, canonical, little_endian=True))

    def factory(self, typename: str, msg: Any) -> Callable[[], bytes]:
        """Return a function computing the CDR bytes of ``msg`` when first needed (then kept).

        Every consumer of one message (``cbor-raw`` subscribers, ROS 2 over Zenoh) shares the
        one serialization.
        """
        kept: list[bytes] = []

        def cdr() -> bytes:
            if not kept:
                kept.append(self.serialize(typename, msg))
            return kept[0]

        return cdr

    def _builder(self, typename: str) -> Builder:
        builder = self._builders.get(typename)
        if builder is None:
            builder = self._compile(typename)
            self._builders[typename] = builder
        return builder

    def _compile(self, typename: str) -> Builder:
        store = self.registry.store
        cls = store.types[typename]
        _consts, fields = store.fielddefs[typename]
        parts: list[tuple[str, Callable[[Any], Any] | None]] = []
        for name, (kind, detail) in fields:
            if name == _PLACEHOLDER:
                parts.append((name, None))
            else:
                parts.append((name, self._field(int(kind), detail)))

        def build(value: Any) -> Any:
            kwargs = {}
            for name, convert in parts:
                if convert is None:
                    kwargs[name] = 0
                else:
                    kwargs[name] = convert(value[name])
            return cls(**kwargs)

        return build

    def _field(self, kind: int, detail: Any) -> Callable[[Any], Any]:
        if kind == 1:  # BASE
            return _same
        if kind == 2:  # NAME
            name = str(detail)
            return lambda v: self._builder(name)(v)
        (inner_kind, inner_detail), _count = detail
        if int(inner_kind) == 2:
            name = str(inner_detail)
            return lambda v: [self._builder(name)(x) for x in v]
        base = str(inner_detail[0])
        if base in ("string", "wstring"):
            return list
        if base == "bool":
            return lambda v: np.asarray(v, dtype=np.bool_)
        if base in _BYTES:
            return _uint8s
        dtype = NUMPY_DTYPES[base]
        return lambda v: np.asarray(v, dtype=dtype)


def _same(value: Any) -> Any:
    return value


def _uint8s(value: Any) -> Any:
    if isinstance(value, bytes | bytearray | memoryview):
        return np.frombuffer(bytes(value), dtype=np.uint8)
    return np.asarray(value, dtype=np.uint8)


def to_dict(obj: Any) -> Any:
    """Return a rosbags message object (deserialized CDR) as a plain dict (arrays as lists)."""
    fields = getattr(obj, "__dataclass_fields__", None)
    if fields is not None:
        return {name: to_dict(getattr(obj, name)) for name in fields if name != "__msgtype__"}
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, list | tuple):
        return [to_dict(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
