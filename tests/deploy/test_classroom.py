"""docker-compose.classroom.yml run for real: one router, two simulators, front-ends, nginx.

The file as written plus a small override: the project image built with the ``zenoh`` extra
FROM the tests' local base, the tests' nginx image, the router's and nginx's ports on free
127.0.0.1 ports. A WebSocket client of nginx's ``/ws`` (which a ``--no-sim`` front-end
answers) sees the robots of both simulators and gets their /odom: the data crossed Zenoh from
the simulators' containers. Skipped, with the reason, where no Docker engine can start or no
``docker compose`` (v2) is installed.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import WebSocketException

from tests.deploy import stack as docker
from tests.helpers import ROOT, TIMEOUT_FACTOR


pytestmark = [pytest.mark.e2e, pytest.mark.timeout(1200)]

CLASSROOM = ROOT / "docker-compose.classroom.yml"
COMPOSE = ["docker", "compose"]


@pytest.fixture(scope="module")
def zenoh_image() -> str:
    """An engine, the local base and nginx images, and the project image with Zenoh."""
    reason = docker.start_engine()
    if reason is not None:
        pytest.skip(f"classroom compose test skipped: {reason}")
    if shutil.which("docker") is None or docker.run([*COMPOSE, "version"], check=False).returncode:
        pytest.skip("classroom compose test skipped: no `docker compose` (v2) plugin")
    docker.reap_stale_projects()
    docker.ensure_base_image()
    docker.build_images()  # the tests' nginx image (the project image comes from cache)
    tag = "simbridge-test-zenoh:" + docker.project_image_tag().split(":")[1]
    with docker.machine_lock("amd64"):
        docker.run(
            [
                "docker",
                "build",
                "--network",
                "host",
                "--build-arg",
                f"BASE_IMAGE={docker.BASE_IMAGE}",
                "--build-arg",
                "SIMBRIDGE_EXTRAS=zenoh",
                "--label",
                docker.TEST_LABEL,
                "-t",
                tag,
                str(ROOT),
            ],
            timeout=900,
        )
    return tag


class Classroom:
    """The compose project of docker-compose.classroom.yml and the test's override."""

    def __init__(self, image: str, directory: Path) -> None:
        self.project = f"{docker.PROJECT_PREFIX}{os.getpid()}cls"
        self.web_port = docker.free_port()
        override = directory / "classroom.test.yml"
        services = {
            name: {"image": image, "pull_policy": "never"}
            for name in ("zenoh-router", "sim-a", "sim-b", "front")
        }
        override.write_text(json.dumps({"services": services}))
        self.files = [CLASSROOM, override]
        self.env = dict(os.environ)
        self.env.update(
            NGINX_IMAGE=docker.NGINX_IMAGE,
            ZENOH_PUBLISH=f"127.0.0.1:{docker.free_port()}",
            WEB_PUBLISH=f"127.0.0.1:{self.web_port}",
        )

    def __call__(self, *args: str, timeout: float = 300, check: bool = True) -> Any:
        files = [arg for path in self.files for arg in ("-f", str(path))]
        cmd = [*COMPOSE, "-p", self.project, *files, *args]
        return docker.run(cmd, timeout=timeout, check=check, env=self.env)


@pytest.fixture(scope="module")
def classroom(zenoh_image: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Classroom]:
    project = Classroom(zenoh_image, tmp_path_factory.mktemp("classroom"))
    try:
        project("up", "-d", "--scale", "front=2")
        yield project
    finally:
        project("down", "--timeout", "10", check=False)


async def _call(ws: Any, service: str) -> Any:
    await ws.send(json.dumps({"op": "call_service", "service": service, "id": service}))
    while True:
        msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
        if msg.get("id") == service:
            return msg


async def test_a_front_end_behind_nginx_serves_the_robots_of_both_simulators(
    classroom: Classroom,
) -> None:
    url = f"ws://127.0.0.1:{classroom.web_port}/ws"
    wanted = {"/a1/odom", "/a15/odom", "/b1/odom", "/b15/odom"}
    deadline = time.monotonic() + 180 * TIMEOUT_FACTOR
    topics: set[str] = set()
    while time.monotonic() < deadline:
        try:
            async with connect(url, open_timeout=5) as ws:
                reply = await _call(ws, "/rosapi/topics")
                topics = set(reply["values"]["topics"])
                if wanted <= topics:
                    break
        except (OSError, TimeoutError, KeyError, WebSocketException) as err:  # still starting
            topics = {f"({type(err).__name__})"}
        await asyncio.sleep(1)
    logs = classroom("logs", "--no-color", "--tail", "20", check=False).stdout
    assert wanted <= topics, f"robots not seen through nginx: {sorted(topics)[:20]}\n{logs}"
    # two connections (nginx spreads them over the front-ends): each gets both worlds' /odom
    for _ in range(2):
        async with connect(url, open_timeout=5, max_size=None) as ws:
            for topic in ("/a1/odom", "/b15/odom"):
                await ws.send(json.dumps({"op": "subscribe", "topic": topic}))
            seen: set[str] = set()
            end = time.monotonic() + 20 * TIMEOUT_FACTOR
            while seen != {"/a1/odom", "/b15/odom"} and time.monotonic() < end:
                msg = json.loads(await asyncio.wait_for(ws.recv(), 10))
                if msg.get("op") == "publish":
                    assert msg["msg"]["child_frame_id"].endswith("base_link")
                    seen.add(msg["topic"])
            assert seen == {"/a1/odom", "/b15/odom"}
    ps = classroom("ps", "--format", "json", check=False).stdout
    assert ps.count('"front') >= 2 or ps.count("front-") >= 2, ps
