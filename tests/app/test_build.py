"""The composition root: what a server and the headless API are made of, and in what order."""

from __future__ import annotations

from pathlib import Path

import pytest

from simbridge.app.build import build, build_headless
from simbridge.app.settings import ServerSettings
from simbridge.tools.bag import BagError


def _settings() -> ServerSettings:
    return ServerSettings(host="127.0.0.1", port=0, http_port=None)


def _health() -> dict[str, object]:
    return {"status": "ok"}


def test_server_and_headless_offer_the_same_graph() -> None:
    server = build(_settings(), health=_health).core.graph
    headless = build_headless().graph
    assert sorted(server.topics.topics) == sorted(headless.topics.topics)
    assert sorted(server.services.services) == sorted(headless.services.services)
    assert sorted(server.nodes) == sorted(headless.nodes)


def test_the_hooks_run_in_one_list_made_once_in_the_builders_order() -> None:
    parts = build(_settings(), health=_health)
    core = parts.core
    robot = core.robot
    assert core.steps.hooks == [robot.tf_republisher.tick, robot.safety.tick, core.grader.tick]
    assert core.steps.loop_hooks == []  # no front end but rosbridge, no recorder


def test_the_builder_wires_the_parts_to_each_other() -> None:
    """What no part does to another itself: the server's broadcast, the guard, the peers."""
    parts = build(_settings(), health=_health)
    graph, robot = parts.core.graph, parts.core.robot
    assert parts.rosbridge.subscribers.send_many == parts.server.send_many
    assert graph.access.guarded and parts.guard.peer_connected in graph.on_connect
    assert robot.safety is not None and robot.safety.peer_lost in graph.on_lost


def test_no_sim_builds_no_robot_no_clock_no_estop_and_no_roles() -> None:
    """--no-sim builds the world's graph without what simulates; nothing is taken off after."""
    core = build(_settings(), health=_health, no_sim=True).core
    graph, robot = core.graph, core.robot
    assert "/virtual_robot" not in graph.nodes and "/sim" not in graph.nodes
    services = set(graph.services.services)
    assert not {"/reset", "/sim/step", "/spawn", "/estop", "/simbridge/access"} & services
    assert {"/republish_tfs", "/rosapi/topics", "/simbridge/grade/start"} <= services
    assert not {"/clock", "/tf", "/odom", "/walls", "/estop/state"} & set(graph.topics.topics)
    assert (robot.bridge, robot.simclock, robot.estop, robot.roles, robot.safety) == (None,) * 5
    assert graph.params.nodes == {}
    before = core.world.steps
    core.steps.tick(1.0)  # nothing to step; the rest of the tick runs
    assert core.world.steps == before


def test_an_existing_record_directory_is_refused_before_any_port(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="exists already"):
        build(_settings(), health=_health, record=(tmp_path, None))


def test_the_record_bag_is_made_at_start_not_when_built(tmp_path: Path) -> None:
    parts = build(_settings(), health=_health, record=(tmp_path / "bag", None))
    assert parts.recorder is not None and not (tmp_path / "bag").exists()
    assert parts.core.steps.loop_hooks == [parts.recorder.tick]
