"""docker-compose.yml and the Dockerfile as written: what the course relies on, engine or not.

Both compose front ends parse the file (``config`` needs no engine); test_docker.py runs it.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tomllib
from typing import Any

import pytest
import yaml

from tests.helpers import ROOT


COMPOSE = ROOT / "docker-compose.yml"
DOCKERFILE = ROOT / "Dockerfile"


@pytest.fixture(scope="module")
def services() -> dict[str, Any]:
    return dict(yaml.safe_load(COMPOSE.read_text())["services"])


def instructions() -> list[tuple[str, str]]:
    """The Dockerfile's instructions (continuation lines joined, comments dropped)."""
    text = re.sub(r"\\\n", " ", DOCKERFILE.read_text())
    lines = [ln.strip() for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    return [(ln.split(None, 1)[0].upper(), ln.split(None, 1)[1]) for ln in lines]


def final_stage() -> list[tuple[str, str]]:
    """The instructions of the image's own stage (after the last FROM)."""
    steps = instructions()
    last = max(i for i, (op, _) in enumerate(steps) if op == "FROM")
    return steps[last:]


def test_dockerfile_base_is_an_argument_defaulting_to_python_slim() -> None:
    """`ARG BASE_IMAGE=python:3.12-slim-bookworm`; every stage is `FROM ${BASE_IMAGE}`."""
    steps = instructions()
    assert steps[0] == ("ARG", "BASE_IMAGE=python:3.12-slim-bookworm")
    assert [arg for op, arg in steps if op == "FROM"] == [
        "${BASE_IMAGE} AS dds-binding",
        "${BASE_IMAGE}",
    ]


def test_dockerfile_runs_simbridge_unprivileged_in_exec_form_with_a_healthcheck() -> None:
    """Non-root USER, exec-form CMD (SIGTERM reaches simbridge), HEALTHCHECK by the CLI."""
    steps = dict(instructions())
    assert steps["USER"].split(":")[0] not in ("root", "0")
    assert json.loads(steps["CMD"])[0] == "simbridge"
    assert steps["HEALTHCHECK"].endswith('CMD ["simbridge", "healthcheck"]')


def test_dockerfile_installs_wheels_only_without_a_cache() -> None:
    """The image's pip installs are --no-cache-dir --only-binary=:all:; it has no compiler.

    Its one Debian package is Cyclone DDS's runtime library, for the binding that the first
    stage compiles on aarch64 only.
    """
    runs = [arg for op, arg in final_stage() if op == "RUN"]
    installs = [part for arg in runs for part in arg.split("&&") if "pip install" in part]
    assert installs
    for part in installs:
        assert "--no-cache-dir" in part and "--only-binary=:all:" in part, part
    assert not any(re.search(r"\b(gcc|build-essential|-dev)\b", arg) for arg in runs)
    packages = [
        part.split("--no-install-recommends")[1].split()
        for arg in runs
        for part in arg.split("&&")
        if "apt-get install" in part
    ]
    assert packages == [["libddsc0debian"]]


def test_dockerfile_builds_the_aarch64_dds_binding_pyproject_pins() -> None:
    """The first stage compiles the dds extra's aarch64 pin, for aarch64 with dds only."""
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pins = [
        req.split(";")[0].strip()
        for req in pyproject["project"]["optional-dependencies"]["dds"]
        if "platform_machine == 'aarch64'" in req
    ]
    stage = instructions()[: len(instructions()) - len(final_stage())]
    args = dict(arg.split("=", 1) for op, arg in stage if op == "ARG")
    assert [args["CYCLONEDDS_AARCH64"]] == pins == ["cyclonedds==0.10.2"]
    (build,) = [arg for op, arg in stage if op == "RUN"]
    assert "*,dds,*aarch64) ;; *) exit 0 ;;" in build
    assert '--no-binary cyclonedds -w /wheels "${CYCLONEDDS_AARCH64}"' in build


def test_dockerignore_admits_only_what_the_image_needs() -> None:
    """The build context is the package, its page and config: no .venv, node_modules, tests."""
    lines = (ROOT / ".dockerignore").read_text().split()
    assert lines[lines.index("*")] == "*"
    admitted = {ln[1:].rstrip("/") for ln in lines if ln.startswith("!")}
    assert admitted == {"pyproject.toml", "README.md", "simbridge", "static", "config"}


def test_bridge_service_publishes_9090_restarts_and_caps_its_logs(
    services: dict[str, Any],
) -> None:
    """ros2-web-bridge: built here, port 9090, unless-stopped, healthcheck, logs <= 3 x 10 MB."""
    bridge = services["ros2-web-bridge"]
    assert bridge["build"] == "."
    assert bridge["ports"] == ["${WS_PUBLISH:-9090}:9090"]
    assert bridge["restart"] == "unless-stopped"
    assert bridge["healthcheck"]["test"] == ["CMD", "simbridge", "healthcheck"]
    assert bridge["logging"] == {
        "driver": "json-file",
        "options": {"max-size": "10m", "max-file": "3"},
    }
    assert "./config:/etc/simbridge:ro" in bridge["volumes"]
    assert all(name.startswith("SIMBRIDGE_") for name in bridge["environment"])
    assert bridge["mem_limit"] and bridge["cpus"]


def test_web_interface_serves_static_read_only_after_the_bridge_is_healthy(
    services: dict[str, Any],
) -> None:
    """web-interface: pinned nginx alpine image (overridable), 8080, read-only mounts."""
    web = services["web-interface"]
    default = re.fullmatch(r"\$\{NGINX_IMAGE:-(nginx:[\d.]+-alpine)\}", web["image"])
    assert default, web["image"]
    assert web["ports"] == ["${WEB_PUBLISH:-8080}:8080"]
    assert set(web["volumes"]) == {
        "./static:/usr/share/nginx/html:ro",
        "./config/nginx.conf:/etc/nginx/conf.d/default.conf:ro",
    }
    assert web["depends_on"] == {"ros2-web-bridge": {"condition": "service_healthy"}}
    assert web["restart"] == "unless-stopped"
    assert web["healthcheck"]["test"][0] == "CMD"
    assert web["logging"] == services["ros2-web-bridge"]["logging"]


@pytest.mark.parametrize("front_end", [["docker-compose"], ["docker", "compose"]], ids=" ".join)
def test_both_compose_front_ends_read_the_file_as_written(front_end: list[str]) -> None:
    """`docker-compose config` (v1) and `docker compose config` (v2) accept it, same ports."""
    if shutil.which(front_end[0]) is None or (
        subprocess.run([*front_end, "version"], capture_output=True, check=False).returncode
    ):
        pytest.skip(f"{' '.join(front_end)} is not installed (`make deps` installs it as root)")
    env = {k: v for k, v in os.environ.items() if k not in ("WS_PUBLISH", "WEB_PUBLISH")}
    env.pop("NGINX_IMAGE", None)
    out = subprocess.run(
        [*front_end, "-f", str(COMPOSE), "config"],
        capture_output=True,
        text=True,
        env=env,
        check=False,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    config = yaml.safe_load(out.stdout)["services"]
    for name, port in (("ros2-web-bridge", 9090), ("web-interface", 8080)):
        (published,) = config[name]["ports"]
        assert int(published["published"]) == port and int(published["target"]) == port
    assert config["web-interface"]["image"].startswith("nginx:")
