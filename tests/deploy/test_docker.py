"""Docker smoke test: the Dockerfile and docker-compose.yml, built and run for real.

The course's commands (``up -d``, ``ps``, ``logs -f ros2-web-bridge``, ``down``) run with the
legacy ``docker-compose`` (v1, Debian's package) and with ``docker compose`` (v2), on the
compose file as written plus tests/deploy/compose.test.yml (local images, fast healthchecks, the
two ports published on free 127.0.0.1 ports). Skipped, with the reason, only where no Docker
engine can start (or, for the v2 run, where no ``docker compose`` plugin is installed).
"""

from __future__ import annotations

import asyncio
import json
import shutil
import urllib.request
from collections.abc import Iterator

import pytest

from tests.conftest import ClientRunner
from tests.deploy import stack as docker
from tests.helpers import ROOT, TIMEOUT_FACTOR


pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]


@pytest.fixture(scope="module")
def image() -> str:
    """An engine, the local base and nginx images, and this checkout's project image."""
    reason = docker.start_engine()
    if reason is not None:
        pytest.skip(f"Docker smoke test skipped: {reason}")
    docker.reap_stale_projects()
    docker.ensure_base_image()
    return docker.build_images()


@pytest.fixture(scope="module", params=list(docker.COMPOSE_COMMANDS))
def stack(request: pytest.FixtureRequest, image: str) -> Iterator[docker.Stack]:
    """The compose project, up and healthy, brought down afterwards."""
    compose = docker.COMPOSE_COMMANDS[request.param]
    if shutil.which(compose[0]) is None:
        pytest.skip(f"{request.param} is not installed (`make deps` installs it as root)")
    if docker.run([*compose, "version"], check=False).returncode != 0:
        pytest.skip(f"{request.param} is not installed (`make deps` installs it as root)")
    suffix = "v1" if request.param == "docker-compose" else "v2"
    project = docker.Stack(compose, image, suffix)
    try:
        project("up", "-d", timeout=300)
        project.wait_healthy(["ros2-web-bridge", "web-interface"], timeout=120 * TIMEOUT_FACTOR)
        yield project
    finally:
        project("down", "--timeout", "10", check=False)


def get(url: str) -> tuple[int, str, bytes]:
    with urllib.request.urlopen(url, timeout=10) as response:
        return response.status, response.headers.get("Content-Type", ""), response.read()


def test_image_runs_unprivileged_with_its_own_healthcheck_and_bundled_config(image: str) -> None:
    """The image alone: non-root user, HEALTHCHECK `simbridge healthcheck`, defaults built in."""
    config = json.loads(docker.run(["docker", "image", "inspect", image]).stdout)[0]["Config"]
    assert config["User"].split(":")[0] not in ("", "root", "0")
    assert config["Healthcheck"]["Test"] == ["CMD", "simbridge", "healthcheck"]
    assert config["Cmd"][0] == "simbridge"
    # no config mounted, no network: the bundled world and parameters load
    checked = docker.run(
        ["docker", "run", "--rm", "--network", "none", image, "simbridge", "check-config"]
    )
    assert checked.stdout.startswith("ok: world 'default'")


def test_ps_lists_both_services_up_and_healthy(stack: docker.Stack) -> None:
    """`ps` shows the bridge and the web interface running, both healthchecks passing."""
    out = stack("ps").stdout
    for service in ("ros2-web-bridge", "web-interface"):
        line = next(ln for ln in out.splitlines() if service in ln)
        assert "healthy" in line and "unhealthy" not in line, out
    assert f"127.0.0.1:{stack.ws_port}->9090/tcp" in out
    assert f"127.0.0.1:{stack.web_port}->8080/tcp" in out


async def test_roslibjs_receives_odom_on_the_bridge_port(
    stack: docker.Stack, run_js: ClientRunner
) -> None:
    """Roslibjs 1.4.1 on ws://HOST:9090 (the published port) receives /odom."""
    result = await run_js("roslib1", f"ws://127.0.0.1:{stack.ws_port}", "odom_rate", {"count": 5})
    assert result["count"] == 5
    assert result["first"]["header"]["frame_id"] == "odom"
    assert result["first"]["child_frame_id"] == "base_link"


async def test_roslibjs_receives_odom_and_scan_through_nginx_ws(
    stack: docker.Stack, run_js: ClientRunner
) -> None:
    """Roslibjs 2.1.0 on ws://HOST:8080/ws, proxied by nginx to the bridge, gets /odom, /scan."""
    url = f"ws://127.0.0.1:{stack.web_port}/ws"
    odom = await run_js("roslib2", url, "odom_rate", {"count": 3})
    assert odom["first"]["header"]["frame_id"] == "odom"
    scan = await run_js("roslib2", url, "scan")
    assert len(scan["ranges"]) == 360
    assert scan["header"]["frame_id"] == "laser"


def test_nginx_serves_the_page_and_the_bridge_health(stack: docker.Stack) -> None:
    """The page over HTTP from static/ (read-only mount), and /healthz proxied to the bridge."""
    base = f"http://127.0.0.1:{stack.web_port}"
    status, ctype, body = get(f"{base}/")
    assert status == 200 and ctype.startswith("text/html")
    assert body == (ROOT / "static" / "index.html").read_bytes()
    status, ctype, body = get(f"{base}/vendor/roslib.min.js")
    assert status == 200 and "javascript" in ctype
    assert body == (ROOT / "static" / "vendor" / "roslib.min.js").read_bytes()
    status, _, body = get(f"{base}/healthz")
    assert status == 200 and b'"status":"ok"' in body


def test_bridge_runs_unprivileged_with_config_mounted_read_only(stack: docker.Stack) -> None:
    """The bridge is not root; config/ is mounted read-only and the server uses it."""
    uid = stack("exec", "-T", "ros2-web-bridge", "id", "-u").stdout.strip()
    assert uid != "0" and uid.isdigit()
    touched = stack("exec", "-T", "ros2-web-bridge", "touch", "/etc/simbridge/x", check=False)
    assert touched.returncode != 0
    assert "Read-only file system" in touched.stderr + touched.stdout
    info = stack.inspect("ros2-web-bridge")
    env = info["Config"]["Env"]
    assert "SIMBRIDGE_WORLD=/etc/simbridge/worlds/default.yaml" in env
    host = info["HostConfig"]
    assert host["RestartPolicy"]["Name"] == "unless-stopped"
    assert host["LogConfig"] == {
        "Type": "json-file",
        "Config": {"max-file": "3", "max-size": "10m"},
    }


async def test_logs_follow_shows_a_client_connecting(
    stack: docker.Stack, run_js: ClientRunner
) -> None:
    """`logs -f ros2-web-bridge` streams the bridge's log: a new client's connection appears."""
    proc = await asyncio.create_subprocess_exec(
        *stack.command("logs", "-f", "--no-color", "ros2-web-bridge"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
        env=stack.env,
    )
    assert proc.stdout is not None
    try:
        await run_js("roslib1", f"ws://127.0.0.1:{stack.ws_port}", "topics")
        seen: list[str] = []
        async with asyncio.timeout(30 * TIMEOUT_FACTOR):
            while not any("disconnected" in line for line in seen):
                line = (await proc.stdout.readline()).decode(errors="replace")
                assert line, f"logs -f ended: {seen[-10:]}"
                seen.append(line)
        assert any("rosbridge ws://" in line for line in seen)
    finally:
        proc.kill()
        await proc.wait()


def test_stop_reaches_simbridge_and_down_removes_everything(stack: docker.Stack) -> None:
    """SIGTERM reaches simbridge (exec-form CMD): it exits 0 at once; `down` leaves nothing."""
    stack("stop", "-t", "10", "ros2-web-bridge")
    state = stack.inspect("ros2-web-bridge")["State"]
    # 137 would be docker's SIGKILL after the 10 s grace: the signal did not reach simbridge
    assert state["ExitCode"] == 0, state
    logs = stack("logs", "--no-color", "ros2-web-bridge").stdout
    assert "simbridge: stopping" in logs
    stack("down", "--timeout", "10")
    assert stack.containers() == {}
