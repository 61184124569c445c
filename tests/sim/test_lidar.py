from __future__ import annotations

import math

import numpy as np
import pytest

from simbridge.app.config import WorldSpec
from simbridge.sim.lidar import beam_angles, raycast, raycast_batch, segments_array


SQUARE = WorldSpec.parse(
    {
        "walls": [
            [-2.0, -2.0, 2.0, -2.0],
            [2.0, -2.0, 2.0, 2.0],
            [2.0, 2.0, -2.0, 2.0],
            [-2.0, 2.0, -2.0, -2.0],
        ]
    }
)


def test_ranges_in_a_4_m_square_room_match_the_analytic_formula() -> None:
    """At the centre, range(a) = min(3.5, 2 / max(|cos a|, |sin a|)) for every ray."""
    angles = beam_angles(360)
    ranges = raycast(0.0, 0.0, 0.0, angles, segments_array(SQUARE.segments()), 3.5)
    expected = np.minimum(3.5, 2.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles))))
    np.testing.assert_allclose(ranges, expected, atol=1e-9)


def test_ray_with_no_wall_within_range_reports_range_max() -> None:
    """No segment in reach: every ray is range_max (the course's convention, not inf)."""
    far = segments_array([(10.0, -1.0, 10.0, 1.0)])
    ranges = raycast(0.0, 0.0, 0.0, beam_angles(8), far, 3.5)
    assert ranges.tolist() == [3.5] * 8


def test_empty_world_reports_range_max_everywhere() -> None:
    """A world without walls is all range_max."""
    ranges = raycast(0.0, 0.0, 0.0, beam_angles(4), segments_array([]), 2.0)
    assert ranges.tolist() == [2.0] * 4


def test_sensor_yaw_rotates_the_scan() -> None:
    """With yaw pi/2, ray 0 looks along +y and meets the wall at y = 1."""
    wall = segments_array([(-5.0, 1.0, 5.0, 1.0)])
    ranges = raycast(0.0, 0.0, math.pi / 2, np.array([0.0, math.pi]), wall, 3.5)
    assert ranges[0] == pytest.approx(1.0)
    assert ranges[1] == pytest.approx(3.5)


def test_nearest_of_several_walls_wins_and_walls_behind_are_ignored() -> None:
    """A ray sees the first wall along it; segments behind the origin do not count."""
    walls = segments_array([(2.0, -1.0, 2.0, 1.0), (1.0, -1.0, 1.0, 1.0), (-0.5, -1, -0.5, 1)])
    ranges = raycast(0.0, 0.0, 0.0, np.array([0.0]), walls, 3.5)
    assert ranges[0] == pytest.approx(1.0)


def test_parallel_ray_does_not_hit_a_segment_along_it() -> None:
    """A ray parallel to a segment (zero denominator) does not report a hit."""
    wall = segments_array([(1.0, 0.5, 3.0, 0.5)])
    ranges = raycast(0.0, 0.0, 0.0, np.array([0.0]), wall, 3.5)
    assert ranges[0] == 3.5


def test_beam_angles_are_360_increments_of_2_pi_over_n() -> None:
    """angle_max = angle_min + (n - 1) * increment, self-consistent with n ranges."""
    angles = beam_angles(360)
    assert len(angles) == 360
    assert angles[0] == 0.0
    assert angles[-1] == pytest.approx(359 * 2 * math.pi / 360)


def test_batched_scans_equal_one_scan_at_a_time() -> None:
    """raycast_batch (culled by range and angle) gives exactly what the brute force gives."""
    rng = np.random.default_rng(5)
    segments = rng.uniform(-5.0, 5.0, (100, 4))
    origins = rng.uniform(-5.0, 5.0, (50, 2))
    yaws = rng.uniform(-4.0, 4.0, 50)
    batch = raycast_batch(origins, yaws, 360, segments, 3.5)
    for i in range(50):
        one = raycast(origins[i, 0], origins[i, 1], yaws[i], beam_angles(360), segments, 3.5)
        np.testing.assert_allclose(batch[i], one, atol=1e-9)


def test_batched_scan_sees_other_footprints_but_not_its_own() -> None:
    """Two robots 2 m apart: each sees the other's disc at 2 - r straight ahead, not itself."""
    origins = np.array([[0.0, 0.0], [2.0, 0.0]])
    ranges = raycast_batch(
        origins,
        np.array([0.0, math.pi]),
        360,
        np.zeros((0, 4)),
        3.5,
        circles=origins,
        circle_radius=0.105,
        owners=np.array([0, 1]),
    )
    assert ranges[0, 0] == pytest.approx(2.0 - 0.105)
    assert ranges[1, 0] == pytest.approx(2.0 - 0.105)
    assert ranges[0, 180] == 3.5  # behind: nothing
    # the disc subtends 2 asin(0.105 / 2) = 6 degrees: rays 3 and 357 graze it, 4 misses
    assert ranges[0, 3] < 3.5 and ranges[0, 357] < 3.5 and ranges[0, 4] == 3.5


def test_walls_beyond_range_max_are_culled_without_changing_ranges() -> None:
    """A wall 5 m away cannot shorten a 3.5 m ray."""
    segments = np.array([[5.0, -1.0, 5.0, 1.0], [1.0, -1.0, 1.0, 1.0]])
    ranges = raycast_batch(np.zeros((1, 2)), np.zeros(1), 360, segments, 3.5)
    assert ranges[0, 0] == pytest.approx(1.0)
    assert ranges[0, 90] == 3.5
