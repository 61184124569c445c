"""--dds's options from the environment, and the Cyclone configuration they make."""

from __future__ import annotations

import pytest

from simbridge.errors import ConfigError
from simbridge.ros2.dds.options import DdsOptions


def test_defaults_are_a_default_ros_2_installs() -> None:
    options = DdsOptions.from_env({})
    assert (options.domain, options.distro, options.discovery) == (0, "jazzy", "SUBNET")
    assert "<Peers>" not in options.cyclone_config()


def test_domain_distro_and_discovery_range_come_from_the_environment() -> None:
    env = {"ROS_DOMAIN_ID": "17", "ROS_DISTRO": "humble", "ROS_AUTOMATIC_DISCOVERY_RANGE": "off"}
    options = DdsOptions.from_env(env)
    assert (options.domain, options.distro, options.discovery) == (17, "humble", "OFF")
    assert DdsOptions.from_env(env, distro="kilted").distro == "kilted"
    assert '<Domain id="17">' in options.cyclone_config()


def test_localhost_only_keeps_discovery_on_the_loopback_interface() -> None:
    options = DdsOptions.from_env({"ROS_LOCALHOST_ONLY": "1"})
    assert options.discovery == "LOCALHOST"
    config = options.cyclone_config()
    assert 'address="127.0.0.1"' in config
    assert '<Peer address="localhost"/>' in config
    # Jazzy's variable wins over Humble's
    env = {"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}
    assert DdsOptions.from_env(env).discovery == "SUBNET"


def test_cyclonedds_uri_comes_after_simbridges_part_as_rmw_cyclonedds_puts_it() -> None:
    """The user's CYCLONEDDS_URI (files or XML) follows simbridge's own: where both set, it wins."""
    assert DdsOptions.from_env({}).cyclone_config().count("<CycloneDDS>") == 1
    user = "<CycloneDDS><Domain><General><AllowMulticast>false</AllowMulticast></General>"
    options = DdsOptions.from_env({"CYCLONEDDS_URI": f" {user} ", "ROS_LOCALHOST_ONLY": "1"})
    own, _, rest = options.cyclone_config().partition(",")
    assert '<Peer address="localhost"/>' in own
    assert rest == user


@pytest.mark.parametrize(
    ("env", "named"),
    [
        ({"ROS_DOMAIN_ID": "x"}, "ROS_DOMAIN_ID"),
        ({"ROS_DOMAIN_ID": "233"}, "ROS_DOMAIN_ID"),
        ({"ROS_DISTRO": "rolling"}, "--ros-distro"),
        ({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LAN"}, "ROS_AUTOMATIC_DISCOVERY_RANGE"),
    ],
)
def test_a_bad_value_is_refused_naming_the_variable(env: dict[str, str], named: str) -> None:
    with pytest.raises(ConfigError, match=named):
        DdsOptions.from_env(env)


def test_writers_heartbeat_every_second_unless_the_users_configuration_says_otherwise() -> None:
    config = DdsOptions.from_env({}).cyclone_config()
    assert "<HeartbeatInterval>1s</HeartbeatInterval>" in config
    user = "<CycloneDDS><Domain><Internal><HeartbeatInterval>100ms</HeartbeatInterval>"
    user += "</Internal></Domain></CycloneDDS>"
    config = DdsOptions.from_env({"CYCLONEDDS_URI": user}).cyclone_config()
    assert config.index("1s") < config.index("100ms")  # Cyclone reads the user's last
