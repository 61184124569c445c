// The course's PID lab: heading and position control at 10 Hz, run in the page.
// The PID class below is also shown verbatim in the page as the copyable example.

export const PID_RATE_HZ = 10;

export class PID {
  constructor(kp, ki, kd, limit) {
    this.kp = kp; this.ki = ki; this.kd = kd;
    this.limit = limit;        // |output| limit (the robot's velocity limit)
    this.integral = 0;
    this.prevError = null;
  }
  update(error, dt) {
    const derivative = this.prevError === null ? 0 : (error - this.prevError) / dt;
    this.prevError = error;
    const unclamped = this.kp * error + this.ki * (this.integral + error * dt) + this.kd * derivative;
    // anti-windup: integrate only while the output is not saturated
    if (Math.abs(unclamped) < this.limit) this.integral += error * dt;
    const out = this.kp * error + this.ki * this.integral + this.kd * derivative;
    return Math.max(-this.limit, Math.min(this.limit, out));
  }
}

export function wrapAngle(a) {
  return Math.atan2(Math.sin(a), Math.cos(a));
}

/**
 * Step-response figures: the response is given as (t, y) with the step from y0 to ys at t0.
 * Overshoot: the largest excursion past ys, as % of |ys - y0|. Settling time: from t0 to the
 * last time |y - ys| left the band (band = max(bandFraction * |step|, bandMin)); null while
 * still outside the band.
 */
export function stepFigures(samples, y0, ys, t0, bandFraction = 0.02, bandMin = 0) {
  const step = ys - y0;
  const dir = Math.sign(step) || 1;
  const band = Math.max(Math.abs(step) * bandFraction, bandMin);
  let peak = 0, lastOut = null, inBand = false;
  for (const [t, y] of samples) {
    if (t < t0) continue;
    peak = Math.max(peak, (y - ys) * dir);
    if (Math.abs(y - ys) > band) { lastOut = t; inBand = false; } else inBand = true;
  }
  return {
    overshootPct: Math.abs(step) > 1e-9 ? (100 * peak) / Math.abs(step) : 0,
    settlingTime: inBand ? (lastOut === null ? 0 : lastOut - t0) : null,
    band,
    error: samples.length ? ys - samples[samples.length - 1][1] : null,
  };
}

/**
 * The lab's controller. mode 'heading': omega = PID(wrap(setpoint - theta)), v = 0.
 * mode 'position': v = PID(distance along the start->goal line), omega = 2 * bearing error,
 * v scaled by cos(bearing error) (no driving while facing away).
 */
export class PidLab {
  constructor(publish, limits) {
    this.publish = publish;     // (v, w) -> bool
    this.limits = limits;       // () -> {v, w}
    this.running = false;
    this.timer = null;
    this.samples = [];          // [t, y, setpoint, command]
  }

  /** Start a step from the current pose; getPose() returns the latest {x, y, theta}. */
  start(mode, setpoint, gains, getPose) {
    this.stop(false);
    const lim = this.limits();
    const pose = getPose();
    this.mode = mode;
    this.setpoint = setpoint;
    this.pose = getPose;
    this.t0 = performance.now() / 1000;
    this.samples = [];
    if (mode === 'heading') {
      this.pid = new PID(gains.kp, gains.ki, gains.kd, lim.w);
      this.y0 = pose.theta;
      // unwrap the setpoint near the start heading, so the plotted step is the one driven
      this.ys = pose.theta + wrapAngle(setpoint.theta - pose.theta);
    } else {
      this.pid = new PID(gains.kp, gains.ki, gains.kd, lim.v);
      this.start0 = { x: pose.x, y: pose.y };
      const dx = setpoint.x - pose.x, dy = setpoint.y - pose.y;
      this.length = Math.hypot(dx, dy);
      this.dir = this.length > 1e-9 ? { x: dx / this.length, y: dy / this.length } : { x: 1, y: 0 };
      this.y0 = 0;
      this.ys = this.length;
    }
    this.running = true;
    this.timer = setInterval(() => this._tick(), 1000 / PID_RATE_HZ);
    this._tick();
  }

  /** Progress measure plotted: heading (rad, unwrapped near the step) or distance along the line. */
  measure(pose) {
    if (this.mode === 'heading') return this.ys - wrapAngle(this.ys - pose.theta);
    return (pose.x - this.start0.x) * this.dir.x + (pose.y - this.start0.y) * this.dir.y;
  }

  _tick() {
    const pose = this.pose();
    if (!pose) return;
    const dt = 1 / PID_RATE_HZ;
    const lim = this.limits();
    let v = 0, w = 0;
    if (this.mode === 'heading') {
      this.pid.limit = lim.w;
      w = this.pid.update(wrapAngle(this.setpoint.theta - pose.theta), dt);
    } else {
      this.pid.limit = lim.v;
      const dx = this.setpoint.x - pose.x, dy = this.setpoint.y - pose.y;
      const along = dx * this.dir.x + dy * this.dir.y;   // signed: negative once past the goal
      const bearing = Math.hypot(dx, dy) > 0.03 ? wrapAngle(Math.atan2(dy, dx) - pose.theta) : 0;
      v = this.pid.update(along, dt) * Math.max(0, Math.cos(bearing));
      w = Math.max(-lim.w, Math.min(lim.w, 2.0 * bearing));
    }
    this.publish(v, w);
    const t = performance.now() / 1000 - this.t0;
    this.samples.push([t, this.measure(pose), this.ys, this.mode === 'heading' ? w : v]);
    if (this.onSample) this.onSample(this.samples[this.samples.length - 1]);
  }

  figures() {
    const band = this.mode === 'heading' ? 0.02 : 0.01; // at least 0.02 rad / 1 cm
    return stepFigures(this.samples.map((s) => [s[0], s[1]]), this.y0, this.ys, 0, 0.02, band);
  }

  /** Stop the controller; sends one zero unless told not to. */
  stop(sendZero = true) {
    if (this.timer !== null) clearInterval(this.timer);
    this.timer = null;
    const was = this.running;
    this.running = false;
    if (was && sendZero) this.publish(0, 0);
  }
}

/**
 * The copyable example: the PID class above plus a 10 Hz loop with roslib, current gains;
 * cmdVelType is the type the page sends (Twist, or TwistStamped with a header). link is where
 * the page drives: {url} its rosbridge (never with a token), {ns} the robot's namespace ('' for
 * the single robot), {token} whether the connection has one (the example then has a placeholder
 * for it, never the token itself). Without a url, the page's host on port 9090.
 */
export function exampleCode(mode, gains, setpoint, cmdVelType = 'geometry_msgs/msg/Twist', link = {}) {
  const loop = mode === 'heading'
    ? `const target = ${setpoint.theta.toFixed(3)};                 // rad
const pid = new PID(${gains.kp}, ${gains.ki}, ${gains.kd}, 2.5);   // limit: max angular velocity
setInterval(() => {
  if (!pose) return;
  const w = pid.update(wrapAngle(target - pose.theta), 0.1);
  cmdVel.publish(command(0, w));
}, 100);`
    : `const goal = { x: ${setpoint.x.toFixed(2)}, y: ${setpoint.y.toFixed(2)} };   // m
const pid = new PID(${gains.kp}, ${gains.ki}, ${gains.kd}, 0.5);   // limit: max linear velocity
let dir = null;                                   // start -> goal unit vector, set once
setInterval(() => {
  if (!pose) return;
  const dx = goal.x - pose.x, dy = goal.y - pose.y;
  if (!dir) { const d = Math.hypot(dx, dy) || 1; dir = { x: dx / d, y: dy / d }; }
  const along = dx * dir.x + dy * dir.y;          // distance left, negative once past
  const bearing = Math.hypot(dx, dy) > 0.03 ? wrapAngle(Math.atan2(dy, dx) - pose.theta) : 0;
  const v = pid.update(along, 0.1) * Math.max(0, Math.cos(bearing));
  const w = Math.max(-2.5, Math.min(2.5, 2.0 * bearing));
  cmdVel.publish(command(v, w));
}, 100);`;
  const command = cmdVelType.endsWith('TwistStamped')
    ? `function command(v, w) {                        // TwistStamped: header + twist
  const ms = Date.now(), sec = Math.floor(ms / 1000);
  return { header: { stamp: { sec, nanosec: (ms - sec * 1000) * 1e6 }, frame_id: 'base_link' },
           twist: { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } } };
}`
    : `function command(v, w) {
  return { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } };
}`;
  const topic = (name) => (link.ns ? `/${link.ns}/${name}` : `/${name}`);
  const address = link.url ? JSON.stringify(link.url) : "'ws://' + location.hostname + ':9090'";
  const sep = link.url && link.url.includes('?') ? '&' : '?';
  const url = link.token
    ? `const TOKEN = 'YOUR_TOKEN';                       // the one your instructor gave you
const ros = new ROSLIB.Ros({ url: ${address} + '${sep}token=' + encodeURIComponent(TOKEN) });`
    : `const ros = new ROSLIB.Ros({ url: ${address} });`;
  return `// ${mode} control at 10 Hz with roslib (browser: <script src="roslib.min.js">)
${url}
const cmdVel = new ROSLIB.Topic({ ros, name: '${topic('cmd_vel')}', messageType: '${cmdVelType}' });
const odom = new ROSLIB.Topic({ ros, name: '${topic('odom')}', messageType: 'nav_msgs/msg/Odometry' });
let pose = null;
odom.subscribe((m) => {
  const p = m.pose.pose, q = p.orientation;
  pose = { x: p.position.x, y: p.position.y, theta: 2 * Math.atan2(q.z, q.w) };
});
function wrapAngle(a) { return Math.atan2(Math.sin(a), Math.cos(a)); }
${command}

${PID.toString()}

${loop}
`;
}
