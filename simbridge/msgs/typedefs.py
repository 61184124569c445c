"""rosapi TypeDefs (``rosapi_msgs/msg/TypeDef``) of a message type, as ROS 2 rosapi builds them.

Rules (protocol reference section 4.1): ``type`` is ``pkg/Type`` and equals the ``fieldtypes``
string of every field that refers to it (roslibjs ``decodeTypeDefs`` matches nested entries by
that equality); primitive field types use the IDL names rclpy reports (``double``, ``float``,
``boolean``, ``octet``...); ``fieldarraylen`` is -1 for a scalar, 0 for a sequence and N for a
fixed array; ``examples`` are ``"[]"`` for arrays, ``"{}"`` for messages, else the default as
Python prints it. The first entry is the requested type, then every nested type once,
depth-first.
"""

from __future__ import annotations

from typing import Any

from simbridge.msgs.registry import FieldSpec, TypeRegistry, short_type


__all__ = ["IDL_NAMES", "typedefs"]

#: .msg primitive names -> the IDL names rclpy reports.
IDL_NAMES: dict[str, str] = {
    "bool": "boolean",
    "byte": "octet",
    "char": "uint8",
    "float32": "float",
    "float64": "double",
}

_EXAMPLES = {"boolean": "False", "float": "0.0", "double": "0.0", "string": "", "wstring": ""}


def _fieldtype(field: FieldSpec) -> str:
    if field.nested:
        return short_type(field.base)
    return IDL_NAMES.get(field.base, field.base)


def _example(field: FieldSpec, fieldtype: str) -> str:
    if field.arraylen != -1:
        return "[]"
    if field.nested:
        return "{}"
    return _EXAMPLES.get(fieldtype, "0")


def typedefs(registry: TypeRegistry, name: str) -> list[dict[str, Any]]:
    """Return the TypeDef list of message type ``name`` (any accepted spelling).

    Raises:
        TypeNotFoundError: the type is unknown.
    """
    out: list[dict[str, Any]] = []
    seen: set[str] = set()

    def visit(typename: str) -> None:
        spec = registry.spec(typename)
        if spec.name in seen:
            return
        seen.add(spec.name)
        types = [_fieldtype(f) for f in spec.fields]
        out.append(
            {
                "type": short_type(spec.name),
                "fieldnames": [f.name for f in spec.fields],
                "fieldtypes": types,
                "fieldarraylen": [f.arraylen for f in spec.fields],
                "examples": [_example(f, t) for f, t in zip(spec.fields, types, strict=True)],
                "constnames": [c[0] for c in spec.constants],
                "constvalues": [str(c[2]) for c in spec.constants],
            }
        )
        for field in spec.fields:
            if field.nested:
                visit(field.base)

    visit(name)
    return out
