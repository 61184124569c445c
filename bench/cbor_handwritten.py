"""The CBOR encoder simbridge had before it used cbor2 (simbridge/rosbridge/cbor.py at 65d96de).

Kept only as the baseline of ``python -m bench cbor``: the same RFC 8949 encoding of canonical
messages (8-byte doubles, bignum tags 2/3, RFC 8746 typed arrays), written by hand.
"""

from __future__ import annotations

import struct
import sys
from typing import Any

import numpy as np

from simbridge.rosbridge.cbor import TYPED_ARRAY_TAGS


__all__ = ["encode_cbor"]

_BIG_ENDIAN = sys.byteorder == "big"
_DOUBLE = struct.Struct(">Bd")
_U8 = struct.Struct(">BB")
_U16 = struct.Struct(">BH")
_U32 = struct.Struct(">BI")
_U64 = struct.Struct(">BQ")


def _head(major: int, n: int) -> bytes:
    """Return the initial bytes of a data item of ``major`` type with argument ``n``."""
    mt = major << 5
    if n < 24:
        return bytes((mt | n,))
    if n < 0x100:
        return _U8.pack(mt | 24, n)
    if n < 0x10000:
        return _U16.pack(mt | 25, n)
    if n < 0x100000000:
        return _U32.pack(mt | 26, n)
    return _U64.pack(mt | 27, n)


def _array(value: np.ndarray[Any, Any], out: list[bytes]) -> None:
    char = value.dtype.char
    if char == "?":
        out.append(_head(4, len(value)))
        out.extend(b"\xf5" if x else b"\xf4" for x in value.tolist())
        return
    tag = TYPED_ARRAY_TAGS.get(char)
    if tag is None or value.ndim != 1:
        _encode(value.tolist(), out)
        return
    if value.dtype.byteorder == ">" or (_BIG_ENDIAN and value.dtype.byteorder == "="):
        value = value.astype(value.dtype.newbyteorder("<"))
    data = value.tobytes()
    out.append(_head(6, tag))
    out.append(_head(2, len(data)))
    out.append(data)


#: Encoded text strings seen as map keys (field names: a small, fixed set).
_KEYS: dict[str, bytes] = {}


def _text(value: str) -> bytes:
    data = value.encode("utf-8")
    n = len(data)
    if n < 24:
        return bytes((0x60 | n,)) + data
    return _head(3, n) + data


def _encode(value: Any, out: list[bytes]) -> None:
    t = type(value)
    append = out.append
    if t is dict:
        append(_head(5, len(value)))
        keys = _KEYS
        for key, item in value.items():
            encoded = keys.get(key)
            if encoded is None:
                encoded = _text(key)
                if len(keys) < 4096:
                    keys[key] = encoded
            append(encoded)
            it = type(item)
            if it is float:
                append(_DOUBLE.pack(0xFB, item))
            elif it is str:
                append(_text(item))
            elif it is int and 0 <= item < 24:
                append(_SMALL[item])
            else:
                _encode(item, out)
    elif t is float:
        append(_DOUBLE.pack(0xFB, value))
    elif t is str:
        append(_text(value))
    elif t is bool:
        append(b"\xf5" if value else b"\xf4")
    elif t is int:
        if 0 <= value < _BIG:
            append(_head(0, value))
        elif -_BIG <= value < 0:
            append(_head(1, -1 - value))
        else:  # beyond 64 bits (JSON allows it): a bignum, tag 2 or 3 (RFC 8949 3.4.3)
            n = value if value >= 0 else -1 - value
            append(_head(6, 2 if value >= 0 else 3))
            _encode(n.to_bytes((n.bit_length() + 7) // 8, "big"), out)
    elif t is list or t is tuple:
        append(_head(4, len(value)))
        for item in value:
            _encode(item, out)
    elif value is None:
        append(b"\xf6")
    elif t is bytes or t is bytearray or t is memoryview:
        data = bytes(value)
        append(_head(2, len(data)))
        append(data)
    elif t is np.ndarray:
        _array(value, out)
    elif isinstance(value, np.generic):
        _encode(value.item(), out)
    else:
        msg = f"cannot encode a {t.__name__} as CBOR"
        raise TypeError(msg)


_SMALL = [bytes((n,)) for n in range(24)]
#: Integers from ``-_BIG`` to ``_BIG - 1`` fit a CBOR head; others are bignums.
_BIG = 1 << 64


def encode_cbor(value: Any) -> bytes:
    """Return the CBOR encoding of a canonical message or envelope."""
    out: list[bytes] = []
    _encode(value, out)
    return b"".join(out)
