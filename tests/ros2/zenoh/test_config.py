"""Options and session configuration of --zenoh (rmw_zenoh's defaults and overrides)."""

from __future__ import annotations

import json

import pytest

from simbridge.errors import ConfigError
from simbridge.ros2.zenoh.config import (
    DATA_QUEUE_BATCHES,
    ZenohOptions,
    parse_override,
    router_config,
    session_config,
)


zenoh = pytest.importorskip("zenoh")


def test_defaults_are_rmw_zenohs_domain_0_jazzy() -> None:
    options = ZenohOptions.from_env({})
    assert (options.domain, options.distro) == (0, "jazzy")
    config = json.loads(str(session_config(zenoh, options)))
    assert config["mode"] == "peer"
    assert config["connect"]["endpoints"] == ["tcp/localhost:7447"]
    assert config["scouting"]["multicast"]["enabled"] is False


def test_a_tick_of_samples_fits_the_data_queue_unless_overridden() -> None:
    config = json.loads(str(session_config(zenoh, ZenohOptions.from_env({}))))
    assert config["transport"]["link"]["tx"]["queue"]["size"]["data"] == DATA_QUEUE_BATCHES
    assert config["transport"]["link"]["tx"]["queue"]["size"]["data_low"] == 2  # Zenoh's
    env = {"ZENOH_CONFIG_OVERRIDE": "transport/link/tx/queue/size/data=2"}
    config = json.loads(str(session_config(zenoh, ZenohOptions.from_env(env))))
    assert config["transport"]["link"]["tx"]["queue"]["size"]["data"] == 2
    # the router forwards a tick's burst when samples go through it
    config = json.loads(str(router_config(zenoh, [], [], {})))
    assert config["mode"] == "router"
    assert config["transport"]["link"]["tx"]["queue"]["size"]["data"] == DATA_QUEUE_BATCHES
    config = json.loads(str(router_config(zenoh, [], [], env)))
    assert config["transport"]["link"]["tx"]["queue"]["size"]["data"] == 2


def test_environment_sets_domain_distro_and_overrides() -> None:
    env = {
        "ROS_DOMAIN_ID": "7",
        "ROS_DISTRO": "humble",
        "ZENOH_CONFIG_OVERRIDE": 'mode="client";connect/endpoints=["tcp/10.0.0.1:7447"]',
    }
    options = ZenohOptions.from_env(env, listen=["tcp/127.0.0.1:0"])
    assert (options.domain, options.distro) == (7, "humble")
    config = json.loads(str(session_config(zenoh, options)))
    assert config["mode"] == "client"
    assert config["connect"]["endpoints"] == ["tcp/10.0.0.1:7447"]
    assert config["listen"]["endpoints"] == ["tcp/127.0.0.1:0"]


def test_the_command_line_beats_the_environment() -> None:
    options = ZenohOptions.from_env(
        {"ROS_DISTRO": "humble"}, distro="kilted", connect=["tcp/1.2.3.4:7447"]
    )
    assert options.distro == "kilted"
    config = json.loads(str(session_config(zenoh, options)))
    assert config["connect"]["endpoints"] == ["tcp/1.2.3.4:7447"]


@pytest.mark.parametrize(
    ("env", "message"),
    [
        ({"ROS_DOMAIN_ID": "x"}, "ROS_DOMAIN_ID='x' is not a number"),
        ({"ROS_DOMAIN_ID": "300"}, "out of range"),
        ({"ROS_DISTRO": "rolling"}, "choose one of humble, jazzy, kilted"),
        ({"ZENOH_CONFIG_OVERRIDE": "mode"}, "is not key=value"),
        ({"ZENOH_SESSION_CONFIG_URI": "/nonexistent.json5"}, "no such file"),
    ],
)
def test_bad_settings_fail_fast_naming_the_setting(env: dict[str, str], message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        ZenohOptions.from_env(env)


def test_a_session_config_file_replaces_the_defaults(tmp_path: object) -> None:
    from pathlib import Path

    path = Path(str(tmp_path)) / "session.json5"
    path.write_text('{mode: "client", connect: {endpoints: ["tcp/127.0.0.1:9"]}}')
    options = ZenohOptions.from_env({"ZENOH_SESSION_CONFIG_URI": str(path)})
    config = json.loads(str(session_config(zenoh, options)))
    assert config["mode"] == "client"
    assert parse_override(" a=1 ; b=[2] ;") == [("a", "1"), ("b", "[2]")]
