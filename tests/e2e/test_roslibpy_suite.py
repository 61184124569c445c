"""roslibpy 2.1.0's own test suite (tests/ of its PyPI sdist) against ``simbridge --demo-nodes``.

The suite hard-codes ws://127.0.0.1:9090, so each run gets a network namespace of its own
(``unshare -n`` as root, ``unshare -rn`` otherwise) holding only ``lo``, the server and the suite:
the machine's port 9090 is never used, and both transports run at once. scripts/setup-test-deps.sh
puts the suite in .cache/roslibpy-2.1.0; tests/clients/roslibpy_suite.py runs it.

Every test of tests/ros2 and of the top level passes, but the one that never talks to the server
(:data:`tests.clients.roslibpy_suite.NOT_ABOUT_SIMBRIDGE`, deselected there, with the reason).
Of tests/ros1, the ones in :data:`ROS1_CANNOT_PASS` fail, for the reasons given there; the rest
pass.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from collections import Counter
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from tests.helpers import ROOT, TIMEOUT_FACTOR


pytestmark = pytest.mark.e2e

SUITE = ROOT / ".cache" / "roslibpy-2.1.0"
RUNNER = ROOT / "tests" / "clients" / "roslibpy_suite.py"
TRANSPORTS = ("twisted", "asyncio")
#: tests/ros1 tests that cannot pass against a ROS 2 graph, and why.
ROS1_CANNOT_PASS = {
    "test_actionlib.py::test_action_preemt": (
        "roslibpy's ROS 1 SimpleActionServer reads stamp.secs of the actionlib_msgs/GoalID its "
        "client publishes on /test_action/cancel; simbridge, like rosbridge on ROS 2, sends "
        "messages with ROS 2 field names (stamp.sec/nanosec), so the server's cancel handler "
        "raises KeyError and the goal never ends"
    ),
    "test_param.py::test_param_manipulation": (
        "needs ROS 1's global parameter server (any name, e.g. 'test_param', can be set and "
        "deleted); ROS 2 parameters belong to nodes ('node:param'), and simbridge's are fixed"
    ),
}
#: Outcome of one test: directory ('ros1', 'ros2' or '.'), test id, outcome.
Outcome = tuple[str, str, str]


def _run(transport: str, out: Path) -> list[Outcome]:
    unshare = ["unshare", "-n"] if os.geteuid() == 0 else ["unshare", "-rn"]
    junit = out / f"roslibpy-suite-{transport}.xml"
    cmd = [*unshare, sys.executable, str(RUNNER), str(SUITE), transport, str(junit)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300 * TIMEOUT_FACTOR)
    assert junit.exists(), f"no report ({proc.returncode}):\n{proc.stdout[-3000:]}{proc.stderr}"
    outcomes = []
    for case in ET.parse(junit).iter("testcase"):
        module = case.get("classname", "").split(".")
        directory = module[1] if len(module) > 2 else "."
        test = f"{module[-1]}.py::{case.get('name', '').split('[')[0]}"
        if case.find("failure") is not None or case.find("error") is not None:
            outcome = "failed"
        elif case.find("skipped") is not None:
            outcome = "skipped"
        else:
            outcome = "passed"
        outcomes.append((directory, test, outcome))
    return outcomes


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list[Outcome]]:
    """Run the suite once per transport, both at once (each in its own namespace)."""
    if not (SUITE / "tests" / "conftest.py").exists():
        pytest.fail(f"{SUITE} is missing: run scripts/setup-test-deps.sh (make deps)")
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.skip("unshare (util-linux) and ip (iproute2) are needed for a network namespace")
    out = tmp_path_factory.mktemp("roslibpy-suite")
    with ThreadPoolExecutor(len(TRANSPORTS)) as pool:
        runs = {t: pool.submit(_run, t, out) for t in TRANSPORTS}
        found = {t: f.result() for t, f in runs.items()}
    for transport, outcomes in found.items():
        counts = Counter((d, o) for d, _t, o in outcomes)
        print(
            f"roslibpy suite, {transport}: "
            + ", ".join(f"{d} {o} {n}" for (d, o), n in sorted(counts.items()))
        )
    return found


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_every_ros2_and_top_level_test_of_roslibpy_passes(
    results: dict[str, list[Outcome]], transport: str
) -> None:
    """tests/ros2 (actions, topics, rosapi, connections) and tests/*.py: no failure."""
    outcomes = results[transport]
    ros2 = [(t, o) for d, t, o in outcomes if d == "ros2"]
    assert len(ros2) == 25
    assert [t for t, o in ros2 if o != "passed"] == []
    top = [(t, o) for d, t, o in outcomes if d == "."]
    assert [t for t, o in top if o == "failed"] == []
    # the two asyncio-protocol tests skip themselves outside an asyncio-transport process
    assert sum(o == "skipped" for _t, o in top) == (2 if transport == "twisted" else 0)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_ros1_tests_of_roslibpy_pass_but_those_a_ros2_graph_cannot(
    results: dict[str, list[Outcome]], transport: str
) -> None:
    """23 of 25 pass (actionlib, services with result false, TF, header.seq...); 2 cannot."""
    ros1 = [(t, o) for d, t, o in results[transport] if d == "ros1"]
    assert len(ros1) == 25
    assert {t for t, o in ros1 if o != "passed"} == set(ROS1_CANNOT_PASS)
