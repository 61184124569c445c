from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from simbridge.app.config import (
    Params,
    default_params_path,
    default_world_path,
    load_params,
    load_world,
    resource_dir,
)
from simbridge.app.settings import ServerSettings, SettingsError, server_settings
from simbridge.errors import ConfigError
from simbridge.msgs.convert import finite_number


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_bundled_parameters_are_the_pi4b_platform_defaults() -> None:
    """config/pi4b_params.yaml holds the course's figures (wheel radius, not diameter)."""
    p = load_params(None)
    assert p.robot.mass == 1.5
    assert p.robot.wheel_radius == 0.033
    assert p.robot.wheelbase == 0.160
    assert p.robot.inertia == 0.0075
    assert (p.robot.max_linear_velocity, p.robot.max_angular_velocity) == (0.5, 2.5)
    assert (p.lidar.rays, p.lidar.range_min, p.lidar.range_max, p.lidar.rate) == (
        360,
        0.12,
        3.5,
        10.0,
    )
    assert p.lidar.mount == (0.0, 0.0, 0.0)
    assert p == Params()


def test_bundled_world_is_a_room_with_obstacles_and_a_corridor() -> None:
    """The default world has walls, boxes, a pillar and starts the robot at the origin."""
    w = load_world(None)
    assert len(w.walls) >= 8
    assert w.boxes and w.circles
    assert w.robot.pose == (0.0, 0.0, 0.0)


def test_the_defaults_are_the_bundled_files() -> None:
    """load_params(None) and load_world(None) build, without YAML, what the files hold."""
    assert load_params(default_params_path()) == load_params(None) == Params()
    assert load_world(default_world_path()) == load_world(None)
    assert load_world(default_world_path()).given == load_world(None).given


def test_the_defaults_are_built_without_pyyaml_and_a_file_still_loads(tmp_path: Path) -> None:
    """The default run does not import yaml; a world file given imports it where it is read."""
    path = write(tmp_path, "w.yaml", "walls: [[0, 0, 1, 0]]\n")
    code = (
        "import sys; from simbridge.app.config import load_params, load_world; "
        "load_params(None); load_world(None); print('yaml' in sys.modules); "
        f"print(load_world({str(path)!r}).walls, 'yaml' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    ).stdout.splitlines()
    assert out == ["False", "[(0.0, 0.0, 1.0, 0.0)] True"]


def test_minimal_world_form_is_accepted(tmp_path: Path) -> None:
    """The issue's minimal form: walls as [x1, y1, x2, y2] and robot.pose."""
    path = write(
        tmp_path,
        "w.yaml",
        "walls:\n  - [-2.0, -2.0, 2.0, -2.0]\nrobot:\n  pose: [0.0, 0.0, 0.0]\n",
    )
    w = load_world(path)
    assert w.segments() == [(-2.0, -2.0, 2.0, -2.0)]
    assert w.name == "w"


def test_boxes_circles_and_polygons_become_closed_rings_of_segments(tmp_path: Path) -> None:
    """A box gives 4 segments, a circle its segment count, a triangle 3."""
    path = write(
        tmp_path,
        "w.yaml",
        "boxes: [{center: [0, 0], size: [2, 1]}]\n"
        "circles: [{center: [5, 5], radius: 1, segments: 8}]\n"
        "polygons: [[[0, 0], [1, 0], [0, 1]]]\n",
    )
    segs = load_world(path).segments()
    assert len(segs) == 4 + 8 + 3
    assert (-1.0, -0.5, 1.0, -0.5) in segs


def test_wall_with_three_numbers_names_the_file_the_index_and_the_fix(tmp_path: Path) -> None:
    """A wrong wall entry is reported with the file, walls[i] and the expected shape."""
    path = write(tmp_path, "lab.yaml", "walls:\n  - [0, 0, 1, 1]\n  - [0, 0, 1]\n")
    with pytest.raises(ConfigError) as err:
        load_world(path)
    text = str(err.value)
    assert "lab.yaml" in text
    assert "walls[1]" in text
    assert "[x1, y1, x2, y2]" in text


def test_negative_mass_names_the_key_and_the_value(tmp_path: Path) -> None:
    """robot.mass: -1 is refused naming the file, robot.mass and the bound."""
    path = write(tmp_path, "p.yaml", "robot:\n  mass: -1\n")
    with pytest.raises(ConfigError) as err:
        load_params(path)
    assert str(err.value) == f"params file '{path}': robot.mass: must be greater than 0 (got -1)"


def test_misspelled_key_is_reported_as_unknown(tmp_path: Path) -> None:
    """A typo (wheel_radus) is not silently ignored."""
    path = write(tmp_path, "p.yaml", "robot:\n  wheel_radus: 0.033\n")
    with pytest.raises(ConfigError, match=r"robot\.wheel_radus: unknown key"):
        load_params(path)


def test_range_min_above_range_max_is_refused(tmp_path: Path) -> None:
    """Relations between fields are checked too."""
    path = write(tmp_path, "p.yaml", "lidar:\n  range_min: 4.0\n")
    with pytest.raises(ConfigError, match="range_min"):
        load_params(path)


def test_missing_file_and_bad_yaml_are_clear(tmp_path: Path) -> None:
    """A missing file and invalid YAML each get a message naming the file."""
    with pytest.raises(ConfigError, match="cannot be read"):
        load_world(tmp_path / "nope.yaml")
    bad = write(tmp_path, "bad.yaml", "walls: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_world(bad)
    listy = write(tmp_path, "list.yaml", "- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must be a mapping"):
        load_params(listy)


def test_non_finite_pose_is_refused(tmp_path: Path) -> None:
    """.nan in a pose is an error, not a robot at NaN."""
    path = write(tmp_path, "w.yaml", "robot:\n  pose: [.nan, 0, 0]\n")
    with pytest.raises(ConfigError, match="finite"):
        load_world(path)


def test_flat_parameters_round_trip() -> None:
    """Params.flat() and Params.from_flat() are inverse; invalid values raise ValueError."""
    p = Params()
    assert Params.from_flat(p.flat()) == p
    assert p.flat()["lidar.mount"] == [0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"robot\.mass"):
        Params.from_flat({**p.flat(), "robot.mass": 0})
    assert set(Params.describe()) == set(p.flat())


def test_resources_are_found() -> None:
    """The page and config directories resolve (package data or checkout)."""
    assert (resource_dir("static") / "index.html").is_file()
    assert (resource_dir("config") / "pi4b_params.yaml").is_file()


def test_a_world_may_list_named_robots(tmp_path: Path) -> None:
    """robots: [{name, pose}] gives named robots; the single robot: key keeps name ''."""
    path = write(
        tmp_path,
        "fleet.yaml",
        "robots:\n  - {name: r1, pose: [1, 2, 0]}\n  - {name: r2, pose: [-1, 0, 3.14]}\n",
    )
    assert load_world(path).start_poses() == {"r1": (1.0, 2.0, 0.0), "r2": (-1.0, 0.0, 3.14)}
    assert load_world(None).start_poses() == {"": (0.0, 0.0, 0.0)}


@pytest.mark.parametrize(
    ("text", "error"),
    [
        ("robot: {pose: [0, 0, 0]}\nrobots: [{name: a}]\n", "either 'robot:'"),
        ("robots: [{name: a}, {name: a}]\n", "robots[1]: name 'a' is used twice"),
        ("robots: [{name: 'r-1'}]\n", "robots[0].name: robot name 'r-1' is not a valid ROS name"),
        ("robots: [{pose: [0, 0, 0]}]\n", "robots[0].name: required, but missing"),
        (
            "robots: [{name: a, realism: {slip: 2}}]\n",
            "robots[0].realism.slip: must be less than or equal to 1",
        ),
        ("robot: {realism: {slipp: 0.1}}\n", "robot.realism.slipp: unknown key"),
        (
            "floor: [{polygon: [[0, 0], [1, 0]], slip: 0.1}]\n",
            "floor[0].polygon: must be a list of at least 3 corners",
        ),
        ("floor: [{polygon: [[0, 0], [1, 0], [1, 1]]}]\n", "floor[0].slip: required"),
    ],
)
def test_bad_robot_lists_fail_naming_the_key(tmp_path: Path, text: str, error: str) -> None:
    with pytest.raises(ConfigError, match=error.replace("[", r"\[")):
        load_world(write(tmp_path, "bad.yaml", text))


def test_a_world_lists_static_frames_and_turns_on_the_tutorial_nodes(tmp_path: Path) -> None:
    """frames: [x, y, yaw] or [x, y, z, roll, pitch, yaw]; demo_nodes a boolean."""
    text = (
        "demo_nodes: true\nframes:\n"
        "  - {parent: world, child: turtle1, pose: [1, 2, 0.5]}\n"
        "  - {parent: world, child: cam, pose: [1, 2, 3, 0.1, 0.2, 0.3]}\n"
    )
    world = load_world(write(tmp_path, "w.yaml", text))
    assert world.demo_nodes is True
    assert [f.xyz_rpy() for f in world.frames] == [
        (1.0, 2.0, 0.0, 0.0, 0.0, 0.5),
        (1.0, 2.0, 3.0, 0.1, 0.2, 0.3),
    ]


@pytest.mark.parametrize(
    ("text", "error"),
    [
        (
            "frames: [{parent: world, child: a, pose: [1, 2]}]\n",
            "frames[0].pose: has 2 numbers, expected [x, y, yaw] or",
        ),
        ("frames: [{parent: a, child: /a}]\n", "frames[0]: parent and child are both 'a'"),
        (
            "frames: [{parent: w, child: a}, {parent: v, child: a}]\n",
            "frames[1]: frame 'a' has two parents",
        ),
        ("frames: [{parent: w, child: a, pose: [0, 0, .nan]}]\n", "not a finite number"),
    ],
)
def test_bad_frames_fail_naming_the_entry(tmp_path: Path, text: str, error: str) -> None:
    with pytest.raises(ConfigError, match=error.replace("[", r"\[")):
        load_world(write(tmp_path, "bad.yaml", text))


def test_server_settings_are_validated_naming_the_field() -> None:
    """ServerSettings holds the same bounds as the options: -5 s and unknown names refused."""
    with pytest.raises(ConfigError, match=r"^settings: stall_timeout: .*greater than 0 \(got -5\)"):
        server_settings(stall_timeout=-5)
    with pytest.raises(ConfigError, match=r"max_clinets: unknown key"):
        server_settings(max_clinets=3)
    with pytest.raises(ConfigError, match=r"port: .*65535"):
        server_settings(port=70000)
    assert server_settings(stall_timeout=None).stall_timeout is None
    assert ServerSettings().max_clients == 200


def test_server_settings_cannot_be_changed_after_validation() -> None:
    """Settings are validated once: a later assignment is refused, not slipped in."""
    settings = ServerSettings()
    with pytest.raises(SettingsError):
        settings.max_clients = -1  # type: ignore[misc]


@pytest.mark.parametrize(
    ("value", "finite"),
    [
        (1, True),
        (-2.5, True),
        (0.0, True),
        (True, False),
        (float("nan"), False),
        (float("inf"), False),
        (10**400, False),
        ("1", False),
        (None, False),
    ],
)
def test_finite_number_is_the_one_check(value: object, finite: bool) -> None:
    """Numbers only (a bool is not one), finite, and an int past float range is not finite."""
    assert finite_number(value) is finite
