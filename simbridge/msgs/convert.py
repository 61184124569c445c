"""Conversion of client JSON payloads into validated messages, as rosbridge does it.

The in-memory form of a message (its *canonical* form) is a plain ``dict`` keyed by ROS field
names, with these value conventions, chosen so that every outgoing encoding is cheap:

* numeric sequences and arrays (``float32[]``, ``int16[9]``...) are numpy arrays of the exact
  dtype; ``uint8``/``char``/``byte`` arrays are ``bytes`` (base64 in JSON, byte strings in CBOR);
* ``bool`` and ``string`` arrays are lists; nested messages are dicts;
* ``builtin_interfaces/Time`` and ``Duration`` are ``{"sec": int, "nanosec": int}``.

Rules (rosbridge ``message_conversion.py`` behaviour, see the protocol reference section 3.2):
missing fields get their defaults; a key that is not a field, or a value of the wrong JSON type,
is rejected with the field's path; an integer is accepted for a float field, a float is not
accepted for an integer field; ``uint8[]`` accepts a base64 string or a list of integers;
Time accepts ``sec``/``secs`` and ``nanosec``/``nsecs`` and the string ``"now"``; a ``header``
object present without a stamp gets the current time.

ROS 1-era payloads are read where they are unambiguous (docs/compatibility.md): ``secs``/``nsecs``
in any Time or Duration field (giving both ``sec`` and ``secs`` is refused), and a
``std_msgs/Header`` ``seq`` (an unsigned integer, dropped: ROS 2 headers have none). What goes
out is always ROS 2 (``sec``/``nanosec``, no ``seq``).

Deliberate difference from rosbridge: ``null`` is accepted in float fields and read as NaN,
because JSON cannot carry NaN and ``JSON.stringify`` turns it into ``null`` (simbridge sends NaN
out as ``null`` too, so a message round-trips). Consumers that need finite values check them.
"""

from __future__ import annotations

import base64
import binascii
import math
import sys
from collections.abc import Callable, Sequence
from typing import Any, TypeGuard

import numpy as np

from simbridge.errors import ConversionError
from simbridge.msgs.registry import FieldSpec, TypeRegistry


def finite_number(value: object) -> TypeGuard[int | float]:
    """Whether ``value`` is a finite number: an int or a float (not a bool), not NaN or infinite.

    The one check for numbers from files, parameters and service requests (JSON has no NaN,
    but Python's parser and YAML's ``.nan`` do). An int too large for a float is not finite.
    """
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


__all__ = [
    "FLOAT32_MAX",
    "INT_RANGES",
    "NUMPY_DTYPES",
    "Converter",
    "Stamp",
    "finite_number",
    "positional_args",
]

#: A clock giving (sec, nanosec) of "now" for header stamps and ``"now"`` times.
Stamp = Callable[[], tuple[int, int]]

NUMPY_DTYPES: dict[str, type[np.generic]] = {
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}

INT_RANGES: dict[str, tuple[int, int]] = {
    "int8": (-(2**7), 2**7 - 1),
    "uint8": (0, 2**8 - 1),
    "byte": (0, 2**8 - 1),
    "char": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1),
    "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1),
    "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1),
    "uint64": (0, 2**64 - 1),
}

#: Largest finite float32: a finite number above it cannot be a float32 (it is refused, not
#: turned into infinity by one encoder and into an error by another).
FLOAT32_MAX = float(np.finfo(np.float32).max)
_BYTES_BASES = frozenset({"uint8", "char", "byte"})
_FLOAT_ELEMENTS = frozenset({int, float, type(None)})
_INT_ELEMENTS = frozenset({int})
_FLOATS = frozenset({"float32", "float64"})
#: Largest finite double: a JSON integer above it cannot become a float.
_FLOAT_MAX = sys.float_info.max
_TIME_TYPES = frozenset({"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})
_HEADER = "std_msgs/msg/Header"


def positional_args(args: list[Any], fields: Sequence[str], what: str) -> dict[str, Any]:
    """Return list ``args`` of a call or goal as an object: zipped onto ``fields`` in order.

    rosbridge protocol reference section 3.5 (``args: [a, b]`` maps positionally onto the request
    fields). Fewer values leave the rest to their defaults; more values than fields is refused
    (rosbridge drops them silently; a value sent to no field is a mistake worth telling).

    Raises:
        ConversionError: more values than fields; the text names ``what`` and the fields.
    """
    if len(args) > len(fields):
        expected = ", ".join(fields) or "no fields"
        msg = f"{what} has {len(fields)} fields ({expected}), got {len(args)} positional args"
        raise ConversionError(msg)
    return dict(zip(fields, args, strict=False))


def _jtype(value: object) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int | float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


class Converter:
    """Turns JSON payloads into canonical messages of known types, and makes defaults."""

    def __init__(self, registry: TypeRegistry, stamp: Stamp) -> None:
        #: Where field definitions come from.
        self.registry = registry
        #: Clock for header stamps and ``"now"``.
        self.stamp = stamp

    # -- public -------------------------------------------------------------------------------

    def from_json(self, typename: str, value: object) -> dict[str, Any]:
        """Return the canonical message of type ``typename`` built from a JSON value.

        A canonical message (numpy arrays, bytes) is taken too: a partial one is completed.

        Raises:
            ConversionError: the value does not fit the type; the text names the field path.
            TypeNotFoundError: the type is unknown.
        """
        spec = self.registry.spec(typename)
        if not isinstance(value, dict):
            msg = f"Expected a JSON object for type {spec.name} but received a {_jtype(value)}"
            raise ConversionError(msg)
        return self._message(spec.name, value, spec.name, "")

    def default(self, typename: str) -> dict[str, Any]:
        """Return the default (all-zero) canonical message of a type."""
        return self._message(self.registry.spec(typename).name, {}, typename, "", fill_now=False)

    # -- internals ----------------------------------------------------------------------------

    def _message(
        self, typename: str, obj: dict[str, Any], root: str, path: str, *, fill_now: bool = True
    ) -> dict[str, Any]:
        if typename in _TIME_TYPES:
            return self._time(typename, obj, root, path)
        spec = self.registry.spec(typename)
        names = {f.name for f in spec.fields}
        if typename == _HEADER and "seq" in obj:
            # ROS 1's header.seq (roslibpy's Header, ROS 1-era pages): checked, then dropped
            self._int(obj["seq"], "uint32", root, f"{path}.seq" if path else "seq")
            obj = {k: v for k, v in obj.items() if k != "seq"}
        for key in obj:
            if key not in names:
                where = f"{path}.{key}" if path else key
                msg = f"Message type {root} does not have a field {where}"
                raise ConversionError(msg)
        out: dict[str, Any] = {}
        for field in spec.fields:
            where = f"{path}.{field.name}" if path else field.name
            if field.name in obj:
                out[field.name] = self._field(field, obj[field.name], root, where)
            else:
                out[field.name] = self._default_field(field)
        if typename == _HEADER and fill_now and "stamp" not in obj:
            sec, nanosec = self.stamp()
            out["stamp"] = {"sec": sec, "nanosec": nanosec}
        return out

    def _time(self, typename: str, obj: object, root: str, path: str) -> dict[str, Any]:
        if obj == "now" and typename.endswith("/Time"):
            sec, nanosec = self.stamp()
            return {"sec": sec, "nanosec": nanosec}
        if not isinstance(obj, dict):
            msg = f"{root} message requires a {typename} for field {path}, got a {_jtype(obj)}"
            raise ConversionError(msg)
        extra = set(obj) - {"sec", "secs", "nanosec", "nsecs"}
        if extra:
            msg = f"Message type {root} does not have a field {path}.{sorted(extra)[0]}"
            raise ConversionError(msg)
        for ros2, ros1 in (("sec", "secs"), ("nanosec", "nsecs")):
            if ros2 in obj and ros1 in obj:
                msg = (
                    f"{root} message: {path} has both '{ros2}' (ROS 2) and '{ros1}' (ROS 1); "
                    "give one of them"
                )
                raise ConversionError(msg)
        sec = self._int(obj.get("sec", obj.get("secs", 0)), "int32", root, f"{path}.sec")
        nanosec = self._int(
            obj.get("nanosec", obj.get("nsecs", 0)), "uint32", root, f"{path}.nanosec"
        )
        return {"sec": sec, "nanosec": nanosec}

    def _field(self, field: FieldSpec, value: object, root: str, path: str) -> Any:
        if field.arraylen == -1:
            return self._element(field, value, root, path)
        if field.base in _BYTES_BASES:
            data = self._bytes(value, root, path)
            self._check_len(field, len(data), root, path)
            return data
        if isinstance(value, np.ndarray):  # a canonical message's array, completed again
            value = value.tolist()
        if not isinstance(value, list):
            msg = f"{root} message requires an array for field {path}, got a {_jtype(value)}"
            raise ConversionError(msg)
        self._check_len(field, len(value), root, path)
        dtype = NUMPY_DTYPES.get(field.base)
        if dtype is not None and not field.nested:
            return self._numeric_array(field.base, dtype, value, root, path)
        return [self._element(field, v, root, f"{path}[{i}]") for i, v in enumerate(value)]

    def _check_len(self, field: FieldSpec, n: int, root: str, path: str) -> None:
        if field.arraylen > 0 and n != field.arraylen:
            msg = f"{root} field {path} needs exactly {field.arraylen} elements, got {n}"
            raise ConversionError(msg)
        if field.bound and n > field.bound:
            msg = f"{root} field {path} holds at most {field.bound} elements, got {n}"
            raise ConversionError(msg)

    def _numeric_array(
        self, base: str, dtype: type[np.generic], value: list[Any], root: str, path: str
    ) -> Any:
        floats = base in _FLOATS
        # the element types at C speed; the per-element walks below only run when needed
        types = set(map(type, value))
        if not types <= (_FLOAT_ELEMENTS if floats else _INT_ELEMENTS):
            for i, v in enumerate(value):
                t = type(v)
                if t is int or (floats and (t is float or v is None)):
                    continue
                want = "number" if floats else "integer"
                msg = f"{root} field {path}[{i}] must be a {want}, got {_jtype(v)} {v!r}"
                raise ConversionError(msg)
        if floats:
            if int in types:
                for i, v in enumerate(value):
                    if type(v) is int and abs(v) > _FLOAT_MAX:
                        msg = f"{root} field {path}[{i}] = {v} is out of range for {base}"
                        raise ConversionError(msg)
            if type(None) in types:
                value = [math.nan if v is None else v for v in value]
            array = np.array(value, dtype=np.float64)
            if base == "float32":
                with np.errstate(invalid="ignore"):
                    over = np.flatnonzero(np.isfinite(array) & (np.abs(array) > FLOAT32_MAX))
                if over.size:
                    i = int(over[0])
                    msg = (
                        f"{root} field {path}[{i}] = {value[i]!r} is out of range for float32 "
                        f"(at most {FLOAT32_MAX:.8g} in magnitude)"
                    )
                    raise ConversionError(msg)
            return array.astype(dtype, copy=False)
        lo, hi = INT_RANGES[base]
        if value and not lo <= min(value) <= max(value) <= hi:
            for i, v in enumerate(value):
                if not lo <= v <= hi:
                    msg = f"{root} field {path}[{i}] = {v} is out of range for {base} [{lo}, {hi}]"
                    raise ConversionError(msg)
        return np.array(value, dtype=dtype)

    def _bytes(self, value: object, root: str, path: str) -> bytes:
        if isinstance(value, bytes | bytearray):
            return bytes(value)
        if isinstance(value, str):
            try:
                return base64.b64decode(value, validate=True)
            except (binascii.Error, ValueError):
                msg = f"{root} field {path} must be base64 text or a list of integers 0-255"
                raise ConversionError(msg) from None
        if isinstance(value, list):
            for i, v in enumerate(value):
                if type(v) is not int or not 0 <= v <= 255:
                    msg = f"{root} field {path}[{i}] must be an integer 0-255, got {v!r}"
                    raise ConversionError(msg)
            return bytes(value)
        msg = f"{root} field {path} must be base64 text or a list of integers 0-255"
        raise ConversionError(msg)

    def _element(self, field: FieldSpec, value: object, root: str, path: str) -> Any:
        base = field.base
        if field.nested:
            if base in _TIME_TYPES:
                return self._time(base, value, root, path)
            if not isinstance(value, dict):
                msg = f"{root} message requires a {base} for field {path}, got a {_jtype(value)}"
                raise ConversionError(msg)
            return self._message(base, value, root, path)
        if base in _FLOATS:
            if value is None:
                return math.nan
            if type(value) is int:
                if abs(value) > _FLOAT_MAX:  # float() would raise OverflowError
                    msg = f"{root} field {path} = {value} is out of range for {base}"
                    raise ConversionError(msg)
                value = float(value)
            if type(value) is float:
                if base == "float32" and math.isfinite(value) and abs(value) > FLOAT32_MAX:
                    msg = (
                        f"{root} field {path} = {value!r} is out of range for float32 "
                        f"(at most {FLOAT32_MAX:.8g} in magnitude)"
                    )
                    raise ConversionError(msg)
                return value
        elif base == "bool":
            if isinstance(value, bool):
                return value
        elif base in ("string", "wstring"):
            if isinstance(value, str):
                if field.string_bound and len(value) > field.string_bound:
                    msg = f"{root} field {path} holds at most {field.string_bound} characters"
                    raise ConversionError(msg)
                if "\x00" in value:  # a ROS string ends at its first NUL (CDR, rcl)
                    msg = f"{root} field {path} must not contain a NUL character (\\u0000)"
                    raise ConversionError(msg)
                return value
        else:
            return self._int(value, base, root, path)
        msg = f"{root} field {path} must be a {base}, got {_jtype(value)} {value!r}"
        raise ConversionError(msg)

    def _int(self, value: object, base: str, root: str, path: str) -> int:
        if type(value) is not int:
            msg = f"{root} field {path} must be an integer ({base}), got {_jtype(value)} {value!r}"
            raise ConversionError(msg)
        lo, hi = INT_RANGES[base]
        if not lo <= value <= hi:
            msg = f"{root} field {path} = {value} is out of range for {base} [{lo}, {hi}]"
            raise ConversionError(msg)
        return value

    def _default_field(self, field: FieldSpec) -> Any:
        if field.arraylen == -1:
            return self._default_element(field)
        n = max(field.arraylen, 0)
        if field.base in _BYTES_BASES:
            return bytes(n)
        dtype = NUMPY_DTYPES.get(field.base)
        if dtype is not None:
            return np.zeros(n, dtype=dtype)
        return [self._default_element(field) for _ in range(n)]

    def _default_element(self, field: FieldSpec) -> Any:
        base = field.base
        if field.nested:
            if base in _TIME_TYPES:
                return {"sec": 0, "nanosec": 0}
            return self._message(base, {}, base, "", fill_now=False)
        if base in _FLOATS:
            return 0.0
        if base == "bool":
            return False
        if base in ("string", "wstring"):
            return ""
        return 0
