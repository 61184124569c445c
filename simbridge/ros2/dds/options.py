"""How simbridge joins a DDS domain: the options (from the environment) and Cyclone's config.

A ROS 2 node reads ``ROS_DOMAIN_ID`` (0 when unset), Humble's ``ROS_LOCALHOST_ONLY=1`` and, from
Iron on, ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (``SUBNET``, the default: multicast discovery on the
host's network; ``LOCALHOST``: this host only; ``OFF``: no discovery at all;
``SYSTEM_DEFAULT``: the DDS library's own). simbridge reads them the same way and says them
to Cyclone DDS as rmw_cyclonedds does (``rmw_init.cpp``: localhost means the loopback interface,
no multicast and the local participant indices as unicast peers). ``CYCLONEDDS_URI`` (Cyclone's
own configuration: files or XML, comma-separated) comes after simbridge's part, as
rmw_cyclonedds puts it after its own, so that where both set something the user's wins.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from simbridge.errors import ConfigError


__all__ = ["DISCOVERY_RANGES", "DdsOptions", "DiscoveryRange"]

DiscoveryRange = Literal["SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT"]
DISCOVERY_RANGES: tuple[DiscoveryRange, ...] = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
_DISTROS = ("humble", "jazzy", "kilted")


@dataclass(frozen=True, slots=True)
class DdsOptions:
    """What ``--dds`` and the environment say.

    Attributes:
        domain: the ROS domain id (``ROS_DOMAIN_ID``; 0 when unset).
        distro: whose middlewares to match: ``humble`` (24-byte GIDs, no type hashes),
            ``jazzy`` or ``kilted`` (16-byte GIDs, RIHS01 type hashes in USER_DATA).
        discovery: the automatic discovery range (see the module's docstring).
        cyclone_uri: ``CYCLONEDDS_URI``, Cyclone's configuration of the user ("" when unset).
    """

    domain: int = 0
    distro: str = "jazzy"
    discovery: DiscoveryRange = "SUBNET"
    cyclone_uri: str = ""

    @classmethod
    def from_env(
        cls, env: Mapping[str, str] | None = None, *, distro: str | None = None
    ) -> DdsOptions:
        """Read the ROS 2 variables (domain, distribution, discovery range) and CYCLONEDDS_URI.

        Raises:
            ConfigError: a value is not valid (the message names the variable).
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
        chosen = distro or env.get("ROS_DISTRO", "").strip().lower() or "jazzy"
        if chosen not in _DISTROS:
            msg = f"ROS distribution '{chosen}' is not one of {', '.join(_DISTROS)} (--ros-distro)"
            raise ConfigError(msg)
        discovery: DiscoveryRange = "SUBNET"
        text = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
        if text:
            if text not in DISCOVERY_RANGES:
                msg = (
                    f"ROS_AUTOMATIC_DISCOVERY_RANGE='{text}' is not one of "
                    f"{', '.join(DISCOVERY_RANGES)}"
                )
                raise ConfigError(msg)
            discovery = text
        elif env.get("ROS_LOCALHOST_ONLY", "").strip() == "1":
            discovery = "LOCALHOST"  # Humble's variable (Jazzy still reads it when unset)
        uri = env.get("CYCLONEDDS_URI", "").strip()
        return cls(domain=domain, distro=chosen, discovery=discovery, cyclone_uri=uri)

    def cyclone_config(self) -> str:
        """Return the Cyclone DDS configuration (XML) of these options.

        No ``Tracing`` of its own: Cyclone traces nothing by default (and makes no
        ``cyclonedds.log``); the DDS link reads the domain's log (errors, warnings, each sample
        Cyclone refuses) from a pipe (``trace.py``).
        """
        parts: list[str] = []
        # a writer's heartbeats every second (Fast DDS's default period is 3 s), not Cyclone's
        # 100 ms: with 100 ms every /scan (10 Hz, so 100 ms after its last write) asked each
        # reader for an acknowledgement and every /odom writer sent 10 heartbeats a second, all
        # of them answered: Cyclone's threads took 0.5-0.6 % of a core for 30 robots to one
        # subscriber, 0.15-0.2 % with 1 s (6 of the 23 us a sample cost in all, by itself). A
        # lost sample is still asked for again at once: each sample carries a heartbeat too
        parts.append("<Internal><HeartbeatInterval>1s</HeartbeatInterval></Internal>")
        if self.discovery == "LOCALHOST":
            # the loopback interface only; multicast on it where lo has it (a Fast DDS node's
            # default discovery), and the local participant indices as unicast peers
            parts.append(
                '<General><Interfaces><NetworkInterface address="127.0.0.1" multicast="true"/>'
                "</Interfaces></General>"
                "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
                "<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
                '<Peers><Peer address="localhost"/></Peers></Discovery>'
            )
        elif self.discovery == "OFF":
            parts.append(
                '<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
                "<AllowMulticast>false</AllowMulticast></General>"
                "<Discovery><ParticipantIndex>none</ParticipantIndex></Discovery>"
            )
        own = f'<CycloneDDS><Domain id="{self.domain}">{"".join(parts)}</Domain></CycloneDDS>'
        return f"{own},{self.cyclone_uri}" if self.cyclone_uri else own
