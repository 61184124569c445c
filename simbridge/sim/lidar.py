"""2D LiDAR raycasting against wall segments, vectorised with numpy.

A ray from ``o`` in direction ``d`` meets segment ``p + u e`` (``0 <= u <= 1``) at
``o + t d`` where, with ``c(a, b) = a_x b_y - a_y b_x`` and ``r = p - o``::

    t = c(r, e) / c(d, e)        u = c(r, d) / c(d, e)

All rays against all segments are solved at once as ``(rays, segments)`` arrays; the range of a
ray is its smallest ``t >= 0``. Ranges follow REP-117 as a saturating sensor: a ray with no wall
within ``range_max`` reports ``range_max`` (the course's convention, not ``+inf``), and a wall
closer than ``range_min`` reports ``range_min``.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


__all__ = ["FloatArray", "beam_angles", "raycast", "segments_array"]

FloatArray = npt.NDArray[np.float64]


def beam_angles(rays: int, angle_min: float = 0.0) -> FloatArray:
    """Return the beam angles of a scan: ``angle_min + k * 2 pi / rays`` for k < rays."""
    return angle_min + np.arange(rays, dtype=np.float64) * (2.0 * np.pi / rays)


def segments_array(segments: list[tuple[float, float, float, float]]) -> FloatArray:
    """Return wall segments as a contiguous ``(N, 4)`` float64 array ``[x1, y1, x2, y2]``."""
    return np.asarray(segments, dtype=np.float64).reshape(-1, 4)


def raycast(
    x: float,
    y: float,
    yaw: float,
    angles: FloatArray,
    segments: FloatArray,
    range_max: float,
) -> FloatArray:
    """Return the distance along each ray to the nearest segment, or ``range_max``.

    Args:
        x: ray origin, m.
        y: ray origin, m.
        yaw: heading of the sensor; ray k points at ``yaw + angles[k]``.
        angles: beam angles relative to the sensor, rad.
        segments: ``(N, 4)`` array of ``[x1, y1, x2, y2]``.
        range_max: the value of a ray that hits nothing closer.

    Returns:
        float64 ranges, one per angle, each in ``[0, range_max]``.
    """
    n_rays = angles.shape[0]
    if segments.shape[0] == 0:
        return np.full(n_rays, range_max, dtype=np.float64)
    theta = angles + yaw
    dx = np.cos(theta)[:, None]
    dy = np.sin(theta)[:, None]
    px = segments[:, 0] - x
    py = segments[:, 1] - y
    ex = segments[:, 2] - segments[:, 0]
    ey = segments[:, 3] - segments[:, 1]
    denom = dx * ey - dy * ex  # (rays, segments)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / denom
        t = (px * ey - py * ex) * inv
        u = (px * dy - py * dx) * inv
    hit = (t >= 0.0) & (u >= 0.0) & (u <= 1.0)
    t = np.where(hit, t, range_max)
    ranges: FloatArray = np.minimum(t.min(axis=1), range_max)
    return ranges
