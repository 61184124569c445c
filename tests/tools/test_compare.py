from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from simbridge.tools.compare import CompareError, compare, compare_main, load_run
from simbridge.tools.record import replay_headless
from tests.helpers import cmd_vel_bag


SQUAREISH = [(2.0, 0.2, 0.0), (2.0, 0.0, 0.5), (2.0, 0.2, 0.0)]


def simulated(
    tmp_path: Path, name: str, segments: list, idle: float, world: Path | None = None
) -> Path:
    cmd_vel_bag(tmp_path / f"{name}_cmds", [(idle, 0.0, 0.0), *segments])
    out = tmp_path / name
    replay_headless(str(tmp_path / f"{name}_cmds"), out, world=str(world) if world else None)
    return out


def test_same_commands_at_other_times_and_places_compare_equal(tmp_path: Path) -> None:
    """Alignment removes a different idle time before the first command and another start pose."""
    world = tmp_path / "world.yaml"
    world.write_text("walls: [[-5, -5, 5, -5]]\nrobot:\n  pose: [1.0, -0.5, 2.0]\n")
    a = simulated(tmp_path, "a", SQUAREISH, idle=1.0)
    b = simulated(tmp_path, "b", SQUAREISH, idle=3.0, world=world)
    result = compare(load_run(a), load_run(b))
    m = result.metrics()
    assert m["sim_start_offset_s"] == pytest.approx(1.0, abs=0.06)
    assert m["real_start_offset_s"] == pytest.approx(3.0, abs=0.06)
    assert m["position_rmse_m"] < 1e-6
    assert m["heading_final_drift_rad"] < 1e-6
    assert m["duration_s"] > 6.0
    assert m["sim_distance_m"] == pytest.approx(0.8, abs=0.01)


def test_a_robot_that_turns_10_percent_less_drifts_as_expected(tmp_path: Path) -> None:
    """Turning 0.45 instead of 0.5 rad/s for 2 s gives a 0.1 rad final heading error.

    The last 0.4 m leg then ends 2 * 0.4 * sin(0.05) = 0.040 m away.
    """
    sim = simulated(tmp_path, "sim", SQUAREISH, idle=1.0)
    real = simulated(tmp_path, "real", [(2.0, 0.2, 0.0), (2.0, 0.0, 0.45), (2.0, 0.2, 0.0)], 2.0)
    m = compare(load_run(sim), load_run(real)).metrics()
    assert m["heading_final_drift_rad"] == pytest.approx(0.1, abs=0.005)
    assert m["position_final_drift_m"] == pytest.approx(2 * 0.4 * math.sin(0.05), abs=0.003)
    assert 0 < m["position_rmse_m"] < m["position_max_m"]


def test_command_line_report_json_and_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sim = simulated(tmp_path, "sim", SQUAREISH, idle=1.0)
    real = simulated(tmp_path, "real", SQUAREISH, idle=1.5)
    assert (
        compare_main([str(sim), str(real / "real.mcap"), "--plot", str(tmp_path / "p.html")]) == 0
    )
    out = capsys.readouterr().out
    assert "position error: RMSE" in out
    assert "final drift" in out
    page = (tmp_path / "p.html").read_text()
    assert "<svg" in page
    assert "<polyline" in page
    assert compare_main([str(sim), str(real), "--json", "--plot", str(tmp_path / "p.svg")]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["position_rmse_m"] < 1e-6
    assert (tmp_path / "p.svg").read_text().startswith("<svg")


def test_a_bag_without_commands_is_a_clear_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cmd_vel_bag(tmp_path / "still", [(1.0, 0.0, 0.0)])  # only zero commands
    with pytest.raises(CompareError, match="no non-zero /cmd_vel"):
        load_run(tmp_path / "still")
    assert compare_main([str(tmp_path / "still"), str(tmp_path / "still")]) == 1
    assert "no non-zero /cmd_vel" in capsys.readouterr().err
