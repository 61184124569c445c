"""CDR encoding and decoding of canonical messages, compiled to Python once per type.

rosbags' serializer needs its own message objects: building them from a canonical ``dict`` and
serializing took 140 us for an ``Odometry`` (its 21 nested objects), which at 20 Hz times 30
robots is most of what publishing to ROS 2 costs. Here each type becomes one generated
function that writes (or reads) the bytes straight from (into) the canonical form. Writing,
consecutive fields that are primitives, strings or arrays of primitives, nested ones included,
are packed by one ``struct`` call, whose format is made for the segment's alignment and the
lengths of its strings and arrays on first use and then kept: an ``Odometry``, a ``LaserScan``
or a ``TransformStamped`` is one call, header included (1.4 us for an ``Odometry``, 2.8 us
field by field). Bulk arrays go through numpy (``tobytes``; an array of the field's own dtype
without ``np.asarray``: 1.2 us for an ``Odometry``, ``bench/cdr.py``), and the elements of a
sequence that one pack writes (a ``TFMessage``'s transforms) are written in the sequence's
loop, not by a call each. Reading, consecutive primitives are unpacked by one precompiled
``struct`` per alignment of their start.

The bytes are exactly rosbags' (the tests compare them type by type): little-endian plain CDR
(XCDR1) after the 4-byte encapsulation header, each primitive aligned to its size from the
start of the body, a string as ``uint32`` length (with its NUL) then the bytes and NUL, a
sequence as ``uint32`` count then its elements, an empty message as one ``uint8``. Types with
``wstring`` are not compiled (:class:`Unsupported`): the caller uses rosbags for them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np


__all__ = ["LAYOUTS_KEPT", "Unsupported", "compile_reader", "compile_serializer", "compile_writer"]

#: A registry's ``fielddefs``: name -> (constants, [(field, (nodetype, detail))]), as rosbags'.
FieldDefs = Any
Writer = Callable[[Any, bytearray], None]
Serializer = Callable[[Any], bytes]
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
#: The encapsulation header of little-endian plain CDR.
_HEADER = b"\x00\x01\x00\x00"
#: Struct layouts kept per segment of a type (see :class:`_Layouts`).
LAYOUTS_KEPT = 256


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
    writer: Writer = _compile_writer(fielddefs, name, nested)["write"]
    return writer


def compile_serializer(
    fielddefs: FieldDefs, name: str, nested: Callable[[str], Writer]
) -> Serializer:
    """Return ``serialize(message) -> bytes``: the encapsulation header and the CDR body.

    A type without sequences of messages or strings is packed by one ``struct`` call, the
    header included; the others are written into a buffer by :func:`compile_writer`'s code.

    Raises:
        Unsupported: the type (or one it contains) has a field this codec does not compile.
    """
    serializer: Serializer = _compile_writer(fielddefs, name, nested)["serialize"]
    return serializer


class _Layouts:
    """The structs packing one segment, by its start offset (mod 8) and variable lengths.

    A segment is a run of consecutive fields that one ``struct`` packs: primitives, strings
    and arrays of primitives (as bytes, ``Ns``); its format depends on where it starts (the
    alignment) and on the byte lengths of its strings and sequences, so it is made on first
    use and kept (:data:`LAYOUTS_KEPT` of them at most: strings of ever new lengths do not grow
    the cache without bound).
    """

    def __init__(self, spec: list[tuple[Any, ...]], *, header: bool) -> None:
        self.spec = spec
        self.header = header
        self.cache: dict[tuple[int, ...], struct.Struct] = {}

    def __call__(self, key: tuple[int, ...]) -> struct.Struct:
        if len(self.cache) >= LAYOUTS_KEPT:
            self.cache.clear()
        found = self.cache[key] = struct.Struct(self.format(key))
        return found

    def format(self, key: tuple[int, ...]) -> str:
        """Return the struct format for ``key``: (start offset mod 8, lengths...)."""
        offset = key[0]
        lengths = iter(key[1:])
        fmt = ["<4s" if self.header else "<"]

        def align(size: int) -> None:
            nonlocal offset
            pad = -offset % size
            if pad:
                fmt.append(f"{pad}x")
                offset += pad

        for part in self.spec:
            kind = part[0]
            if kind == "prim":
                _, code, size = part
                align(size)
                fmt.append(code)
                offset += size
            elif kind == "string":  # uint32 length with the NUL, the bytes, the NUL
                n = next(lengths)
                align(4)
                fmt.append(f"I{n}sx")
                offset += 4 + n + 1
            else:  # "sequence" (uint32 count, then the elements) or "array": bytes
                _, size, fixed = part
                n = next(lengths) if fixed is None else fixed
                if fixed is None:
                    align(4)
                    fmt.append("I")
                    offset += 4
                if n:
                    align(size)
                fmt.append(f"{n}s")
                offset += n
        return "".join(fmt)


def _compile_writer(
    fielddefs: FieldDefs, name: str, nested: Callable[[str], Writer]
) -> dict[str, Any]:
    """Generate ``write(m, b)`` and ``serialize(m)`` of one type; return the namespace."""
    env: dict[str, Any] = {
        "_U32": _U32,
        "_Z": _ZEROS,
        "np": np,
        "_ND": np.ndarray,
        "_bytes": _as_bytes,
        "_H": _HEADER,
    }
    gen = _Gen(fielddefs, name, env)
    body = _segments(gen.flatten(name, ()))
    paths = _Paths(gen, _leaves(body))
    lines = ["def write(m, b):"]
    lines += _write_body(gen, paths, body, nested) or ["    pass"]
    paths.reset()
    lines.append("def serialize(m):")
    if len(body) == 1 and isinstance(body[0], list):  # one segment: one pack, header included
        lines += _write_segment(gen, paths, body[0], "    ", header=True)
    else:  # write's code again, not a call of it
        lines.append("    b = bytearray(_H)")
        lines += _write_body(gen, paths, body, nested)
        lines.append("    return bytes(b)")
    exec("\n".join(lines), env)
    return env


#: A type's fields for the writer: segments (lists of fields one ``struct`` packs) and, between
#: them, sequences and arrays of strings or of messages.
_Body = list[list[tuple[Any, ...]] | tuple[Any, ...]]


def _segments(items: list[tuple[Any, ...]]) -> _Body:
    """Group consecutive primitives, strings and arrays of primitives into segments."""
    body: _Body = []
    for item in items:
        if item[0] not in ("prim", "string", "numbers"):
            body.append(item)
        elif body and isinstance(body[-1], list):
            body[-1].append(item)
        else:
            body.append([item])
    return body


def _leaves(body: _Body) -> list[tuple[str, ...]]:
    return [item[1] for part in body for item in (part if isinstance(part, list) else [part])]


def _write_body(
    gen: _Gen, paths: _Paths, body: _Body, nested: Callable[[str], Writer]
) -> list[str]:
    """Return the lines appending the CDR of ``body``'s fields of ``m`` to ``b``."""
    lines: list[str] = []
    for part in body:
        if isinstance(part, list):
            lines += _write_segment(gen, paths, part, "    ", header=False)
            continue
        kind = part[0]
        if kind == "strings":
            _, path, fixed = part
            lines.append(f"    v = {paths.expr(path, lines)}")
            lines += _write_count(fixed, path, "    ")
            lines.append("    for x in v:")
            lines += _write_string("x", "        ")
            continue
        _, path, inner, fixed = part  # structs
        lines.append(f"    v = {paths.expr(path, lines)}")
        lines += _write_count(fixed, path, "    ")
        lines.append("    for x in v:")
        element = _segments(_flat(gen, inner))
        if len(element) == 1 and isinstance(element[0], list):
            # an element that one pack writes (a TransformStamped, a Point): its code in the
            # loop, not a call per element (a /tf of 30 transforms: 30 calls fewer)
            inline = _Paths(gen, _leaves(element), root="x")
            lines += _write_segment(gen, inline, element[0], "        ", header=False)
        else:
            lines.append(f"        {gen.const(nested(inner))}(x, b)")
    return lines


def _flat(gen: _Gen, name: str) -> list[tuple[Any, ...]]:
    """Return the fields of an element type (paths from the element), as :meth:`_Gen.flatten`."""
    order = len(gen.order)
    items = gen.flatten(name, ())
    del gen.order[order:]  # the reader's field order is the top type's only
    return items


class _Paths:
    """Field accesses of the generated code: a dict reached by two leaves or more is a local."""

    def __init__(self, gen: _Gen, leaves: list[tuple[str, ...]], root: str = "m") -> None:
        self.gen = gen
        #: The variable holding the message the paths start from.
        self.root = root
        self.shared: set[tuple[str, ...]] = set()
        seen: set[tuple[str, ...]] = set()
        for path in leaves:
            for end in range(1, len(path)):
                prefix = path[:end]
                if prefix in seen:
                    self.shared.add(prefix)
                seen.add(prefix)
        self.bound: dict[tuple[str, ...], str] = {}

    def reset(self) -> None:
        """Forget the locals (a new function begins)."""
        self.bound = {}

    def expr(self, path: tuple[str, ...], lines: list[str], indent: str = "    ") -> str:
        """Return the expression of ``path``, binding the shared dicts on it first (to lines)."""
        root, start = self.root, 0
        for end in range(1, len(path)):
            prefix = path[:end]
            if prefix not in self.shared:
                continue
            var = self.bound.get(prefix)
            if var is None:
                var = self.bound[prefix] = self.gen.var("d")
                lines.append(f"{indent}{var} = {_access(path[start:end], root)}")
            root, start = var, end
        return _access(path[start:], root)


def _write_segment(
    gen: _Gen, paths: _Paths, items: list[tuple[Any, ...]], indent: str, *, header: bool
) -> list[str]:
    """Return the lines packing a segment with one struct (appended to ``b``, or returned)."""
    lines: list[str] = []
    spec: list[tuple[Any, ...]] = []
    args: list[str] = ["_H"] if header else []
    lengths: list[str] = []
    for item in items:
        kind = item[0]
        if kind == "prim":
            _, path, base, placeholder = item
            spec.append(("prim", *_PRIMITIVES[base]))
            args.append("0" if placeholder else paths.expr(path, lines, indent))
        elif kind == "string":
            var = gen.var("s")
            lines.append(f"{indent}{var} = {paths.expr(item[1], lines, indent)}.encode()")
            spec.append(("string",))
            args += [f"len({var}) + 1", var]
            lengths.append(f"len({var})")
        else:  # numbers
            _, path, base, fixed = item
            size = _PRIMITIVES[base][1]
            var = gen.var("a")
            value = paths.expr(path, lines, indent)
            lines += _numbers(gen, base, var, value, indent)
            if fixed is None:
                spec.append(("sequence", size, None))
                args += [f"len({var}) // {size}", var]
                lengths.append(f"len({var})")
            else:
                spec.append(("array", size, fixed * size))
                args.append(var)
                field = ".".join(path)
                lines += [
                    f"{indent}if len({var}) != {fixed * size}:",
                    f"{indent}    raise ValueError('{field} has ' + str(len({var}) // {size}) + "
                    f"' elements, expected {fixed}')",
                ]
    layouts = _Layouts(spec, header=header)
    packed = ", ".join(args)
    if not lengths:  # a fixed layout: one struct per start offset, made now
        if header:
            lines.append(f"{indent}return {gen.const(layouts((0,)))}.pack({packed})")
        else:
            structs = gen.const(tuple(layouts((start,)) for start in range(8)))
            lines.append(f"{indent}b += {structs}[(len(b) - 4) & 7].pack({packed})")
        return lines
    cache, make = gen.const(layouts.cache), gen.const(layouts)
    start = "0" if header else "(len(b) - 4) & 7"
    lines.append(f"{indent}k = ({start}, {', '.join(lengths)})")
    lines.append(f"{indent}s = {cache}.get(k) or {make}(k)")
    if header:
        lines.append(f"{indent}return s.pack({packed})")
    else:
        lines.append(f"{indent}b += s.pack({packed})")
    return lines


def _numbers(gen: _Gen, base: str, var: str, value: str, indent: str) -> list[str]:
    """Return the lines setting ``var`` to an array of primitives as its little-endian bytes.

    A numpy array of the field's own dtype (what the converter and the simulation make) is
    written as it is, without ``np.asarray``'s look at its argument and dtype.
    """
    if base in _BYTES:
        return [f"{indent}{var} = _bytes({value})"]
    dtype = gen.const(np.dtype(np.bool_ if base == "bool" else _DTYPES[base]))
    return [
        f"{indent}{var} = {value}",
        f"{indent}{var} = {var}.tobytes() if type({var}) is _ND and {var}.dtype is {dtype} "
        f"else np.asarray({var}, {dtype}).tobytes()",
    ]


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
