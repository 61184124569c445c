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


def _point_segment_distance(
    px: FloatArray, py: FloatArray, segments: FloatArray
) -> npt.NDArray[np.float64]:
    """Return the distance of each point ``(N,)`` to each segment ``(W, 4)``, ``(N, W)``."""
    x1, y1 = segments[:, 0], segments[:, 1]
    ex, ey = segments[:, 2] - x1, segments[:, 3] - y1
    length2 = ex * ex + ey * ey
    safe = np.where(length2 > 0.0, length2, 1.0)
    rx = px[:, None] - x1
    ry = py[:, None] - y1
    s = np.clip((rx * ex + ry * ey) / safe, 0.0, 1.0)
    dx = rx - s * ex
    dy = ry - s * ey
    out: npt.NDArray[np.float64] = np.sqrt(dx * dx + dy * dy)
    return out


def _enumerate_rays(
    owner: npt.NDArray[np.intp],
    start: FloatArray,
    width: FloatArray,
    yaw: FloatArray,
    n_rays: int,
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """List the rays of each candidate that fall in its angular interval.

    Candidate ``c`` of scan ``owner[c]`` covers absolute angles ``[start, start + width]``;
    ray ``k`` of scan ``i`` points at ``yaw[i] + k * 2 pi / n_rays``. Returns, for every
    (candidate, ray) pair, the candidate index and the ray index.
    """
    inc = 2.0 * np.pi / n_rays
    rel = (start - yaw[owner]) / inc
    k0 = np.ceil(rel - 1e-6)
    k1 = np.floor(rel + width / inc + 1e-6)
    counts = np.clip(k1 - k0 + 1.0, 0.0, float(n_rays)).astype(np.intp)
    total = int(counts.sum())
    cand = np.repeat(np.arange(counts.shape[0], dtype=np.intp), counts)
    offsets = np.cumsum(counts) - counts
    j = np.arange(total, dtype=np.intp) - np.repeat(offsets, counts)
    k = (k0.astype(np.intp)[cand] + j) % n_rays
    return cand, k


def raycast_batch(
    origins: FloatArray,
    yaws: FloatArray,
    n_rays: int,
    segments: FloatArray,
    range_max: float,
    *,
    circles: FloatArray | None = None,
    circle_radius: float = 0.0,
    owners: npt.NDArray[np.intp] | None = None,
) -> FloatArray:
    """Return the ranges of many scans at once, ``(N, n_rays)``, each in ``[0, range_max]``.

    Scan ``i`` has its origin at ``origins[i]`` and ray ``k`` at ``yaws[i] + k * 2 pi / n_rays``
    (``angle_min = 0``). Obstacles are the wall ``segments`` and round footprints ``circles``
    ``(C, 2)`` of radius ``circle_radius`` (other robots); circle ``owners[i]`` (if not -1) is
    the scanning robot's own footprint and is not seen (no self-hits).

    Two cullings keep the work proportional to what each scan can see: only obstacles within
    ``range_max`` of an origin are considered, and each of them is intersected only with the
    rays inside the angle it subtends (a wall 3 m away and 0.5 m long meets about 10 of 360
    rays), instead of every ray against every wall.
    """
    n = origins.shape[0]
    ranges = np.full(n * n_rays, range_max, dtype=np.float64)
    if n == 0:
        return ranges.reshape(0, n_rays)
    inc = 2.0 * np.pi / n_rays
    ox, oy = origins[:, 0], origins[:, 1]
    # Chunks of scans bound the temporary arrays (about 1 MB per scan in a dense world).
    chunk = 128
    for lo in range(0, n, chunk):
        hi = min(n, lo + chunk)
        if segments.shape[0]:
            _walls_into(ranges, lo, hi, ox, oy, yaws, n_rays, inc, segments, range_max)
        if circles is not None and circles.shape[0] and circle_radius > 0:
            _circles_into(
                ranges, lo, hi, ox, oy, yaws, n_rays, inc, circles, circle_radius, range_max, owners
            )
    return ranges.reshape(n, n_rays)


def _walls_into(
    ranges: FloatArray,
    lo: int,
    hi: int,
    ox: FloatArray,
    oy: FloatArray,
    yaws: FloatArray,
    n_rays: int,
    inc: float,
    segments: FloatArray,
    range_max: float,
) -> None:
    near = _point_segment_distance(ox[lo:hi], oy[lo:hi], segments) < range_max
    scan, wall = np.nonzero(near)
    if scan.shape[0] == 0:
        return
    scan = scan + lo
    x, y = ox[scan], oy[scan]
    seg = segments[wall]
    a1 = np.arctan2(seg[:, 1] - y, seg[:, 0] - x)
    a2 = np.arctan2(seg[:, 3] - y, seg[:, 2] - x)
    delta = (a2 - a1 + np.pi) % (2.0 * np.pi) - np.pi
    start = np.where(delta >= 0.0, a1, a2)
    cand, k = _enumerate_rays(scan, start, np.abs(delta), yaws, n_rays)
    s = scan[cand]
    theta = yaws[s] + k * inc
    dx, dy = np.cos(theta), np.sin(theta)
    sg = seg[cand]
    px, py = sg[:, 0] - x[cand], sg[:, 1] - y[cand]
    ex, ey = sg[:, 2] - sg[:, 0], sg[:, 3] - sg[:, 1]
    denom = dx * ey - dy * ex
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / denom
        t = (px * ey - py * ex) * inv
        u = (px * dy - py * dx) * inv
    hit = (t >= 0.0) & (u >= -1e-12) & (u <= 1.0 + 1e-12)
    np.minimum.at(ranges, s[hit] * n_rays + k[hit], t[hit])


def _circles_into(
    ranges: FloatArray,
    lo: int,
    hi: int,
    ox: FloatArray,
    oy: FloatArray,
    yaws: FloatArray,
    n_rays: int,
    inc: float,
    circles: FloatArray,
    radius: float,
    range_max: float,
    owners: npt.NDArray[np.intp] | None,
) -> None:
    cx, cy = circles[:, 0], circles[:, 1]
    # Sorting by x limits the pairs to a window instead of every scan against every circle.
    order = np.argsort(cx, kind="stable")
    sx = cx[order]
    reach = range_max + radius
    left = np.searchsorted(sx, ox[lo:hi] - reach, side="left")
    right = np.searchsorted(sx, ox[lo:hi] + reach, side="right")
    counts = right - left
    scan = np.repeat(np.arange(lo, hi, dtype=np.intp), counts)
    offsets = np.cumsum(counts) - counts
    j = np.arange(int(counts.sum()), dtype=np.intp) - np.repeat(offsets, counts)
    circle = order[np.repeat(left, counts) + j]
    rx, ry = cx[circle] - ox[scan], cy[circle] - oy[scan]
    d2 = rx * rx + ry * ry
    keep = (d2 < reach * reach) & (d2 > radius * radius)
    if owners is not None:
        keep &= circle != owners[scan]
    scan, rx, ry, d2 = scan[keep], rx[keep], ry[keep], d2[keep]
    if scan.shape[0] == 0:
        return
    dist = np.sqrt(d2)
    half = np.arcsin(np.minimum(radius / dist, 1.0))
    centre = np.arctan2(ry, rx)
    cand, k = _enumerate_rays(scan, centre - half, 2.0 * half, yaws, n_rays)
    s = scan[cand]
    theta = yaws[s] + k * inc
    dx, dy = np.cos(theta), np.sin(theta)
    b = dx * rx[cand] + dy * ry[cand]
    disc = b * b - (d2[cand] - radius * radius)
    hit = disc >= 0.0
    t = b[hit] - np.sqrt(disc[hit])
    s, k = s[hit], k[hit]
    front = t >= 0.0
    np.minimum.at(ranges, s[front] * n_rays + k[front], t[front])
