"""End to end: a classroom world of named robots, driven by an unmodified roslibpy 2.1.0."""

from __future__ import annotations

import pytest

from simbridge.app.config import WorldSpec
from tests.conftest import AppFactory, ClientRunner
from tests.helpers import ws_url


pytestmark = pytest.mark.e2e

WORLD = WorldSpec.parse(
    {
        "walls": [[-5, -5, 5, -5], [5, -5, 5, 5], [5, 5, -5, 5], [-5, 5, -5, -5]],
        "robots": [{"name": "r1", "pose": [-1, 0, 0]}, {"name": "r2", "pose": [1, 0, 0]}],
    }
)


async def test_roslibpy_spawns_teleports_collides_and_kills_named_robots(
    make_app: AppFactory, run_roslibpy: ClientRunner
) -> None:
    """Namespaced topics and frames, scans that see r2, contact with r2, spawn/teleport/kill."""
    app = await make_app(world=WORLD)
    radius = app.world.params.robot.radius
    r = await run_roslibpy(ws_url(app), "fleet", {}, timeout=40)
    for topic in ("/r1/odom", "/r1/scan", "/r1/cmd_vel", "/r2/odom", "/tf", "/tf_static"):
        assert topic in r["topics"]
    assert "/odom" not in r["topics"]
    assert r["r1_frames"] == ["r1/odom", "r1/base_link"]
    assert r["r1_scan_frame"] == "r1/laser"
    assert ["r1/base_link", "r1/laser"] in r["tf_static"]
    assert ["r2/base_link", "r2/laser"] in r["tf_static"]
    assert r["r1_scan_front"] == pytest.approx(2.0 - radius, abs=1e-4)  # r2's footprint
    assert r["spawn"] == {"name": "r3"}
    assert (r["r3_start"]["x"], r["r3_start"]["y"]) == (2.0, 2.0)
    assert "overlaps another robot" in r["spawn_on_r2"]
    assert (r["r3_teleported"]["x"], r["r3_teleported"]["y"]) == (-2.0, -2.0)
    assert r["r3_teleported"]["yaw"] == pytest.approx(1.0)
    contact = r["contact"]
    assert (contact["robot"], contact["other"]) == ("r1", "r2")
    assert contact["normal"]["x"] == pytest.approx(-1.0)
    assert r["r1_after_contact"]["x"] == pytest.approx(1.0 - 2 * radius, abs=1e-6)
    # r2 is 0.105 m ahead of the laser: below range_min, so it reads range_min (REP-117)
    assert r["r1_scan_front_at_contact"] == pytest.approx(app.world.params.lidar.range_min)
    assert r["hit_logs"] == ["robot 'r1' hit robot 'r2' at (0.90, 0.00): motion into it stopped"]
    assert r["kill"] == {}
    assert not [t for t in r["topics_after_kill"] if t.startswith("/r3/")]
    assert (r["r1_after_reset"]["x"], r["r1_after_reset"]["y"]) == (-1.0, 0.0)
