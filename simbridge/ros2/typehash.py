"""Type hashes in rmw_zenoh's key expressions, per ROS 2 distribution.

Jazzy and later put the RIHS01 hash of the type description (REP-2011) in every key expression
and token; Humble's rmw_zenoh has no type hashes and writes ``TypeHashNotSupported``. A
subscriber matches the data key exactly, so a wrong hash means silence, not an error.

Messages are hashed by rosbags' ``Typestore.hash_rihs01`` over the registry's definitions
(:attr:`TypeRegistry.fielddefs`: the shipped ones and simbridge's own), so a ``--zenoh`` run does
not build rosbags' type store for it. A service's hash covers a type with
three fields, ``request_message``, ``response_message`` and ``event_message``, the last of type
``pkg/srv/Foo_Event`` (``service_msgs/ServiceEventInfo info``, ``Foo_Request[<=1] request``,
``Foo_Response[<=1] response``). rosidl describes ``ServiceEventInfo.client_gid`` as
``uint8[16]`` where rosbags' definition has ``char[16]``, so the event types are described here
rather than taken from rosbags (``example_interfaces/srv/AddTwoInts`` must come out
``RIHS01_e118de6b...``, as ``ros2 service info`` shows).
"""

from __future__ import annotations

from collections import ChainMap
from typing import Any, Literal

from rosbags.typesys.base import Nodetype  # type: ignore[attr-defined]
from rosbags.typesys.store import Typestore

from simbridge.msgs import TypeRegistry, normalize_type


__all__ = ["DISTROS", "NO_HASH", "Distro", "TypeHasher"]

Distro = Literal["humble", "jazzy", "kilted"]
#: The distributions whose rmw_zenoh simbridge speaks.
DISTROS: tuple[Distro, ...] = ("humble", "jazzy", "kilted")
#: What Humble's rmw_zenoh writes where later distributions put the RIHS01 hash.
NO_HASH = "TypeHashNotSupported"

_EVENT_INFO = "service_msgs/msg/ServiceEventInfo"
_TIME = "builtin_interfaces/msg/Time"


class _Defs:
    """The ``fielddefs`` view ``Typestore.hash_rihs01`` reads, with extra definitions on top."""

    def __init__(self, fielddefs: Any, extra: dict[str, Any]) -> None:
        self.fielddefs = ChainMap(extra, fielddefs)


class TypeHasher:
    """The type hash each key expression carries, for one distribution (cached)."""

    def __init__(self, registry: TypeRegistry, distro: Distro) -> None:
        #: Where the definitions come from.
        self.registry = registry
        #: The distribution whose rmw_zenoh is matched.
        self.distro: Distro = distro
        self._cache: dict[str, str] = {}

    def message(self, type_name: str) -> str:
        """Return the hash field for a message type.

        Raises:
            TypeNotFoundError: the type is unknown.
        """
        if self.distro == "humble":
            return NO_HASH
        canonical = self.registry.spec(type_name).name
        found = self._cache.get(canonical)
        if found is None:
            defs = _Defs(self.registry.fielddefs, {})
            found = str(Typestore.hash_rihs01(defs, canonical))  # type: ignore[arg-type]
            self._cache[canonical] = found
        return found

    def service(self, type_name: str) -> str:
        """Return the hash field for a service type.

        Raises:
            TypeNotFoundError: the type is unknown.
        """
        if self.distro == "humble":
            return NO_HASH
        canonical = normalize_type(type_name, "srv")
        found = self._cache.get(canonical)
        if found is None:
            request, response = self.registry.service(canonical)
            found = self._cache[canonical] = _service_hash(
                self.registry, canonical, request, response
            )
        return found


def _service_hash(registry: TypeRegistry, name: str, request: str, response: str) -> str:
    event = f"{name}_Event"
    extra: dict[str, Any] = {
        name: (
            [],
            [
                ("request_message", (Nodetype.NAME, request)),
                ("response_message", (Nodetype.NAME, response)),
                ("event_message", (Nodetype.NAME, event)),
            ],
        ),
        event: (
            [],
            [
                ("info", (Nodetype.NAME, _EVENT_INFO)),
                ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, request), 1))),
                ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, response), 1))),
            ],
        ),
        _EVENT_INFO: (
            [],
            [
                ("event_type", (Nodetype.BASE, ("uint8", 0))),
                ("stamp", (Nodetype.NAME, _TIME)),
                ("client_gid", (Nodetype.ARRAY, ((Nodetype.BASE, ("uint8", 0)), 16))),
                ("sequence_number", (Nodetype.BASE, ("int64", 0))),
            ],
        ),
    }
    defs = _Defs(registry.fielddefs, extra)
    return str(Typestore.hash_rihs01(defs, name))  # type: ignore[arg-type]
