"""``simbridge fit`` and ``simbridge compare --fitted`` on recordings simbridge made itself.

The "real" robot is simbridge under a hidden realism profile: its commands are replayed headless
(``replay_headless``, sim time, seeded) and recorded; the fit must find the profile again.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from simbridge.app.config import Params, load_params
from simbridge.headless import Simulation
from simbridge.msgs import TypeRegistry
from simbridge.tools.bag import BagWriter
from simbridge.tools.compare import compare_main
from simbridge.tools.fit import fit, fit_main, load_drive
from simbridge.tools.record import replay_headless


HIDDEN = {"cmd_latency": 0.12, "motor_time_constant": 0.25, "deadband": 0.05}
BASE_NS = 1_700_000_000 * 10**9


def commands_bag(path: Path, steps: list[tuple[float, float, float]]) -> Path:
    writer = BagWriter(path, TypeRegistry(), segment_seconds=1e9)
    for t, v, w in steps:
        msg = {"linear": {"x": v, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": w}}
        writer.write("/cmd_vel", "geometry_msgs/msg/Twist", msg, BASE_NS + round(t * 1e9))
    writer.close()
    return path


def real_run(tmp: Path, steps: list[tuple[float, float, float]], **realism: float) -> Path:
    """Record simbridge under the hidden profile driven by ``steps``."""
    hidden = tmp / "hidden.yaml"
    hidden.write_text(yaml.safe_dump({"realism": {"enabled": True, **realism}}))
    cmds = commands_bag(tmp / "cmds", steps)
    replay_headless(str(cmds), tmp / "real", params=str(hidden))
    return tmp / "real"


#: Steps, turns and a ramp of slow commands (what shows the deadband) over 14 s.
WITH_SLOW = [(0.0, 0.2, 0.0), (2.0, 0.0, 1.0), (3.5, 0.3, -0.5), (5.0, 0.0, 0.0)] + [
    (6.0 + 0.5 * i, 0.02 + 0.005 * i, 0.0) for i in range(12)
]
#: Only fast commands: every wheel at 0.2 m/s or more.
FAST_ONLY = [(0.0, 0.3, 0.0), (2.0, 0.0, 0.0), (3.0, -0.25, 0.0), (5.0, 0.4, 1.0), (7.0, 0, 0)]


def test_fit_recovers_a_hidden_profile_within_ten_percent(tmp_path: Path) -> None:
    bag = real_run(tmp_path, WITH_SLOW, wheel_speed_scale=0.9, **HIDDEN)
    result = fit(load_drive(bag))
    for name, value in HIDDEN.items():
        estimate = result.estimates[name]
        assert estimate.determined, estimate
        assert estimate.value == pytest.approx(value, rel=0.1), estimate
        assert estimate.low <= value <= estimate.high, estimate
    assert result.estimates["wheel_speed_scale"].value == pytest.approx(0.9, rel=0.01)
    assert result.rms < 0.1 * result.ideal_rms


@pytest.fixture(scope="module")
def fitted_fast(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, str]:
    """A recording with only fast commands, and ``simbridge fit``'s file and report of it."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("fast")
    bag = real_run(tmp, FAST_ONLY, **HIDDEN)
    out = tmp / "fitted.yaml"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert fit_main([str(bag), "-o", str(out)]) == 0
    return bag, out, printed.getvalue()


def test_fit_says_not_determined_when_the_recording_cannot_show_the_deadband(
    fitted_fast: tuple[Path, Path, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """No slow command: the deadband is "not determined" and written as 0; --params takes it."""
    bag, out, text = fitted_fast
    line = next(ln for ln in text.splitlines() if ln.startswith("deadband"))
    assert "not determined" in line and "slower than 0.2" in line
    fitted = load_params(out)
    assert fitted.realism.enabled and fitted.realism.deadband == 0.0
    assert fitted.realism.cmd_latency == pytest.approx(0.12, rel=0.1)
    assert fitted.realism.motor_time_constant == pytest.approx(0.25, rel=0.1)
    # the real run beside the ideal and the fitted replays: the fitted one is far closer
    plot = tmp_path / "gap.svg"
    assert compare_main([str(bag), "--fitted", str(out), "--json", "--plot", str(plot)]) == 0
    figures = json.loads(capsys.readouterr().out)
    ideal, fitted_rmse = (figures[k]["position_rmse_m"] for k in ("ideal", "fitted"))
    assert fitted_rmse < 0.1 * ideal and ideal > 0.02, figures
    assert plot.read_text().count("<polyline") == 3 + 2 * 2


def test_fit_refuses_a_bag_without_commands(tmp_path: Path) -> None:
    writer = BagWriter(tmp_path / "b", TypeRegistry(), segment_seconds=1e9)
    writer.write("/chatter", "std_msgs/msg/String", {"data": "x"}, BASE_NS)
    writer.close()
    assert fit_main([str(tmp_path / "b")]) == 1


def heading_step(params: Params, kp: float, kd: float, seconds: float = 4.0) -> float:
    """Run the PID lab's heading step (90 deg, PD on /odom) headless; return the overshoot, rad."""
    sim = Simulation(world=None, params=params)
    odom = sim.subscribe("/odom")
    goal, prev, peak = math.pi / 2, None, 0.0
    sim.step()
    for _ in range(round(seconds / sim.dt)):
        latest = odom.latest
        assert latest is not None
        q = latest["pose"]["pose"]["orientation"]
        theta = 2 * math.atan2(q["z"], q["w"])
        err = goal - theta
        d = 0.0 if prev is None else (err - prev) / sim.dt
        prev = err
        sim.command(0.0, kp * err + kd * d)
        sim.step()
        peak = max(peak, theta - goal)
    return peak


def test_pid_gains_tuned_on_the_ideal_plant_overshoot_on_the_fitted_one(
    fitted_fast: tuple[Path, Path, str],
) -> None:
    """The PID lab: the same gains, no overshoot on the ideal plant, overshoot on the fitted."""
    fitted = load_params(fitted_fast[1])
    assert heading_step(Params(), 3.0, 0.05) < 0.01
    assert heading_step(fitted, 3.0, 0.05) > 0.1
