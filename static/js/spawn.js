// Spawn a robot of one's own: the /spawn service (turtlesim/srv/Spawn: x, y, theta, name).
//
// The new robot is placed near the robot in view (or near the origin), at the first spot the
// server accepts: candidates on rings around it, never across a wall from it (the server
// refuses spots that overlap a wall or another robot, and says why).

/** Does segment p-q cross segment [x1, y1, x2, y2]? */
function crosses(p, q, s) {
  const cross = (ax, ay, bx, by) => ax * by - ay * bx;
  const rx = q.x - p.x, ry = q.y - p.y, ex = s[2] - s[0], ey = s[3] - s[1];
  const den = cross(rx, ry, ex, ey);
  if (den === 0) return false;
  const t = cross(s[0] - p.x, s[1] - p.y, ex, ey) / den;
  const u = cross(s[0] - p.x, s[1] - p.y, rx, ry) / den;
  return t >= 0 && t <= 1 && u >= 0 && u <= 1;
}

/** Candidate spots around `from`, nearest first, none across a wall from it. */
export function candidates(from, walls, rings = [0.5, 0.8, 1.2, 1.8, 2.5], per = 12) {
  const out = [];
  for (const r of rings) {
    for (let k = 0; k < per; k++) {
      const a = (2 * Math.PI * k) / per;
      const q = { x: from.x + r * Math.cos(a), y: from.y + r * Math.sin(a) };
      if (!walls.some((s) => crosses(from, q, s))) out.push(q);
    }
  }
  return out;
}

/**
 * Ask the server for a new robot called `name` ('' lets the server pick) near `from`.
 * Resolves to the name the server gave it; rejects with the server's last reason.
 */
export async function spawnNear(conn, name, from, walls) {
  let reason = 'no free spot found near the robot in view';
  for (const q of candidates(from || { x: 0, y: 0 }, walls).slice(0, 40)) {
    try {
      const res = await conn.call('/spawn', 'turtlesim/srv/Spawn', { x: q.x, y: q.y, theta: 0, name });
      return res.name;
    } catch (err) {
      reason = err.message;
      if (!/overlaps/.test(reason)) break; // a bad or taken name: trying elsewhere will not help
    }
  }
  throw new Error(reason);
}
