from __future__ import annotations

import numpy as np
import pytest

from simbridge.sim.collision import _first_touch_walls, pose_clear, resolve_moves
from simbridge.sim.lidar import _point_segment_distance


R = 0.105
WALL_X1 = np.array([[1.0, -5.0, 1.0, 5.0]])  # a wall along x = 1


def move(p0: list[list[float]], p1: list[list[float]], walls: np.ndarray = WALL_X1) -> tuple:
    return resolve_moves(np.array(p0, float), np.array(p1, float), R, walls)


def test_robot_driving_into_a_wall_stops_touching_it() -> None:
    """A move that would cross x = 1 ends with the footprint's edge on the wall."""
    final, contacts = move([[0.8, 0.0]], [[0.95, 0.0]])
    assert final[0, 0] == pytest.approx(1.0 - R, abs=1e-3)
    assert final[0, 0] <= 1.0 - R + 1e-9
    assert [(c.robot, c.other) for c in contacts] == [(0, -1)]
    assert contacts[0].normal == pytest.approx((-1.0, 0.0))
    assert contacts[0].point == pytest.approx((1.0, 0.0), abs=1e-3)


def test_robot_meeting_a_wall_at_an_angle_slides_along_it() -> None:
    """Only the component into the wall is removed: y keeps advancing."""
    final, contacts = move([[1.0 - R - 0.01, 0.0]], [[1.0 - R + 0.02, 0.03]])
    assert final[0, 0] <= 1.0 - R + 1e-9
    assert final[0, 1] == pytest.approx(0.03, abs=1e-3)
    assert len(contacts) == 1


def test_a_fast_robot_does_not_tunnel_through_a_thin_wall() -> None:
    """The whole swept path is checked: a 2 m jump across the wall is stopped at it."""
    final, _ = move([[0.0, 0.0]], [[2.0, 0.0]])
    assert final[0, 0] <= 1.0 - R + 1e-9


def test_moves_clear_of_everything_are_untouched() -> None:
    final, contacts = move([[0.0, 0.0], [0.0, 1.0]], [[0.1, 0.0], [0.0, 1.1]])
    assert final.tolist() == [[0.1, 0.0], [0.0, 1.1]]
    assert contacts == []


def test_two_robots_driving_head_on_stop_touching() -> None:
    """Robots never overlap: the second mover stops where the footprints touch."""
    final, contacts = move([[-0.2, 3.0], [0.2, 3.0]], [[-0.05, 3.0], [0.05, 3.0]])
    gap = final[1, 0] - final[0, 0]
    assert gap == pytest.approx(2 * R, abs=1e-6)
    assert {(c.robot, c.other) for c in contacts} == {(1, 0)}


def test_a_robot_overlapping_a_wall_can_back_out_but_not_go_further_in() -> None:
    """After a larger radius is set at run time, motion away from the wall is allowed."""
    inside = 1.0 - R / 2
    out, _ = move([[inside, 0.0]], [[inside - 0.02, 0.0]])
    assert out[0, 0] == pytest.approx(inside - 0.02)
    deeper, _ = move([[inside, 0.0]], [[inside + 0.02, 0.0]])
    assert deeper[0, 0] == pytest.approx(inside)


def test_many_random_walkers_never_overlap_walls_or_each_other() -> None:
    """200 robots in a box with pillars for 200 steps: every footprint stays clear."""
    rng = np.random.default_rng(7)
    walls = np.array(
        [[-3, -3, 3, -3], [3, -3, 3, 3], [3, 3, -3, 3], [-3, 3, -3, -3], [0, -1, 0, 1]], float
    )
    pts: list[tuple[float, float]] = []
    while len(pts) < 200:
        x, y = rng.uniform(-2.8, 2.8, 2)
        if pose_clear(x, y, R, walls, np.array(pts, float).reshape(-1, 2)) is None:
            pts.append((x, y))
    p = np.array(pts)
    heading = rng.uniform(-np.pi, np.pi, 200)
    for _ in range(200):
        heading += rng.normal(0, 0.3, 200)
        step = 0.05 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
        p, _contacts = resolve_moves(p, p + step, R, walls)
        assert _point_segment_distance(p[:, 0], p[:, 1], walls).min() >= R - 1e-6
        d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
        assert (d + np.eye(200) * 9).min() >= 2 * R - 1e-6


def test_pose_clear_says_what_the_footprint_overlaps() -> None:
    assert pose_clear(0.0, 0.0, R, WALL_X1, np.zeros((0, 2))) is None
    assert "wall [1, -5, 1, 5]" in (pose_clear(0.95, 0.0, R, WALL_X1, np.zeros((0, 2))) or "")
    why = pose_clear(0.0, 0.0, R, WALL_X1, np.array([[0.1, 0.0]]))
    assert why is not None and "another robot" in why


def test_first_touch_with_a_wall_is_exact() -> None:
    """The closed-form time of first touch agrees with a dense walk along each path.

    Random paths and segments (some of them points): up to the touch the path stays at least
    ``R`` from the wall, and just after it comes closer (unless it never touches).
    """
    rng = np.random.default_rng(3)
    a = rng.uniform(-1, 1, (2000, 2))
    d = rng.uniform(-1, 1, (2000, 2))
    seg = rng.uniform(-1, 1, (2000, 4))
    seg[:50, 2:] = seg[:50, :2]  # degenerate segments: points
    clear = np.array([_distance(a[k], seg[k]) > R for k in range(len(a))])
    a, d, seg = a[clear], d[clear], seg[clear]  # paths that start clear of their wall
    t = _first_touch_walls(a, d, seg, R)
    assert ((t >= 0.0) & (t <= 1.0)).all()
    samples = np.linspace(0.0, 1.0, 2001)
    for k in range(a.shape[0]):
        path = a[k] + samples[:, None] * d[k]
        dist = _point_segment_distance(path[:, 0], path[:, 1], seg[k : k + 1])[:, 0]
        assert dist[samples <= t[k]].min() >= R - 1e-9
        if t[k] < 1.0:
            assert _distance(a[k] + min(t[k] + 1e-3, 1.0) * d[k], seg[k]) < R
    assert (t < 1.0).sum() > 100  # plenty of the paths touch


def _distance(p: np.ndarray, seg: np.ndarray) -> float:
    return float(_point_segment_distance(p[:1], p[1:], seg[None, :])[0, 0])
