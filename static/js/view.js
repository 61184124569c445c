// Top-down Canvas 2D view: grid and axes, walls, odometry trail, scan points, robot, contacts.
// World frame = odom (REP-103: x forward/right on screen, y up on screen, angles CCW).
// Drawn only when something shown changed; greyed while the data is stale.

const TRAIL_MAX = 2000;
const TRAIL_STEP_M = 0.02;
// a pose this far from the last one between two odometry messages is a jump (a teleport, a
// reset): the trail breaks instead of drawing a line across the map
const TRAIL_JUMP_M = 0.4;
// LiDAR returns: a colour no map element has (walls dark slate, grid grey, axes red/green,
// robot green, trail blue, other robots grey)
export const SCAN_COLOUR = '#c026d3';
const CONTACT_MS = 600;      // a contact stays drawn this long after the last report
const MIN_ROBOT_PX = 8;      // a robot is never drawn smaller than this radius on screen
const MIN_DATA_FRAME_MS = 45; // data redraws at most ~22 a second (odometry comes at 20 Hz)

export class View {
  constructor(canvas) {
    this.canvas = canvas;
    this.ctx = canvas.getContext('2d');
    this.walls = [];            // [x1, y1, x2, y2]
    this.pose = null;           // {x, y, theta}
    this.others = new Map();    // other robots: name -> {x, y, theta}
    this.ghost = null;          // {x, y, theta}: the true pose (/ground_truth), when it differs
    this.radius = 0.105;
    this.trail = [];            // [x, y]
    this.scan = [];             // [x, y] in world
    this.laser = null;          // {x, y}: where the scan was taken (for rays)
    this.rangeMax = 0;          // the LiDAR's range_max (for the range circle)
    this.showRays = false;
    this.showRange = false;
    this.contact = null;        // {x, y, other, at}: the last contact, drawn for a moment
    this.contacts = 0;          // contacts reported so far
    this.stale = false;         // data no longer live: drawn greyed
    this.scale = 80;            // px per metre (CSS px)
    this.center = { x: 0, y: 0 };
    this.follow = true;
    this.dirty = true;
    this.frames = 0;
    this.pointers = new Map();
    this._installInput();
    new ResizeObserver(() => this.requestDraw(true)).observe(canvas);
    this._frame = null;
    this._wait = null;
    this._lastDraw = 0;
    this.requestDraw();
  }

  /**
   * Draw once for however many changes come: at the next animation frame, but data (odometry,
   * scans, other robots: about 30 changes a second, 40 in a class) at most every
   * MIN_DATA_FRAME_MS; `now` (pan, zoom, resize) at once.
   */
  requestDraw(now = false) {
    this.dirty = true;
    if (this._frame !== null) return;
    if (this._wait !== null && !now) return;
    clearTimeout(this._wait);
    const wait = now ? 0 : Math.max(0, this._lastDraw + MIN_DATA_FRAME_MS - performance.now());
    const frame = () => {
      this._wait = null;
      this._frame = requestAnimationFrame(() => {
        this._frame = null;
        if (this.dirty) { this._lastDraw = performance.now(); this.draw(); }
      });
    };
    if (wait > 0) this._wait = setTimeout(frame, wait); else frame();
  }

  setWalls(segments) { this.walls = segments; this.requestDraw(); }
  setPose(x, y, theta) {
    const p = this.pose;
    if (p && p.x === x && p.y === y && p.theta === theta) return; // parked: nothing to draw
    if (p && Math.hypot(x - p.x, y - p.y) > TRAIL_JUMP_M) this.breakTrail();
    this.pose = { x, y, theta };
    const last = this.trail[this.trail.length - 1];
    if (!last || Math.hypot(x - last[0], y - last[1]) >= TRAIL_STEP_M) {
      this.trail.push([x, y]);
      if (this.trail.length > TRAIL_MAX) this.trail.splice(0, this.trail.length - TRAIL_MAX);
    }
    if (this.follow) this.center = { x, y };
    this.requestDraw();
  }
  /** Scan points in world (flat [x0, y0, x1, y1, ...]) and where the laser was. */
  setScan(points, laser = null, rangeMax = 0) {
    const old = this.scan;
    const same = old.length === points.length && old.every((v, i) => v === points[i])
      && (!laser || (this.laser && laser.x === this.laser.x && laser.y === this.laser.y));
    this.rangeMax = rangeMax;
    if (same) return;
    this.scan = points;
    this.laser = laser;
    this.requestDraw();
  }
  /** The trail stops here; the next pose starts a new piece (reset, reconnect, teleport). */
  breakTrail() {
    if (this.trail.length && this.trail[this.trail.length - 1] !== null) this.trail.push(null);
    this.requestDraw();
  }
  clearTrail() { this.trail = []; this.requestDraw(); }
  clear() {
    this.pose = null; this.scan = []; this.laser = null; this.trail = []; this.contact = null;
    this.ghost = null;
    this.requestDraw();
  }
  /** The true pose drawn as a ghost beside the odometry pose (null: none). */
  setGhost(pose) {
    const g = this.ghost;
    if (pose && g && g.x === pose.x && g.y === pose.y && g.theta === pose.theta) return;
    if (!pose && !g) return;
    this.ghost = pose;
    this.requestDraw();
  }
  setOther(name, pose) {
    const o = this.others.get(name);
    if (pose && o && o.x === pose.x && o.y === pose.y && o.theta === pose.theta) return;
    if (!pose && !o) return;
    if (pose) this.others.set(name, pose); else this.others.delete(name);
    this.requestDraw();
  }
  setContact(c) {
    if (c) this.contacts += 1;
    this.contact = c ? { ...c, at: performance.now() } : null;
    this.requestDraw();
    if (c) {
      clearTimeout(this._contactTimer);
      this._contactTimer = setTimeout(() => { this.contact = null; this.requestDraw(); }, CONTACT_MS);
    }
  }
  setStale(on) {
    if (this.stale === on) return;
    this.stale = on;
    this.requestDraw();
  }
  setLayers({ rays, range }) {
    this.showRays = Boolean(rays); this.showRange = Boolean(range);
    this.requestDraw();
  }

  /** Fit the walls (or a 4 m square) in view. */
  fit() {
    const xs = [], ys = [];
    for (const [x1, y1, x2, y2] of this.walls) { xs.push(x1, x2); ys.push(y1, y2); }
    if (!xs.length) { xs.push(-2, 2); ys.push(-2, 2); }
    const [minX, maxX, minY, maxY] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
    const { width, height } = this.canvas.getBoundingClientRect();
    this.scale = Math.max(5, Math.min((width - 20) / Math.max(maxX - minX, 0.5), (height - 20) / Math.max(maxY - minY, 0.5)));
    this.center = { x: (minX + maxX) / 2, y: (minY + maxY) / 2 };
    this.follow = false;
    this.requestDraw(true);
    this.canvas.dispatchEvent(new CustomEvent('followchange'));
  }

  zoom(factor, sx, sy) {
    const before = sx === undefined ? null : this.toWorld(sx, sy);
    this.scale = Math.max(5, Math.min(2000, this.scale * factor));
    if (before && !this.follow) {
      const after = this.toWorld(sx, sy);
      this.center.x += before.x - after.x;
      this.center.y += before.y - after.y;
    }
    this.requestDraw(true);
  }

  setFollow(on) {
    this.follow = on;
    if (on && this.pose) this.center = { x: this.pose.x, y: this.pose.y };
    this.requestDraw(true);
    this.canvas.dispatchEvent(new CustomEvent('followchange'));
  }

  toWorld(sx, sy) {
    const { width, height } = this.canvas.getBoundingClientRect();
    return { x: this.center.x + (sx - width / 2) / this.scale, y: this.center.y - (sy - height / 2) / this.scale };
  }

  _installInput() {
    const c = this.canvas;
    c.addEventListener('pointerdown', (e) => {
      c.setPointerCapture(e.pointerId);
      this.pointers.set(e.pointerId, { x: e.offsetX, y: e.offsetY });
    });
    c.addEventListener('pointermove', (e) => {
      const prev = this.pointers.get(e.pointerId);
      if (!prev) return;
      if (this.pointers.size === 1) {
        const dx = e.offsetX - prev.x, dy = e.offsetY - prev.y;
        if (dx || dy) {
          if (this.follow) this.setFollow(false);
          this.center.x -= dx / this.scale;
          this.center.y += dy / this.scale;
          this.requestDraw(true);
        }
      } else if (this.pointers.size === 2) {
        const [a, b] = [...this.pointers.entries()];
        const other = a[0] === e.pointerId ? b[1] : a[1];
        const d0 = Math.hypot(prev.x - other.x, prev.y - other.y);
        const d1 = Math.hypot(e.offsetX - other.x, e.offsetY - other.y);
        if (d0 > 0) this.zoom(d1 / d0, (e.offsetX + other.x) / 2, (e.offsetY + other.y) / 2);
      }
      this.pointers.set(e.pointerId, { x: e.offsetX, y: e.offsetY });
    });
    const up = (e) => this.pointers.delete(e.pointerId);
    c.addEventListener('pointerup', up);
    c.addEventListener('pointercancel', up);
    c.addEventListener('wheel', (e) => {
      e.preventDefault();
      this.zoom(Math.exp(-e.deltaY * 0.0015), e.offsetX, e.offsetY);
    }, { passive: false });
  }

  draw() {
    this.dirty = false;
    this.frames += 1;
    const c = this.canvas, ctx = this.ctx;
    const dpr = window.devicePixelRatio || 1;
    const { width, height } = c.getBoundingClientRect();
    const pw = Math.max(1, Math.round(width * dpr)), ph = Math.max(1, Math.round(height * dpr));
    if (c.width !== pw || c.height !== ph) { c.width = pw; c.height = ph; }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = '#fbfbf8';
    ctx.fillRect(0, 0, width, height);
    const s = this.scale;
    // world -> CSS px: flip y so that +y is up (REP-103 seen from above)
    ctx.save();
    ctx.translate(width / 2, height / 2);
    ctx.scale(s, -s);
    ctx.translate(-this.center.x, -this.center.y);
    const px = 1 / s;
    this._grid(ctx, width, height, px);
    // walls
    ctx.strokeStyle = '#2f3140';
    ctx.lineWidth = Math.max(0.03, 2.5 * px);
    ctx.lineCap = 'round';
    ctx.beginPath();
    for (const [x1, y1, x2, y2] of this.walls) { ctx.moveTo(x1, y1); ctx.lineTo(x2, y2); }
    ctx.stroke();
    // trail, in pieces (it breaks at resets, reconnects and jumps)
    if (this.trail.length > 1) {
      ctx.strokeStyle = 'rgba(37, 99, 235, 0.55)';
      ctx.lineWidth = 2 * px;
      ctx.beginPath();
      let pen = false;
      for (const p of this.trail) {
        if (p === null) { pen = false; continue; }
        if (pen) ctx.lineTo(p[0], p[1]); else { ctx.moveTo(p[0], p[1]); pen = true; }
      }
      if (pen && this.pose) ctx.lineTo(this.pose.x, this.pose.y);
      ctx.stroke();
    }
    const r = Math.max(this.radius, MIN_ROBOT_PX * px);
    // LiDAR: range circle, rays, returns
    if (this.laser && this.showRange && this.rangeMax > 0) {
      ctx.strokeStyle = 'rgba(192, 38, 211, 0.45)';
      ctx.lineWidth = px;
      ctx.setLineDash([6 * px, 4 * px]);
      ctx.beginPath(); ctx.arc(this.laser.x, this.laser.y, this.rangeMax, 0, 2 * Math.PI); ctx.stroke();
      ctx.setLineDash([]);
    }
    const scan = this.scan;
    if (this.laser && this.showRays) {
      ctx.strokeStyle = 'rgba(192, 38, 211, 0.18)';
      ctx.lineWidth = px;
      ctx.beginPath();
      for (let i = 0; i + 1 < scan.length; i += 2) { ctx.moveTo(this.laser.x, this.laser.y); ctx.lineTo(scan[i], scan[i + 1]); }
      ctx.stroke();
    }
    ctx.fillStyle = SCAN_COLOUR;
    const dot = Math.max(3 * px, 0.014);
    for (let i = 0; i + 1 < scan.length; i += 2) ctx.fillRect(scan[i] - dot / 2, scan[i + 1] - dot / 2, dot, dot);
    // other robots: grey footprints with their names
    for (const [name, o] of this.others) {
      ctx.save();
      ctx.translate(o.x, o.y);
      ctx.fillStyle = 'rgba(100, 116, 139, 0.35)';
      ctx.strokeStyle = '#475569';
      ctx.lineWidth = 2 * px;
      ctx.beginPath();
      ctx.arc(0, 0, r, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      ctx.beginPath();
      ctx.moveTo(0, 0);
      ctx.lineTo(r * Math.cos(o.theta), r * Math.sin(o.theta));
      ctx.stroke();
      ctx.scale(px, -px);
      ctx.fillStyle = '#334155';
      ctx.font = '11px system-ui, sans-serif';
      ctx.fillText(name || '(default)', r * s + 3, -r * s - 3);
      ctx.restore();
    }
    // a contact: an orange ring on the robot and a mark where it touched
    const hit = this.contact;
    if (hit && this.pose) {
      ctx.strokeStyle = '#ea580c';
      ctx.lineWidth = 4 * px;
      ctx.beginPath(); ctx.arc(this.pose.x, this.pose.y, r + 4 * px, 0, 2 * Math.PI); ctx.stroke();
      ctx.fillStyle = '#ea580c';
      ctx.beginPath(); ctx.arc(hit.x, hit.y, 5 * px, 0, 2 * Math.PI); ctx.fill();
    }
    // the true pose (a realism profile: odometry drifts from it): a dashed ghost
    const ghost = this.ghost;
    if (ghost) {
      ctx.save();
      ctx.translate(ghost.x, ghost.y);
      ctx.strokeStyle = '#7c3aed';
      ctx.fillStyle = 'rgba(124, 58, 237, 0.10)';
      ctx.lineWidth = 2 * px;
      ctx.setLineDash([5 * px, 4 * px]);
      ctx.beginPath(); ctx.arc(0, 0, r, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      ctx.setLineDash([]);
      ctx.beginPath(); ctx.moveTo(0, 0); ctx.lineTo(r * 1.3 * Math.cos(ghost.theta), r * 1.3 * Math.sin(ghost.theta)); ctx.stroke();
      ctx.scale(px, -px);
      ctx.fillStyle = '#6d28d9';
      ctx.font = '11px system-ui, sans-serif';
      ctx.fillText('true pose', r * s + 3, r * s + 12);
      ctx.restore();
    }
    // robot
    if (this.pose) {
      const { x, y, theta } = this.pose;
      ctx.translate(x, y);
      ctx.rotate(theta);
      ctx.fillStyle = 'rgba(22, 163, 74, 0.30)';
      ctx.strokeStyle = '#15803d';
      ctx.lineWidth = 2 * px;
      ctx.beginPath();
      ctx.arc(0, 0, r, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      // heading: a dark arrow from the centre past the footprint
      ctx.strokeStyle = '#052e16';
      ctx.lineWidth = Math.max(3 * px, 0.015);
      ctx.beginPath();
      ctx.moveTo(0, 0);
      ctx.lineTo(r * 1.2, 0);
      ctx.stroke();
      ctx.beginPath();
      ctx.moveTo(r * 1.6, 0);
      ctx.lineTo(r * 1.1, r * 0.35);
      ctx.lineTo(r * 1.1, -r * 0.35);
      ctx.closePath();
      ctx.fillStyle = '#052e16';
      ctx.fill();
    }
    ctx.restore();
    // scale bar
    ctx.fillStyle = '#475569';
    ctx.font = '12px system-ui, sans-serif';
    ctx.fillText(`1 m = ${Math.round(s)} px`, 8, height - 8);
    if (hit && hit.other !== undefined) {
      ctx.fillStyle = '#9a3412';
      ctx.font = '600 13px system-ui, sans-serif';
      ctx.fillText(`contact: ${hit.other === 'wall' ? 'a wall' : `robot ${hit.other}`}`, 8, height - 26);
    }
    if (this.stale) {
      // the data is old (link lost): grey everything and say so
      ctx.fillStyle = 'rgba(241, 245, 249, 0.72)';
      ctx.fillRect(0, 0, width, height);
      ctx.fillStyle = '#475569';
      ctx.font = '600 15px system-ui, sans-serif';
      ctx.fillText('no live data: last known positions', 12, 72);
    }
  }

  _grid(ctx, width, height, px) {
    const half = { x: width / 2 / this.scale, y: height / 2 / this.scale };
    const x0 = this.center.x - half.x, x1 = this.center.x + half.x;
    const y0 = this.center.y - half.y, y1 = this.center.y + half.y;
    let step = 1;
    while (step * this.scale < 25) step *= 5;
    while (step * this.scale > 250) step /= 5;
    ctx.strokeStyle = '#e5e7eb';
    ctx.lineWidth = px;
    ctx.beginPath();
    for (let x = Math.floor(x0 / step) * step; x <= x1; x += step) { ctx.moveTo(x, y0); ctx.lineTo(x, y1); }
    for (let y = Math.floor(y0 / step) * step; y <= y1; y += step) { ctx.moveTo(x0, y); ctx.lineTo(x1, y); }
    ctx.stroke();
    // origin axes: x red, y green (the usual RGB = XYZ convention)
    ctx.lineWidth = 3 * px;
    ctx.strokeStyle = '#ef4444';
    ctx.beginPath(); ctx.moveTo(0, 0); ctx.lineTo(0.5, 0); ctx.stroke();
    ctx.strokeStyle = '#22c55e';
    ctx.beginPath(); ctx.moveTo(0, 0); ctx.lineTo(0, 0.5); ctx.stroke();
  }
}

/**
 * Scan ranges -> world points (flat [x0, y0, x1, y1, ...]), using the laser mount
 * (base_link -> laser) and the robot pose; also the laser's position and the nearest range.
 */
export function scanToWorld(scan, mount, pose) {
  const out = [];
  let nearest = Infinity;
  if (!pose) return { points: out, nearest, laser: null };
  const { ranges, angle_min: amin, angle_increment: inc, range_min: rmin, range_max: rmax } = scan;
  const cm = Math.cos(mount.yaw), sm = Math.sin(mount.yaw);
  const cp = Math.cos(pose.theta), sp = Math.sin(pose.theta);
  for (let i = 0; i < ranges.length; i++) {
    const r = ranges[i];
    // null is how JSON carries inf/NaN: no return (REP-117); range_max also reads "nothing"
    if (r === null || !Number.isFinite(r) || r < rmin || r >= rmax) continue;
    if (r < nearest) nearest = r;
    const a = amin + i * inc;
    const lx = r * Math.cos(a), ly = r * Math.sin(a);
    const bx = mount.x + cm * lx - sm * ly, by = mount.y + sm * lx + cm * ly;
    out.push(pose.x + cp * bx - sp * by, pose.y + sp * bx + cp * by);
  }
  const laser = { x: pose.x + cp * mount.x - sp * mount.y, y: pose.y + sp * mount.x + cp * mount.y };
  return { points: out, nearest, laser };
}

/** LINE_LIST marker points -> [x1, y1, x2, y2] segments (marker pose assumed identity). */
export function markerSegments(marker) {
  const pts = marker.points || [];
  const segs = [];
  for (let i = 0; i + 1 < pts.length; i += 2) segs.push([pts[i].x, pts[i].y, pts[i + 1].x, pts[i + 1].y]);
  return segs;
}

/** Yaw of a geometry_msgs/Quaternion (rotation about z). */
export function yawOf(q) {
  return Math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z));
}
