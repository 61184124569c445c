"""CDR encoding and decoding of canonical messages, compiled to Python once per type.

rosbags' serializer needs its own message objects: building them from a canonical ``dict`` and
serializing took 140 us for an ``Odometry`` (its 21 nested objects), which at 20 Hz times 30
robots is most of what publishing to ROS 2 costs. Here each type becomes one generated
function that writes (or reads) the bytes straight from (into) the canonical form: consecutive
primitive fields, nested ones included, are packed by one precompiled ``struct`` per alignment
of their start, bulk arrays go through numpy. The bytes are exactly rosbags' (the tests compare
them type by type): little-endian plain CDR (XCDR1) after the 4-byte encapsulation header, each
primitive aligned to its size from the start of the body, a string as ``uint32`` length
(with its NUL) then the bytes and NUL, a sequence as ``uint32`` count then its elements, an
empty message as one ``uint8``. Types with ``wstring`` are not compiled (:class:`Unsupported`):
the caller uses rosbags for them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np


__all__ = ["Unsupported", "compile_reader", "compile_writer"]

#: A registry's ``fielddefs``: name -> (constants, [(field, (nodetype, detail))]), as rosbags'.
FieldDefs = Any
Writer = Callable[[Any, bytearray], None]
Reader = Callable[[bytes, int], tuple[Any, int]]

_BASE, _NAME, _ARRAY, _SEQUENCE = 1, 2, 3, 4
_PLACEHOLDER = "structure_needs_at_least_one_member"
_PRIMITIVES = {
    "bool": ("?", 1),
    "byte": ("B", 1),
    "char": ("B", 1),
    "int8": ("b", 1),
    "uint8": ("B", 1),
    "int16": ("h", 2),
    "uint16": ("H", 2),
    "int32": ("i", 4),
    "uint32": ("I", 4),
    "int64": ("q", 8),
    "uint64": ("Q", 8),
    "float32": ("f", 4),
    "float64": ("d", 8),
}
_DTYPES = {
    "int8": "<i1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "int64": "<i8",
    "uint64": "<u8",
    "float32": "<f4",
    "float64": "<f8",
}
_BYTES = frozenset({"uint8", "byte", "char"})
_U32 = struct.Struct("<I")
_ZEROS = tuple(bytes(n) for n in range(8))


class Unsupported(Exception):
    """The type has a field this codec does not compile (``wstring``)."""


def _runs(fields: list[tuple[str, int]]) -> tuple[struct.Struct, ...]:
    """Return, for each start offset mod 8, the struct packing a run of primitives."""
    out = []
    for start in range(8):
        offset, fmt = start, "<"
        for code, size in fields:
            pad = -offset % size
            fmt += "x" * pad + code
            offset += pad + size
        out.append(struct.Struct(fmt))
    return tuple(out)


class _Gen:
    """Generates the writer or reader source of one type."""

    def __init__(self, fielddefs: FieldDefs, name: str, env: dict[str, Any]) -> None:
        self.fielddefs = fielddefs
        self.name = name
        self.env = env
        self.lines: list[str] = []
        self.count = 0
        #: Every field path in declaration order, nested messages before their fields.
        self.order: list[tuple[str, ...]] = []

    def var(self, prefix: str) -> str:
        self.count += 1
        return f"{prefix}{self.count}"

    def const(self, value: Any) -> str:
        key = self.var("_k")
        self.env[key] = value
        return key

    def flatten(self, type_name: str, path: tuple[str, ...]) -> list[tuple[Any, ...]]:
        """Return the fields of a type with nested single messages inlined, in order."""
        try:
            _consts, fields = self.fielddefs[type_name]
        except KeyError:
            msg = f"unknown type {type_name}"
            raise Unsupported(msg) from None
        items: list[tuple[Any, ...]] = []
        for fname, (kind, detail) in fields:
            kind = int(kind)
            here = (*path, fname)
            if fname != _PLACEHOLDER:
                self.order.append(here)
            if kind == _NAME:
                items += self.flatten(str(detail), here)
            elif kind == _BASE:
                base = str(detail[0])
                if base == "string":
                    items.append(("string", here))
                elif base in _PRIMITIVES:
                    items.append(("prim", here, base, fname == _PLACEHOLDER))
                else:
                    raise Unsupported(base)
            else:
                (inner_kind, inner), size = detail
                fixed = size if kind == _ARRAY else None
                if int(inner_kind) == _NAME:
                    items.append(("structs", here, str(inner), fixed))
                else:
                    base = str(inner[0])
                    if base == "string":
                        items.append(("strings", here, fixed))
                    elif base in _PRIMITIVES:
                        items.append(("numbers", here, base, fixed))
                    else:
                        raise Unsupported(base)
        return items

    @staticmethod
    def grouped(items: list[tuple[Any, ...]]) -> list[tuple[Any, ...]]:
        """Merge consecutive primitive fields into runs."""
        out: list[tuple[Any, ...]] = []
        for item in items:
            if item[0] == "prim":
                if out and out[-1][0] == "run":
                    out[-1][1].append(item)
                else:
                    out.append(("run", [item]))
            else:
                out.append(item)
        return out


def _access(path: tuple[str, ...], root: str = "m") -> str:
    return root + "".join(f"[{name!r}]" for name in path)


def compile_writer(fielddefs: FieldDefs, name: str, nested: Callable[[str], Writer]) -> Writer:
    """Return ``write(message, buffer)`` appending the CDR body of ``message`` to ``buffer``.

    ``buffer`` starts with the 4-byte encapsulation header (offsets count from its end).
    ``nested`` gives the writer of an element type of a sequence.

    Raises:
        Unsupported: the type (or one it contains) has a field this codec does not compile.
    """
    env: dict[str, Any] = {"_U32": _U32, "_Z": _ZEROS, "np": np, "_bytes": _as_bytes}
    gen = _Gen(fielddefs, name, env)
    lines = ["def write(m, b):"]
    for item in gen.grouped(gen.flatten(name, ())):
        kind = item[0]
        if kind == "run":
            runs = gen.const(_runs([_PRIMITIVES[p[2]] for p in item[1]]))
            values = ", ".join("0" if p[3] else _access(p[1]) for p in item[1])
            lines.append(f"    b += {runs}[(len(b) - 4) & 7].pack({values})")
        elif kind == "string":
            lines += _write_string(_access(item[1]), "    ")
        elif kind == "numbers":
            _, path, base, fixed = item
            lines.append(f"    v = {_access(path)}")
            lines += _write_numbers(gen, base, fixed, path, "    ")
        elif kind == "strings":
            _, path, fixed = item
            lines.append(f"    v = {_access(path)}")
            lines += _write_count(fixed, path, "    ")
            lines.append("    for x in v:")
            lines += _write_string("x", "        ")
        else:  # structs
            _, path, inner, fixed = item
            element = gen.const(nested(inner))
            lines.append(f"    v = {_access(path)}")
            lines += _write_count(fixed, path, "    ")
            lines.append("    for x in v:")
            lines.append(f"        {element}(x, b)")
    if len(lines) == 1:
        lines.append("    pass")
    exec("\n".join(lines), env)
    writer: Writer = env["write"]
    return writer


def _write_string(value: str, indent: str) -> list[str]:
    return [
        f"{indent}s = {value}.encode()",
        f"{indent}b += _Z[-(len(b) - 4) & 3]",
        f"{indent}b += _U32.pack(len(s) + 1)",
        f"{indent}b += s",
        f'{indent}b += b"\\0"',
    ]


def _write_count(fixed: int | None, path: tuple[str, ...], indent: str) -> list[str]:
    if fixed is None:
        return [f"{indent}b += _Z[-(len(b) - 4) & 3]", f"{indent}b += _U32.pack(len(v))"]
    field = ".".join(path)
    return [
        f"{indent}if len(v) != {fixed}:",
        f"{indent}    raise ValueError('{field} has ' + str(len(v)) + ' elements, expected "
        f"{fixed}')",
    ]


def _write_numbers(
    gen: _Gen, base: str, fixed: int | None, path: tuple[str, ...], indent: str
) -> list[str]:
    if base in _BYTES:
        data = "_bytes(v)"
    elif base == "bool":
        data = "np.asarray(v, dtype=np.bool_).tobytes()"
    else:
        data = f"np.asarray(v, dtype={_DTYPES[base]!r}).tobytes()"
    size = _PRIMITIVES[base][1]
    lines = [f"{indent}a = {data}"]
    if fixed is None:
        lines += [
            f"{indent}b += _Z[-(len(b) - 4) & 3]",
            f"{indent}b += _U32.pack(len(a) // {size})",
        ]
    else:
        field = ".".join(path)
        lines += [
            f"{indent}if len(a) != {fixed * size}:",
            f"{indent}    raise ValueError('{field} has ' + str(len(a) // {size}) + "
            f"' elements, expected {fixed}')",
        ]
    if size > 1:
        lines.append(f"{indent}if a:")
        lines.append(f"{indent}    b += _Z[-(len(b) - 4) & {size - 1}]")
    lines.append(f"{indent}b += a")
    return lines


def _as_bytes(value: Any) -> bytes:
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value)
    return np.asarray(value, dtype=np.uint8).tobytes()


def compile_reader(fielddefs: FieldDefs, name: str, nested: Callable[[str], Reader]) -> Reader:
    """Return ``read(data, offset) -> (message, offset)`` reading one canonical message.

    ``offset`` counts from the start of ``data``, whose first 4 bytes are the encapsulation
    header. The message is what :class:`~simbridge.msgs.cdr.CdrReader` has always given: bulk
    numbers as numpy arrays, ``uint8[]`` as bytes, ``bool[]`` and strings as lists.

    Raises:
        Unsupported: the type (or one it contains) has a field this codec does not compile.
    """
    env: dict[str, Any] = {
        "_U32": _U32,
        "np": np,
        "_string": _read_string,
        "_short": _short,
    }
    gen = _Gen(fielddefs, name, env)
    lines = ["def read(d, o):"]
    leaves: dict[tuple[str, ...], str] = {}
    for item in gen.grouped(gen.flatten(name, ())):
        kind = item[0]
        if kind == "run":
            runs = gen.const(_runs([_PRIMITIVES[p[2]] for p in item[1]]))
            names = []
            for p in item[1]:
                var = gen.var("x")
                names.append(var)
                if not p[3]:
                    leaves[p[1]] = var
            lines.append(f"    s = {runs}[(o - 4) & 7]")
            lines.append(f"    {', '.join(names)}, = s.unpack_from(d, o)")
            lines.append("    o += s.size")
        elif kind == "string":
            var = leaves[item[1]] = gen.var("x")
            lines.append(f"    {var}, o = _string(d, o)")
        elif kind == "numbers":
            _, path, base, fixed = item
            var = leaves[path] = gen.var("x")
            lines += _read_count(fixed, "    ")
            size = _PRIMITIVES[base][1]
            if size > 1:
                lines.append(f"    if n: o += -(o - 4) & {size - 1}")
            lines.append(f"    _short(d, o, n * {size})")
            if base in _BYTES:
                lines.append(f"    {var} = bytes(d[o:o + n])")
            elif base == "bool":
                lines.append(f"    {var} = [c != 0 for c in d[o:o + n]]")
            else:
                dtype = _DTYPES[base]
                lines.append(f"    {var} = np.frombuffer(d, {dtype!r}, n, o).copy()")
            lines.append(f"    o += n * {size}")
        elif kind == "strings":
            _, path, fixed = item
            var = leaves[path] = gen.var("x")
            lines += _read_count(fixed, "    ")
            lines.append(f"    {var} = []")
            lines.append("    for _ in range(n):")
            lines.append("        y, o = _string(d, o)")
            lines.append(f"        {var}.append(y)")
        else:  # structs
            _, path, inner, fixed = item
            element = gen.const(nested(inner))
            var = leaves[path] = gen.var("x")
            lines += _read_count(fixed, "    ")
            lines.append(f"    {var} = []")
            lines.append("    for _ in range(n):")
            lines.append(f"        y, o = {element}(d, o)")
            lines.append(f"        {var}.append(y)")
    lines.append(f"    return {_literal(gen.order, leaves)}, o")
    exec("\n".join(lines), env)
    reader: Reader = env["read"]
    return reader


def _read_count(fixed: int | None, indent: str) -> list[str]:
    if fixed is not None:
        return [f"{indent}n = {fixed}"]
    return [
        f"{indent}o += -(o - 4) & 3",
        f"{indent}n, = _U32.unpack_from(d, o)",
        f"{indent}o += 4",
    ]


def _literal(order: list[tuple[str, ...]], leaves: dict[tuple[str, ...], str]) -> str:
    """Return the source of the nested dict literal holding the leaves (fields in order)."""
    tree: dict[str, Any] = {}
    for path in order:
        node = tree
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = leaves.get(path, {})

    def render(node: dict[str, Any]) -> str:
        parts = [f"{k!r}: {render(v) if isinstance(v, dict) else v}" for k, v in node.items()]
        return "{" + ", ".join(parts) + "}"

    return render(tree)


def _short(data: bytes, offset: int, size: int) -> None:
    if offset + size > len(data):
        msg = f"{size} bytes needed at offset {offset - 4}, the message ends at {len(data) - 4}"
        raise ValueError(msg)


def _read_string(data: bytes, offset: int) -> tuple[str, int]:
    offset += -(offset - 4) & 3
    (size,) = _U32.unpack_from(data, offset)
    offset += 4
    _short(data, offset, size)
    if size == 0:
        return "", offset
    text = bytes(data[offset : offset + size - 1]).decode()
    return text, offset + size
