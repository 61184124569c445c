"""The arm64 image (Raspberry Pi 4B/5, 64-bit OS), built and run here under qemu-user emulation.

The same Dockerfile and docker-compose.yml as test_docker.py, for linux/arm64: an arm64 base from
``debootstrap --arch arm64``, the project image built FROM it with ``docker build --platform
linux/arm64`` (the classic builder: no buildx here), Debian's nginx on the same base, then the
compose stack (compose.test.yml + compose.arm64.yml) up, the page and the robot's topics
checked, and a clean shutdown. Every binary in it is aarch64, run by qemu-aarch64-static through
binfmt_misc. Timing under emulation means nothing for a Pi: only correctness is tested here
(``python -m bench pi`` measures a Pi-sized CPU budget). ``make test-arm64`` runs this file alone.

The image carries the ``dds`` extra (the Cyclone DDS binding 0.10.2, compiled in the Dockerfile's
first stage against Debian's C library): ``simbridge --dds`` runs in a container of its own with
no network (``--network none``: a private network namespace with only ``lo``), and a Cyclone DDS
11 node of the host (``second_peer.py``) joins that namespace (``nsenter``): no DDS packet
reaches the machine's interfaces. Both discover each other by unicast on ``lo``
(``CYCLONEDDS_URI``, :data:`UNICAST`).

Skipped, with the reason, where no Docker engine can start or arm64 binaries cannot be run
(qemu-user-static missing, binfmt_misc not mountable or the entry not registrable).
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import sys
import urllib.request
from collections.abc import Iterator

import pytest

from tests.conftest import ClientRunner
from tests.deploy import stack as docker
from tests.helpers import ROOT, TIMEOUT_FACTOR
from tests.ros2.dds.harness import SECOND_PEER, PeerProcess, allocate_domain


pytestmark = [pytest.mark.e2e, pytest.mark.timeout(3600)]

COMPOSE_ARM64_FILE = docker.HERE / "compose.arm64.yml"
#: Discovery by unicast on lo: Debian's qemu-user 7.2 has no IP_MULTICAST_IF, and Cyclone DDS
#: under it stops at "set IP_MULTICAST_IF failed: Unsupported" (a Pi runs multicast natively).
UNICAST = (
    '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    '<ParticipantIndex>auto</ParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers>'
    "</Discovery></Domain></CycloneDDS>"
)


@pytest.fixture(scope="module")
def image() -> str:
    """An engine, arm64 emulation, the arm64 base and nginx images, this checkout's arm64 image."""
    reason = docker.start_engine()
    if reason is not None:
        pytest.skip(f"arm64 smoke test skipped: {reason}")
    reason = docker.enable_arm64()
    if reason is not None:
        pytest.skip(f"arm64 smoke test skipped: cannot run arm64 binaries: {reason}")
    docker.reap_stale_projects()
    docker.ensure_base_image("arm64")
    return docker.build_images("arm64")


@pytest.fixture(scope="module")
def stack(image: str) -> Iterator[docker.Stack]:
    """The compose project on arm64 images, up and healthy, brought down afterwards."""
    name = next(
        (
            name
            for name, cmd in docker.COMPOSE_COMMANDS.items()
            if shutil.which(cmd[0]) and docker.run([*cmd, "version"], check=False).returncode == 0
        ),
        None,
    )
    if name is None:
        pytest.skip("neither docker-compose nor docker compose is installed (`make deps`)")
    project = docker.Stack(
        docker.COMPOSE_COMMANDS[name],
        image,
        "a64",
        extra=[COMPOSE_ARM64_FILE],
        nginx=docker.ARM64_NGINX_IMAGE,
    )
    try:
        project("up", "-d", timeout=300)
        project.wait_healthy(["ros2-web-bridge", "web-interface"], timeout=240 * TIMEOUT_FACTOR)
        yield project
    finally:
        project("down", "--timeout", "20", check=False)


def test_images_are_arm64_and_the_container_runs_aarch64(image: str, stack: docker.Stack) -> None:
    """Both images are linux/arm64; inside the bridge, `uname -m` says aarch64 (not the host's)."""
    for tag in (image, docker.ARM64_NGINX_IMAGE):
        inspected = json.loads(docker.run(["docker", "image", "inspect", tag]).stdout)[0]
        assert (inspected["Os"], inspected["Architecture"]) == ("linux", "arm64"), tag
    machine = stack("exec", "-T", "ros2-web-bridge", "uname", "-m").stdout.strip()
    assert machine == "aarch64"


def test_page_is_served_on_8080_with_the_bridge_health(stack: docker.Stack) -> None:
    """The arm64 nginx serves the page from static/ and proxies /healthz to the bridge."""
    base = f"http://127.0.0.1:{stack.web_port}"
    with urllib.request.urlopen(f"{base}/", timeout=30) as response:
        assert response.status == 200
        assert response.read() == (ROOT / "static" / "index.html").read_bytes()
    with urllib.request.urlopen(f"{base}/healthz", timeout=30) as response:
        assert b'"status":"ok"' in response.read()


async def test_roslibjs_receives_odom_scan_and_tf(
    stack: docker.Stack, run_js: ClientRunner
) -> None:
    """Roslibjs 1.4.1 on the bridge port and 2.1.0 through nginx's /ws: /odom, /scan, /tf flow."""
    odom = await run_js(
        "roslib1", f"ws://127.0.0.1:{stack.ws_port}", "odom_rate", {"count": 10}, timeout=60
    )
    assert odom["count"] == 10
    assert odom["first"]["header"]["frame_id"] == "odom"
    assert odom["last"]["header"]["stamp"] != odom["first"]["header"]["stamp"]
    url = f"ws://127.0.0.1:{stack.web_port}/ws"
    scan = await run_js("roslib2", url, "scan", timeout=60)
    assert len(scan["ranges"]) == 360
    assert scan["header"]["frame_id"] == "laser"
    tf = await run_js("roslib2", url, "tf", {"timeout_ms": 30000}, timeout=60)
    frames = {(t["header"]["frame_id"], t["child_frame_id"]) for t in tf["tf"]["transforms"]}
    assert ("odom", "base_link") in frames


def test_stop_is_clean_and_down_removes_everything(stack: docker.Stack) -> None:
    """SIGTERM reaches simbridge on arm64 too: exit code 0, "stopping" logged; `down` clears."""
    stack("stop", "-t", "20", "ros2-web-bridge", timeout=120)
    state = stack.inspect("ros2-web-bridge")["State"]
    assert state["ExitCode"] == 0, state
    assert "simbridge: stopping" in stack("logs", "--no-color", "ros2-web-bridge").stdout
    stack("down", "--timeout", "20")
    assert stack.containers() == {}


async def test_dds_in_the_image_a_cyclone_node_reads_odom_and_drives_the_robot(image: str) -> None:
    """`simbridge --dds` on arm64 (binding 0.10.2) and a Cyclone DDS 11 node, in one namespace.

    The node (as rmw_cyclonedds, Humble) lists simbridge's nodes and topics, its /cmd_vel reaches
    the robot through simbridge's reader, and the /odom it reads shows the robot moving.
    """
    pytest.importorskip("cyclonedds")
    name = f"{docker.PROJECT_PREFIX}{os.getpid()}dds"
    # the label lets the next run remove the container if this one dies (reap_stale_projects)
    label = f"com.docker.compose.project={name}"
    run = ["docker", "run", "-d", "--rm", "--network", "none", "--name", name, "--label", label]
    docker.run([*run, image, "sleep", "900"])
    procs: list[PeerProcess] = []
    try:
        pid = docker.run(["docker", "inspect", "-f", "{{.State.Pid}}", name]).stdout.strip()
        enter = ["nsenter", f"--net=/proc/{pid}/ns/net", "--"]
        links = docker.run([*enter, "ip", "-o", "link", "show"]).stdout.splitlines()
        assert [line.split(":")[1].strip() for line in links] == ["lo"]
        with allocate_domain() as domain:
            config = ["-e", f"ROS_DOMAIN_ID={domain}", "-e", f"CYCLONEDDS_URI={UNICAST}"]
            bridge = await asyncio.create_subprocess_exec(
                *["docker", "exec", *config, name],
                *["simbridge", "--dds", "--ros-distro", "humble", "--host", "127.0.0.1"],
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.PIPE,
            )
            inside = PeerProcess(bridge, "simbridge --dds (arm64)")
            procs.append(inside)
            node = await asyncio.create_subprocess_exec(
                *enter,
                *[sys.executable, str(SECOND_PEER), "--domain", str(domain), "--node", "student"],
                *["--echo", "/odom", "--cmd-vel", "0.4,0"],
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.PIPE,
                cwd=ROOT,
                env={**os.environ, "CYCLONEDDS_URI": UNICAST},
            )
            peer = PeerProcess(node, "second_peer (Cyclone DDS 11, host)")
            procs.append(peer)
            try:
                # simbridge starts in an emulated interpreter: seconds, not a fraction of one
                graph = await peer.wait_graph(
                    lambda g: "/virtual_robot" in g.nodes(), 120, "simbridge's nodes"
                )
                odom = await peer.sample(
                    "/odom", lambda d: d["pose"]["pose"]["position"]["x"] > 0.05, 60
                )
            except AssertionError as err:
                said = [str(e.get("line", e)) for e in inside.events] + inside.stderr
                raise AssertionError(f"{err}\nsimbridge said:\n  " + "\n  ".join(said)) from None
            assert graph.topics()["/odom"] == {"nav_msgs/msg/Odometry"}
            assert "/cmd_vel" in graph.node("/virtual_robot")["subscribers"]
            assert (odom["header"]["frame_id"], odom["child_frame_id"]) == ("odom", "base_link")
    finally:
        docker.run(["docker", "rm", "-f", name], check=False)
        for proc in procs:
            await proc.stop()
