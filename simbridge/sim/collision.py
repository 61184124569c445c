"""Collisions of round robot footprints with walls and with each other, for many robots at once.

Each step, every robot proposes a move ``p0 -> p1`` (its motion model's result). A move is
allowed as far as the footprint (a disc of radius ``r``) stays at least ``r`` from every wall
segment and ``2 r`` from every other robot, checked along the whole path, so a fast robot
cannot tunnel through a thin wall. At a wall the robot advances to the contact and slides along
the wall with the rest of its move (only the component into the wall is removed); at another
robot it stops at the contact. Heading is never blocked: a disc turns freely.

Work is proportional to what can touch: walls are culled by bounding boxes of the swept paths,
robot pairs by a window on x, and only the few robots near something are resolved exactly.
Against walls, the time of first touch is solved in closed form (the points within ``r`` of a
segment are a band and two end discs), vectorised over every robot-wall pair. Robot pairs are
resolved in a short Python loop in index order, each robot checked against the others' current
positions so two robots never claim the same spot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from simbridge.sim.lidar import FloatArray


__all__ = ["Contact", "pose_clear", "resolve_moves"]

#: Distances within this of the footprint boundary count as touching, not overlapping (m).
TOLERANCE = 1e-9


@dataclass(frozen=True, slots=True)
class Contact:
    """A robot stopped (fully or partly) by an obstacle during one step.

    Attributes:
        robot: index of the robot that was stopped.
        other: index of the robot it touched, or -1 for a wall.
        point: the contact point on the obstacle, in the world frame.
        normal: unit vector from the obstacle towards the robot.
    """

    robot: int
    other: int
    point: tuple[float, float]
    normal: tuple[float, float]


def _closest_on_segments(
    px: FloatArray, py: FloatArray, seg: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Return the closest point of each segment ``seg[k]`` to point ``(px[k], py[k])``."""
    ex, ey = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
    length2 = ex * ex + ey * ey
    s = ((px - seg[:, 0]) * ex + (py - seg[:, 1]) * ey) / np.where(length2 > 0, length2, 1.0)
    s = np.minimum(np.maximum(s, 0.0), 1.0)  # np.clip's Python wrapper costs more here
    return seg[:, 0] + s * ex, seg[:, 1] + s * ey


def _wall_pairs(
    p0: FloatArray, p1: FloatArray, radius: float, segments: FloatArray
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """Return (robot, wall) pairs a robot could touch this step (bounding boxes overlap).

    The box around ``p0`` has half-size ``|p1 - p0| + radius``: it holds every position within
    one move of ``p0``, slides along a wall included.
    """
    grow = np.hypot(p1[:, 0] - p0[:, 0], p1[:, 1] - p0[:, 1])[:, None] + radius
    lo = p0 - grow
    hi = p0 + grow
    wlo = np.minimum(segments[:, :2], segments[:, 2:])
    whi = np.maximum(segments[:, :2], segments[:, 2:])
    overlap = (
        (lo[:, None, 0] <= whi[None, :, 0])
        & (hi[:, None, 0] >= wlo[None, :, 0])
        & (lo[:, None, 1] <= whi[None, :, 1])
        & (hi[:, None, 1] >= wlo[None, :, 1])
    )
    robot, wall = np.nonzero(overlap)
    return robot.astype(np.intp), wall.astype(np.intp)


def _first_touch_walls(a: FloatArray, d: FloatArray, seg: FloatArray, reach: float) -> FloatArray:
    """Return per pair the fraction of its path at which it first comes ``reach`` from its wall.

    The path is ``a[k] -> a[k] + d[k]``, the wall ``seg[k]``. 1.0 when it never comes that
    close; 0.0 when it starts that close and moves closer.

    The points within ``reach`` of a segment are a band along it plus a disc at each end; the
    first touch is the earliest entry into one of them (the band through its long sides).
    """
    ax, ay, dx, dy = a[:, 0], a[:, 1], d[:, 0], d[:, 1]
    best = np.ones(a.shape[0])
    motion2 = dx * dx + dy * dy
    moving = motion2 > 0.0
    safe2 = np.where(moving, motion2, 1.0)
    for cx, cy in ((seg[:, 0], seg[:, 1]), (seg[:, 2], seg[:, 3])):
        rx, ry = ax - cx, ay - cy
        c = rx * rx + ry * ry - reach * reach
        b = rx * dx + ry * dy
        disc = b * b - motion2 * c
        ok = moving & (b < 0.0) & (disc > 0.0)  # closing in (touching already: t < 0 -> 0)
        t = (-b - np.sqrt(np.where(ok, disc, 0.0))) / safe2
        best = np.where(ok, np.minimum(best, np.maximum(t, 0.0)), best)
    ex, ey = seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]
    length = np.hypot(ex, ey)
    has_length = length > 0.0
    ux, uy = ex / np.where(has_length, length, 1.0), ey / np.where(has_length, length, 1.0)
    h0 = -uy * (ax - seg[:, 0]) + ux * (ay - seg[:, 1])  # signed distance to the line
    hd = -uy * dx + ux * dy
    toward = np.where(h0 >= 0.0, -hd, hd)  # speed towards the line
    ok = has_length & (toward > 0.0)
    t = np.maximum((np.abs(h0) - reach) / np.where(ok, toward, 1.0), 0.0)  # touching: 0
    along = ux * (ax + t * dx - seg[:, 0]) + uy * (ay + t * dy - seg[:, 1])
    ok &= (t <= 1.0) & (along >= 0.0) & (along <= length)
    return np.where(ok, np.minimum(best, t), best)


def _walls(
    p0: FloatArray, p1: FloatArray, radius: float, segments: FloatArray, contacts: list[Contact]
) -> FloatArray:
    """Resolve every move against the walls; return the positions reached."""
    out = p1.copy()
    if segments.shape[0] == 0 or p0.shape[0] == 0:
        return out
    robot, wall = _wall_pairs(p0, p1, radius, segments)
    if robot.shape[0] == 0:
        return out
    seg = segments[wall]
    a = p0[robot]
    d = p1[robot] - a
    limit = radius - TOLERANCE
    # A wall the robot already overlaps (a larger radius set at run time) blocks only motion
    # that goes further into it, so the robot can always back out.
    qx, qy = _closest_on_segments(a[:, 0], a[:, 1], seg)
    nx, ny = a[:, 0] - qx, a[:, 1] - qy
    inside = np.hypot(nx, ny) < limit
    away = (d[:, 0] * nx + d[:, 1] * ny) >= 0.0
    skip = inside & away
    # The fraction of its move at which each path first touches its wall (exact, not
    # bisected); a robot stops at the smallest of its pairs.
    t = _first_touch_walls(a, d, seg, radius)
    t = np.where(inside, np.where(away, 1.0, 0.0), t)
    if not (t < 1.0).any():
        return out
    lo = np.ones(p0.shape[0])
    np.minimum.at(lo, robot, t)
    stopped = np.nonzero(lo < 1.0)[0]
    frac = lo[stopped]
    move = p1[stopped] - p0[stopped]
    here = p0[stopped] + frac[:, None] * move
    # The pairs of the stopped robots, each with its robot's slot in ``stopped``.
    slot = np.full(p0.shape[0], -1)
    slot[stopped] = np.arange(stopped.shape[0])
    mine = slot[robot] >= 0
    k = slot[robot[mine]]
    at = here[k]
    qx, qy = _closest_on_segments(at[:, 0], at[:, 1], seg[mine])
    # each stopped robot's nearest wall (first of its pairs by distance; ties keep pair order)
    order = np.lexsort((np.hypot(at[:, 0] - qx, at[:, 1] - qy), k))
    first = order[np.r_[True, k[order][1:] != k[order][:-1]]]
    point = np.stack([qx[first], qy[first]], axis=1)
    normal = here - point
    length = np.hypot(normal[:, 0], normal[:, 1])
    heading = move / np.maximum(np.hypot(move[:, 0], move[:, 1]), 1e-12)[:, None]
    normal = np.where(
        (length > 0)[:, None], normal / np.where(length > 0, length, 1.0)[:, None], -heading
    )
    # slide with the rest of the move (its part into the wall removed) unless that path comes
    # within the footprint of a wall it does not already overlap and leave
    rest = (1.0 - frac)[:, None] * move
    into = np.minimum((rest * normal).sum(axis=1), 0.0)
    slide = rest - into[:, None] * normal
    touch = _first_touch_walls(at, slide[k], seg[mine], limit)
    blocked = np.zeros(stopped.shape[0], dtype=bool)
    np.logical_or.at(blocked, k, (touch < 1.0) & ~skip[mine])
    out[stopped] = np.where(blocked[:, None], here, here + slide)
    for n, i in enumerate(stopped.tolist()):
        contacts.append(
            Contact(
                i,
                -1,
                (float(point[n, 0]), float(point[n, 1])),
                (float(normal[n, 0]), float(normal[n, 1])),
            )
        )
    return out


def _first_touch(
    ax: float, ay: float, dx: float, dy: float, cx: float, cy: float, reach: float
) -> float:
    """Return the fraction of ``a -> a + d`` at which a point first comes ``reach`` from ``c``.

    1.0 when it never does; 0.0 when it starts closer and moves closer still; 1.0 when it
    starts closer and moves away (overlaps can always be undone).
    """
    rx, ry = ax - cx, ay - cy
    c = rx * rx + ry * ry - reach * reach
    b = rx * dx + ry * dy
    if c < -TOLERANCE:
        return 0.0 if b < 0.0 else 1.0
    a = dx * dx + dy * dy
    if a == 0.0 or b >= 0.0:
        return 1.0
    disc = b * b - a * c
    if disc <= 0.0:
        return 1.0
    t = (-b - math.sqrt(disc)) / a
    return min(max(t, 0.0), 1.0)


def _robots(p0: FloatArray, p1: FloatArray, radius: float, contacts: list[Contact]) -> FloatArray:
    """Resolve robot-robot contacts (after walls); return the positions reached."""
    n = p0.shape[0]
    out = p1.copy()
    if n < 2:
        return out
    step = np.hypot(*(p1 - p0).T)
    reach = 2.0 * radius
    window = reach + 2.0 * float(step.max())
    order = np.argsort(p0[:, 0], kind="stable")
    xs = p0[order, 0]
    right = np.searchsorted(xs, xs + window, side="right")
    start = np.arange(n) + 1
    counts = right - start
    first = np.repeat(np.arange(n), counts)
    offsets = np.cumsum(counts) - counts
    second = np.repeat(start, counts) + (np.arange(int(counts.sum())) - np.repeat(offsets, counts))
    i, j = order[first], order[second]
    near = np.hypot(*(p0[i] - p0[j]).T) < reach + step[i] + step[j]
    i, j = i[near], j[near]
    if i.shape[0] == 0:
        return out
    neighbours: dict[int, list[int]] = {}
    for u, v in zip(i.tolist(), j.tolist(), strict=True):
        neighbours.setdefault(u, []).append(v)
        neighbours.setdefault(v, []).append(u)
    involved = sorted(neighbours)
    current = {k: (float(p0[k, 0]), float(p0[k, 1])) for k in involved}
    for k in involved:
        ax, ay = current[k]
        dx, dy = float(p1[k, 0]) - ax, float(p1[k, 1]) - ay
        frac, other = 1.0, -1
        for m in neighbours[k]:
            cx, cy = current[m]
            f = _first_touch(ax, ay, dx, dy, cx, cy, reach)
            if f < frac:
                frac, other = f, m
        end = (ax + frac * dx, ay + frac * dy)
        current[k] = end
        out[k] = end
        if other >= 0:
            cx, cy = current[other]
            nx, ny = end[0] - cx, end[1] - cy
            length = math.hypot(nx, ny) or 1.0
            nx, ny = nx / length, ny / length
            contacts.append(Contact(k, other, (cx + radius * nx, cy + radius * ny), (nx, ny)))
    return out


def resolve_moves(
    p0: FloatArray, p1: FloatArray, radius: float, segments: FloatArray
) -> tuple[FloatArray, list[Contact]]:
    """Return where each robot ends up when moving ``p0[i] -> p1[i]``, and the contacts.

    Args:
        p0: ``(N, 2)`` positions at the start of the step (clear of each other and the walls).
        p1: ``(N, 2)`` positions the motion model proposes.
        radius: footprint radius of every robot, m.
        segments: ``(W, 4)`` wall segments.
    """
    contacts: list[Contact] = []
    after_walls = _walls(p0, p1, radius, segments, contacts)
    final = _robots(p0, after_walls, radius, contacts)
    return final, contacts


def pose_clear(
    x: float,
    y: float,
    radius: float,
    segments: FloatArray,
    others: FloatArray,
) -> str | None:
    """Return why a footprint at ``(x, y)`` would overlap something, or None when it is clear.

    ``others`` are the ``(K, 2)`` centres of the other robots (same radius).
    """
    if segments.shape[0]:
        qx, qy = _closest_on_segments(
            np.full(segments.shape[0], x), np.full(segments.shape[0], y), segments
        )
        dist = np.hypot(x - qx, y - qy)
        k = int(np.argmin(dist))
        if dist[k] < radius - TOLERANCE:
            wall = ", ".join(f"{v:g}" for v in segments[k])
            return f"it overlaps the wall [{wall}] (footprint radius {radius:g} m)"
    if others.shape[0]:
        dist = np.hypot(others[:, 0] - x, others[:, 1] - y)
        k = int(np.argmin(dist))
        if dist[k] < 2.0 * radius - TOLERANCE:
            return f"it overlaps another robot at ({others[k, 0]:g}, {others[k, 1]:g})"
    return None
