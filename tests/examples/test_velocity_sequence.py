"""The validation workflow end to end, with the simulator standing in for the real robot.

examples/velocity_sequence.py drives a real server while `simbridge record` records it; `simbridge
replay --headless` simulates the recorded commands; `simbridge compare` finds the two runs equal
to within the server's command timing (commands take effect at its next 50 ms tick).
"""

from __future__ import annotations

import asyncio
import json
import signal
import sys
from pathlib import Path

from simbridge.app.config import Params, RobotParams
from simbridge.tools.bag import read_messages
from tests.conftest import AppFactory
from tests.helpers import ROOT, TIMEOUT_FACTOR, finish_process, ws_url


async def run(*cmd: str) -> tuple[int, str, str]:
    proc = await asyncio.create_subprocess_exec(
        *cmd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE, cwd=ROOT
    )
    return await finish_process(proc, 30)


async def test_sequence_recorded_on_the_server_matches_its_headless_replay(
    make_app: AppFactory, tmp_path: Path
) -> None:
    """A "real robot" that wants TwistStamped on /cmd_vel, compared with its Twist replay.

    robot.cmd_vel_stamped stands for a Jazzy diff_drive_controller: the example publishes
    TwistStamped, the replay feeds the default (Twist) simulation the same commands and compare
    aligns on them.
    """
    app = await make_app(params=Params(robot=RobotParams(cmd_vel_stamped=True)))
    sequence = tmp_path / "seq.yaml"
    sequence.write_text(
        "- [0.5, 0.0, 0.0]\n- [1.5, 0.2, 0.0]\n- [1.5, 0.0, 0.6]\n- [1.0, 0.2, 0.3]\n"
    )
    py = sys.executable
    recorder = await asyncio.create_subprocess_exec(
        *(py, "-m", "simbridge", "record", "--url", ws_url(app)),
        *("-o", str(tmp_path / "real"), "/odom", "/cmd_vel"),
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        cwd=ROOT,
    )
    assert recorder.stderr is not None
    line = await asyncio.wait_for(recorder.stderr.readline(), 10 * TIMEOUT_FACTOR)
    assert b"recording to" in line, line  # subscribed: the sequence may start
    code, out, err = await run(
        py, "examples/velocity_sequence.py", "--url", ws_url(app), "--sequence", str(sequence)
    )
    assert code == 0, err
    assert json.loads(out.splitlines()[-1])["messages"] == 46
    await asyncio.sleep(0.5)  # the stopped robot's last /odom
    recorder.send_signal(signal.SIGINT)
    code, _out, err = await finish_process(recorder, 30)
    assert code == 0, err
    kinds = {ty for t, ty, _s, _m in read_messages(tmp_path / "real") if t == "/cmd_vel"}
    assert kinds == {"geometry_msgs/msg/TwistStamped"}
    code, _out, err = await run(
        py, "-m", "simbridge", "replay", str(tmp_path / "real"), "--headless",
        "-o", str(tmp_path / "sim"),
    )  # fmt: skip
    assert code == 0, err
    code, out, err = await run(
        py, "-m", "simbridge", "compare", str(tmp_path / "sim"), str(tmp_path / "real"), "--json"
    )
    assert code == 0, err
    m = json.loads(out)
    print(m)
    assert m["duration_s"] > 4.0
    assert m["real_distance_m"] > 0.45
    assert m["position_rmse_m"] < 0.03, m
    assert m["heading_rmse_rad"] < 0.06, m
