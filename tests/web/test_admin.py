from __future__ import annotations

import json
import urllib.error
import urllib.request
from typing import Any

import pytest
from websockets.asyncio.client import connect

from simbridge.app.runner import App
from simbridge.app.settings import ServerSettings
from simbridge.web.admin import AdminRefused, check_admin_token, token_from_headers
from tests.conftest import AppFactory
from tests.helpers import ROOT, http_url, wait_for, ws_url


def test_check_admin_token_refuses_without_configured_token_missing_or_wrong() -> None:
    with pytest.raises(AdminRefused, match="disabled") as off:
        check_admin_token(None, "x")
    assert off.value.status == 403
    with pytest.raises(AdminRefused, match="required") as missing:
        check_admin_token("s3cret", None)
    assert missing.value.status == 401
    with pytest.raises(AdminRefused, match="wrong"):
        check_admin_token("s3cret", "s3cre")
    check_admin_token("s3cret", "s3cret")


def test_token_from_headers() -> None:
    assert token_from_headers({"authorization": "Bearer abc"}) == "abc"
    assert token_from_headers({"x-admin-token": "def"}) == "def"
    assert token_from_headers({"authorization": "Basic zzz"}) is None


def request(app: App, path: str, body: Any = None, token: str | None = None) -> tuple[int, Any]:
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(
        http_url(app) + path, data=data, method="GET" if data is None else "POST"
    )
    if token is not None:
        req.add_header("Authorization", f"Bearer {token}")
    try:
        with urllib.request.urlopen(req, timeout=5) as res:
            return res.status, json.loads(res.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


async def test_admin_api_refuses_every_change_without_the_token(make_app: AppFactory) -> None:
    app = await make_app(admin_token="s3cret")
    for path, body in [
        ("/api/admin/params", {"changes": {"robot.mass": 3.0}}),
        ("/api/admin/motion", {"model": "dynamic"}),
        ("/api/admin/reset", {}),
    ]:
        assert (await _aio(request, app, path, body))[0] == 401
        assert (await _aio(request, app, path, body, "nope"))[0] == 403
    assert (await _aio(request, app, "/api/admin/state"))[0] == 401
    assert app.world.params.robot.mass == 1.5 and app.world.motion.name == "kinematic"


async def test_admin_is_off_without_a_configured_token(app: App) -> None:
    status, body = await _aio(request, app, "/api/admin/reset", {}, "anything")
    assert status == 403 and "disabled" in body["error"]


async def test_admin_api_with_the_token_changes_params_model_and_lists_clients(
    make_app: AppFactory,
) -> None:
    app = await make_app(admin_token="s3cret")
    status, body = await _aio(
        request, app, "/api/admin/params", {"changes": {"robot.mass": 3.0}}, "s3cret"
    )
    assert status == 200 and body["params"]["robot.mass"] == 3.0
    assert app.world.params.robot.mass == 3.0
    status, body = await _aio(
        request, app, "/api/admin/params", {"changes": {"robot.mass": -1}}, "s3cret"
    )
    assert status == 400
    assert body["error"] == "invalid value: robot.mass: must be greater than 0 (got -1.0)"
    status, body = await _aio(request, app, "/api/admin/motion", {"model": "warp"}, "s3cret")
    assert status == 400 and "kinematic" in body["error"]
    status, body = await _aio(request, app, "/api/admin/motion", {"model": "dynamic"}, "s3cret")
    assert status == 200 and app.world.motion.name == "dynamic"
    status, state = await _aio(request, app, "/api/admin/state", None, "s3cret")
    assert status == 200 and state["motion_model"] == "dynamic"
    assert state["clients"] == [] and "robot.inertia" in state["params"]
    assert state["read_only"] == ["robot.cmd_vel_stamped"]  # /cmd_vel's type: startup only
    status, body = await _aio(
        request, app, "/api/admin/params", {"changes": {"robot.cmd_vel_stamped": True}}, "s3cret"
    )
    assert status == 400 and "read-only at run time" in body["error"]


async def _aio(fn: Any, *args: Any) -> Any:
    import asyncio

    return await asyncio.to_thread(fn, *args)


async def test_admin_lists_and_releases_every_estop_with_who_latched_it(
    make_app: AppFactory,
) -> None:
    app = await make_app(world=ROOT / "config" / "worlds" / "classroom.yaml", admin_token="s3cret")
    student = app.estop.latch_for(None, "r2")  # as a connection's /r2/estop would
    status, body = await _aio(request, app, "/api/admin/estop", {"action": "latch"}, "s3cret")
    assert status == 200 and body["latched"]["global"] is True
    assert all(app.world.halted(n) for n in app.world.robots)
    _, state = await _aio(request, app, "/api/admin/state", None, "s3cret")
    assert [(e["covers"], e["by"]) for e in state["estops"]] == [
        ("r2", "the instructor (/admin)"),
        ("every robot", "the instructor (/admin)"),
    ]
    glob = state["estops"][1]["id"]
    status, _ = await _aio(
        request, app, "/api/admin/estop", {"action": "release", "id": glob}, "s3cret"
    )
    assert status == 200 and not app.world.estopped
    assert app.world.halted("r2") and not app.world.halted("r1")
    status, body = await _aio(
        request, app, "/api/admin/estop", {"action": "release", "id": glob}, "s3cret"
    )
    assert status == 400 and "released already" in body["error"]
    await _aio(request, app, "/api/admin/estop", {"action": "release_all"}, "s3cret")
    assert not app.world.halted("r2") and student.id not in app.estop.latches
    status, _ = await _aio(request, app, "/api/admin/estop", {"action": "latch"}, "wrong")
    assert status == 403 and not app.estop.latches


async def test_admin_gives_one_robot_parameters_of_its_own(make_app: AppFactory) -> None:
    app = await make_app(world=ROOT / "config" / "worlds" / "classroom.yaml", admin_token="s3cret")
    change = {"robot": "r3", "changes": {"robot.mass": 4.5}}
    status, body = await _aio(request, app, "/api/admin/robot", change, "s3cret")
    assert status == 200 and body["own"] == {"robot.mass": 4.5}
    assert app.world.robot_params("r3").mass == 4.5 and app.world.robot_params("r1").mass == 1.5
    # a shared change reaches r3's other parameters, its own mass stays
    await _aio(request, app, "/api/admin/params", {"changes": {"robot.inertia": 0.01}}, "s3cret")
    assert app.world.robot_params("r3").inertia == 0.01 and app.world.robot_params("r3").mass == 4.5
    _, state = await _aio(request, app, "/api/admin/state", None, "s3cret")
    assert state["robots"]["r3"]["own"] == {"robot.mass": 4.5}
    assert "dynamic" in state["affects"]["robot.mass"] and "robot.mass" in state["per_robot"]
    for bad, why in [
        ({"robot": "r3", "changes": {"robot.radius": 0.2}}, "shared by every robot"),
        (
            {"robot": "r3", "changes": {"robot.mass": -1}},
            "robot r3: robot.mass: must be greater than 0 (got -1)",
        ),
        ({"robot": "r9", "changes": {"robot.mass": 2}}, "no robot 'r9'"),
    ]:
        status, body = await _aio(request, app, "/api/admin/robot", bad, "s3cret")
        assert status == 400 and why in body["error"], body
    assert app.world.robot_params("r3").mass == 4.5
    await _aio(
        request, app, "/api/admin/robot", {"robot": "r3", "changes": {"robot.mass": None}}, "s3cret"
    )
    assert app.world.robot_params("r3").mass == 1.5 and not app.world.robots["r3"].overrides


async def test_admin_gives_one_robot_a_realism_profile_of_its_own(make_app: AppFactory) -> None:
    """'Group 3 drives the worn robot': realism.* on r3 only; a bad value is refused by name."""
    app = await make_app(world=ROOT / "config" / "worlds" / "classroom.yaml", admin_token="s3cret")
    worn = {"realism.enabled": True, "realism.slip": 0.2, "realism.motor_time_constant": 0.3}
    status, body = await _aio(
        request, app, "/api/admin/robot", {"robot": "r3", "changes": worn}, "s3cret"
    )
    assert status == 200 and body["own"] == worn
    real = app.world.robots["r3"].realism(app.world.params.realism)
    assert real is not None and real.slip == 0.2
    assert app.world.robots["r1"].realism(app.world.params.realism) is None
    _, state = await _aio(request, app, "/api/admin/state", None, "s3cret")
    assert state["robots"]["r3"]["own"] == worn and "realism.slip" in state["per_robot"]
    assert "/ground_truth" in state["affects"]["realism.slip"]
    bad = {"robot": "r3", "changes": {"realism.slip": 1.5, "robot.mass": 2.0}}
    status, body = await _aio(request, app, "/api/admin/robot", bad, "s3cret")
    assert status == 400 and "realism.slip: must be less than or equal to 1" in body["error"]
    assert (
        app.world.robots["r3"].realism_own["slip"] == 0.2 and not app.world.robots["r3"].overrides
    )


async def test_admin_without_a_simulation_lists_the_clients_and_refuses_the_world_by_name() -> None:
    """--no-sim: the console's state (its clients, no robot), the world's changes refused."""
    settings = ServerSettings(host="127.0.0.1", port=0, http_port=0, admin_token="s3cret")
    app = App(settings, no_sim=True)
    await app.start()
    try:
        async with connect(ws_url(app)):
            await wait_for(lambda: len(app.server.clients) == 1)
            status, state = await _aio(request, app, "/api/admin/state", None, "s3cret")
        assert status == 200, state
        assert [c["robots"] for c in state["clients"]] == [[]]
        assert state["robots"] == {} and state["params"] == {} and state["estops"] == []
        status, body = await _aio(request, app, "/api/admin/estop", {"action": "latch"}, "s3cret")
        assert status == 400 and body["error"] == (
            "this server has no e-stop (it runs without a simulation)"
        )
        status, body = await _aio(request, app, "/api/admin/reset", {}, "s3cret")
        assert status == 400 and "no /reset" in body["error"]
    finally:
        await app.stop()
