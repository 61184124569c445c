"""Cyclone DDS topic types made from the registry's definitions.

Cyclone needs a type for each topic: its name (``pkg::msg::dds_::Type_``, what Fast DDS and
rmw_cyclonedds match on) and its structure (sent as XTypes type information, which another
Cyclone checks for assignability). The structure is the ROS definition's, every type
``@final`` so that Cyclone writes XCDR1 as the ROS 2 middlewares do. simbridge writes and reads
the samples' bytes itself (:mod:`simbridge.msgs.cdr`): these classes are never instantiated
on the hot path.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from typing import Any

from simbridge.msgs.registry import TypeRegistry


__all__ = ["IdlTypes", "old_binding"]

_PLACEHOLDER = "structure_needs_at_least_one_member"


def _cyclone(module: str) -> Any:
    return importlib.import_module(module)


def old_binding() -> bool:
    """Whether the Cyclone binding is 0.10, the one Debian's C library (0.10.2) takes.

    PyPI has wheels of the binding 11 for x86_64 only: on aarch64 (the Raspberry Pi image) it is
    built from the 0.10.2 sdist against Debian's ``libddsc``.
    """
    return importlib.metadata.version("cyclonedds").startswith("0.")


def _final(made: Any, *, type_information: bool) -> Any:
    final = _cyclone("cyclonedds.idl.annotations").final(made)
    if not type_information:
        # Cyclone 0.10.2 crashes (SIGSEGV in its discovery thread, after "ddsi_xt_type_init_impl
        # with invalid type object") matching a remote endpoint against the XTypes type
        # information the binding 0.10 makes of these types: send none. Peers then match on
        # the type name, as Fast DDS 2.x (rmw_fastrtps) always does.
        idl = final.__idl__
        idl.fill_type_data = idl.populate
    return final


def _dds_name(ros_name: str) -> str:
    pkg, kind, name = ros_name.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


class IdlTypes:
    """The Cyclone classes of the registry's types, made once each."""

    def __init__(self, registry: TypeRegistry) -> None:
        t = _cyclone("cyclonedds.idl.types")  # the [dds] extra

        self.registry = registry
        self._made: dict[str, Any] = {}
        self._type_information = not old_binding()
        self._primitives: dict[str, Any] = {
            "bool": bool,
            # Cyclone's Python binding 0.10 (the one Debian's C library takes) has no byte
            "byte": getattr(t, "byte", t.uint8),
            "char": t.uint8,
            "int8": t.int8,
            "uint8": t.uint8,
            "int16": t.int16,
            "uint16": t.uint16,
            "int32": t.int32,
            "uint32": t.uint32,
            "int64": t.int64,
            "uint64": t.uint64,
            "float32": t.float32,
            "float64": t.float64,
            "string": str,
        }

    def get(self, ros_name: str) -> Any:
        """Return the class of message type ``pkg/msg/Type`` (any spelling the registry takes).

        Raises:
            TypeNotFoundError: the registry does not know the type.
            KeyError: a field's primitive has no DDS type here (``wstring``).
        """
        spec = self.registry.spec(ros_name)
        found = self._made.get(spec.name)
        if found is not None:
            return found
        t = _cyclone("cyclonedds.idl.types")
        idl = _cyclone("cyclonedds.idl")
        fields: dict[str, Any] = {}
        for f in spec.fields:
            base = self.get(f.base) if f.nested else self._primitives[f.base]
            if f.base == "string" and f.string_bound:
                base = t.bounded_str[f.string_bound]
            if f.arraylen > 0:
                base = t.array[base, f.arraylen]
            elif f.arraylen == 0:
                base = t.sequence[base, f.bound] if f.bound else t.sequence[base]
            elif f.base == "string" and f.bound:
                base = t.bounded_str[f.bound]
            fields[f.name] = base
        if not fields:
            fields[_PLACEHOLDER] = t.uint8
        made = _final(
            idl.make_idl_struct(spec.name.replace("/", "_"), _dds_name(spec.name), fields),
            type_information=self._type_information,
        )
        self._made[spec.name] = made
        return made

    def wrapped(self, ros_name: str) -> Any:
        """Return the class of a service's request or response as rmw_cyclonedds sends it.

        rmw_cyclonedds writes a header before the message's own fields: the client's id (the
        last 8 bytes of its GUID) and the request's sequence number.
        """
        spec = self.registry.spec(ros_name)
        dds_name = _dds_name(spec.name)
        found = self._made.get(dds_name)
        if found is None:
            t = _cyclone("cyclonedds.idl.types")
            own = self.get(spec.name)
            fields = {"client_guid": t.uint64, "sequence_number": t.int64}
            fields.update(own.__annotations__)
            found = self.named(dds_name, fields)
        return found

    def named(self, dds_name: str, fields: dict[str, Any]) -> Any:
        """Return a ``@final`` class of DDS name ``dds_name`` with these fields (made once)."""
        found = self._made.get(dds_name)
        if found is None:
            class_name = dds_name.replace(":", "_")
            made = _cyclone("cyclonedds.idl").make_idl_struct(class_name, dds_name, fields)
            found = _final(made, type_information=self._type_information)
            self._made[dds_name] = found
        return found
