"""How simbridge joins a Zenoh network: the options and the session configuration.

With no options simbridge joins as an rmw_zenoh node does with its defaults (rmw_zenoh_cpp's
``DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5``): peer mode, the router at ``tcp/localhost:7447``
(retried for ever, so a router started later is found), listening on ``tcp/localhost:0`` for
peers on this host, multicast scouting off and gossip scouting through the router, domain from
``ROS_DOMAIN_ID`` (0 when unset). Then, as rmw_zenoh does:

1. ``ZENOH_SESSION_CONFIG_URI`` names a Zenoh configuration file that replaces those defaults;
2. ``ZENOH_CONFIG_OVERRIDE`` (``key=value;key=value``, JSON5 values) changes single keys;

and last ``--zenoh-connect`` / ``--zenoh-listen`` (repeatable) replace the endpoints.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from simbridge.errors import ConfigError
from simbridge.ros2.typehash import DISTROS, Distro


__all__ = [
    "DATA_QUEUE_BATCHES",
    "DEFAULT_ROUTER",
    "ZenohOptions",
    "parse_override",
    "router_config",
    "sample_limits",
    "session_config",
]

#: Where rmw_zenoh looks for its router.
DEFAULT_ROUTER = "tcp/localhost:7447"

#: Batches (64 kB each) a link's queue of data samples holds before a DROP publisher drops.
DATA_QUEUE_BATCHES = 16

# The keys of rmw_zenoh's default session configuration that differ from Zenoh's own defaults
# (the rest of that file restates Zenoh's defaults).
_SESSION_DEFAULTS: dict[str, Any] = {
    "mode": "peer",
    "connect/endpoints": [DEFAULT_ROUTER],
    "connect/timeout_ms": {"router": -1, "peer": -1, "client": 0},
    "connect/exit_on_failure": {"router": False, "peer": False, "client": True},
    "listen/endpoints": ["tcp/localhost:0"],
    "scouting/multicast/enabled": False,
    "scouting/gossip/enabled": True,
    "scouting/gossip/multihop": False,
    "scouting/gossip/target": {"router": ["router", "peer"], "peer": ["router"]},
    "timestamping/enabled": {"router": True, "peer": True, "client": True},
    "queries_default_timeout": 600000,
    # not rmw_zenoh's: a simulator publishes every robot's messages of a tick back to back
    # (300 robots: 600 samples, 0.7 MB, in a few ms), and a publisher with congestion control
    # DROP (rmw_zenoh's, for every QoS but reliable keep-all) drops what finds its queue full
    # for 1 ms. Zenoh's 2 batches of 64 kB dropped 4.5 % of the samples of 2 x 300 robots on a
    # busy 2-core host (bench.zenoh classroom); 16 batches hold a whole tick. Allocated only
    # when used (allocation "lazy")
    "transport/link/tx/queue/size/data": DATA_QUEUE_BATCHES,
}

_ROUTER_DEFAULTS: dict[str, Any] = {
    "mode": "router",
    "listen/endpoints": ["tcp/[::]:7447"],
    "scouting/multicast/enabled": False,
    "scouting/gossip/enabled": True,
    "timestamping/enabled": {"router": True, "peer": True, "client": True},
    # when samples go through the router (clients in client mode, machines that reach each
    # other only through routers), it forwards a simulator's tick in one burst too
    "transport/link/tx/queue/size/data": DATA_QUEUE_BATCHES,
}


@dataclass(frozen=True, slots=True)
class ZenohOptions:
    """What ``--zenoh`` and its options (and the environment) say.

    Attributes:
        domain: the ROS domain id (``ROS_DOMAIN_ID``; 0 when unset).
        distro: whose rmw_zenoh to match: ``humble`` (no type hashes), ``jazzy``, ``kilted``.
        connect: endpoints to connect to (empty: the configuration's, by default the router).
        listen: endpoints to listen on (empty: the configuration's).
        config_uri: a Zenoh configuration file replacing the defaults.
        override: ``key=value;...`` pairs applied to the configuration.
    """

    domain: int = 0
    distro: Distro = "jazzy"
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    config_uri: str | None = None
    override: str = ""

    @classmethod
    def from_env(
        cls,
        env: Mapping[str, str] | None = None,
        *,
        distro: str | None = None,
        connect: Sequence[str] = (),
        listen: Sequence[str] = (),
    ) -> ZenohOptions:
        """Read the environment (``ROS_DOMAIN_ID``, ``ROS_DISTRO``, ``ZENOH_*``) and options.

        Raises:
            ConfigError: the domain id or the distribution is not valid.
        """
        env = os.environ if env is None else env
        text = env.get("ROS_DOMAIN_ID", "").strip()
        try:
            domain = int(text) if text else 0
        except ValueError:
            msg = f"ROS_DOMAIN_ID='{text}' is not a number (ROS 2 uses 0-232)"
            raise ConfigError(msg) from None
        if not 0 <= domain <= 232:
            msg = f"ROS_DOMAIN_ID={domain} is out of range 0-232"
            raise ConfigError(msg)
        text = (distro or env.get("ROS_DISTRO", "") or "jazzy").strip().lower()
        chosen = next((d for d in DISTROS if d == text), None)
        if chosen is None:
            msg = (
                f"ROS distribution '{text}' is not one simbridge speaks to over Zenoh; "
                f"choose one of {', '.join(DISTROS)} (--ros-distro)"
            )
            raise ConfigError(msg)
        uri = env.get("ZENOH_SESSION_CONFIG_URI", "").strip() or None
        if uri is not None and not os.path.isfile(uri):
            msg = f"ZENOH_SESSION_CONFIG_URI='{uri}': no such file"
            raise ConfigError(msg)
        override = env.get("ZENOH_CONFIG_OVERRIDE", "").strip()
        parse_override(override)  # fail fast on a malformed one
        return cls(
            domain=domain,
            distro=chosen,
            connect=tuple(connect),
            listen=tuple(listen),
            config_uri=uri,
            override=override,
        )


def parse_override(text: str) -> list[tuple[str, str]]:
    """Split ``ZENOH_CONFIG_OVERRIDE`` into (key, JSON5 value) pairs.

    Raises:
        ConfigError: a pair has no ``=``, or an empty key or value.
    """
    pairs = []
    for part in text.split(";"):
        part = part.strip()
        if not part:
            continue
        key, sep, value = part.partition("=")
        if not sep or not key.strip() or not value.strip():
            msg = f"ZENOH_CONFIG_OVERRIDE: '{part}' is not key=value (e.g. mode=\"client\")"
            raise ConfigError(msg)
        pairs.append((key.strip(), value.strip()))
    return pairs


def _build(
    zenoh: Any,
    defaults: dict[str, Any],
    uri: str | None,
    override: str,
    connect: Sequence[str],
    listen: Sequence[str],
    limits: Mapping[str, Any] | None = None,
) -> Any:
    if uri is not None:
        try:
            config = zenoh.Config.from_file(uri)
        except Exception as err:
            msg = f"Zenoh configuration file '{uri}': {err}"
            raise ConfigError(msg) from None
    else:
        config = zenoh.Config()
        for key, value in defaults.items():
            config.insert_json5(key, json.dumps(value))
    for key, value in (limits or {}).items():
        config.insert_json5(key, json.dumps(value))
    for key, value in parse_override(override):
        try:
            config.insert_json5(key, value)
        except Exception as err:
            msg = f"ZENOH_CONFIG_OVERRIDE: cannot set {key}={value}: {err}"
            raise ConfigError(msg) from None
    if connect:
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return config


def sample_limits(max_sample_bytes: int) -> dict[str, Any]:
    """Return the session's keys that bound what one incoming message may hold.

    Zenoh itself drops, before any of simbridge's code sees them, incoming samples, queries
    and replies over ``max_sample_bytes`` (a ``low_pass_filter`` on ingress; the link stays
    up), and does not reassemble a fragmented message past twice that
    (``transport/link/rx/max_message_size``, Zenoh's default 1 GiB): a peer's 4 MB samples
    had taken a server to 600-780 MB (issue 29).
    """
    return {
        "low_pass_filter": [
            {
                "id": "simbridge_max_sample_bytes",
                "flows": ["ingress"],
                "messages": ["put", "delete", "query", "reply"],
                "key_exprs": ["**"],
                "size_limit": max_sample_bytes,
            }
        ],
        "transport/link/rx/max_message_size": max(2 * max_sample_bytes, 65_536),
    }


def session_config(zenoh: Any, options: ZenohOptions, max_sample_bytes: int | None = None) -> Any:
    """Return the ``zenoh.Config`` of simbridge's session (``zenoh``: the imported module).

    ``max_sample_bytes``: add :func:`sample_limits` (to the defaults or the file; the override
    and the endpoints still apply after them).

    Raises:
        ConfigError: the file, an override or an endpoint is refused by Zenoh.
    """
    limits = sample_limits(max_sample_bytes) if max_sample_bytes is not None else {}
    return _build(
        zenoh,
        _SESSION_DEFAULTS,
        options.config_uri,
        options.override,
        options.connect,
        options.listen,
        limits,
    )


def router_config(
    zenoh: Any, listen: Sequence[str], connect: Sequence[str], env: Mapping[str, str]
) -> Any:
    """Return the ``zenoh.Config`` of ``simbridge zenohd`` (``ZENOH_ROUTER_CONFIG_URI`` honoured).

    Raises:
        ConfigError: the file, an override or an endpoint is refused by Zenoh.
    """
    uri = env.get("ZENOH_ROUTER_CONFIG_URI", "").strip() or None
    return _build(
        zenoh, _ROUTER_DEFAULTS, uri, env.get("ZENOH_CONFIG_OVERRIDE", ""), connect, listen
    )
