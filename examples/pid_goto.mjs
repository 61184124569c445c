#!/usr/bin/env node
// Drive to a goal position (and heading) with two PID loops at 10 Hz, over rosbridge (roslibjs).
// The same controller as pid_goto.py; works unchanged against simbridge and the real robot.
//
//   cd examples && npm ci        # roslib 2.1.0 from package-lock.json (or any roslib 1.x or 2.x)
//   node pid_goto.mjs --url ws://127.0.0.1:9090 --goal 1.0 0.5 --heading 1.57
//
// ROSLIB_MODULE=/path/to/roslib/entry.js picks another copy of roslib (the tests use theirs).
// Prints one JSON line at the end ({reached, x, y, yaw, distance_error, heading_error,
// seconds}); exit code 0 when the goal was reached in time.

import { parseArgs } from 'node:util';
import { pathToFileURL } from 'node:url';

const { values: opt } = parseArgs({
  options: {
    url: { type: 'string', default: 'ws://127.0.0.1:9090' },
    goal: { type: 'string', multiple: true },
    heading: { type: 'string' },
    tolerance: { type: 'string', default: '0.05' },
    'heading-tolerance': { type: 'string', default: '0.05' },
    'max-speed': { type: 'string', default: '0.3' },
    timeout: { type: 'string', default: '30' },
  },
  allowPositionals: true,
  strict: false,
});
// `--goal X Y`: parseArgs takes the first number, the second comes as a positional
const rest = process.argv.slice(process.argv.indexOf('--goal') + 1);
const [gx, gy] = process.argv.includes('--goal') ? rest.slice(0, 2).map(Number) : [1.0, 0.5];
const heading = opt.heading === undefined ? null : Number(opt.heading);
const tolerance = Number(opt.tolerance);
const headingTolerance = Number(opt['heading-tolerance']);
const maxSpeed = Number(opt['max-speed']);
const timeoutS = Number(opt.timeout);

const where = process.env.ROSLIB_MODULE;
const mod = await import(where ? pathToFileURL(where).href : 'roslib').catch((err) => {
  if (where || err.code !== 'ERR_MODULE_NOT_FOUND') throw err;
  console.error('pid_goto.mjs needs roslib: run `npm ci` in examples/ (roslib 2.1.0, from package-lock.json)');
  process.exit(1);
});
const ROSLIB = mod.Ros ? mod : mod.default; // roslib 2 (ESM namespace) or 1 (CommonJS)

const wrap = (a) => Math.atan2(Math.sin(a), Math.cos(a));
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

class PID {
  constructor(kp, ki, kd, limit) {
    Object.assign(this, { kp, ki, kd, limit, integral: 0, previous: null });
  }

  update(error, dt) {
    this.integral += error * dt;
    const bound = this.ki ? this.limit / this.ki : 0;
    this.integral = Math.max(-bound, Math.min(bound, this.integral)); // anti-windup
    const derivative = this.previous === null ? 0 : (error - this.previous) / dt;
    this.previous = error;
    const out = this.kp * error + this.ki * this.integral + this.kd * derivative;
    return Math.max(-this.limit, Math.min(this.limit, out));
  }
}

const ros = new ROSLIB.Ros({ url: opt.url, encoding: 'utf8' });
await new Promise((resolve, reject) => {
  ros.on('connection', resolve);
  ros.on('error', (e) => reject(new Error(`cannot connect to ${opt.url}: ${e?.message ?? e}`)));
});
const odom = new ROSLIB.Topic({ ros, name: '/odom', messageType: 'nav_msgs/msg/Odometry' });
// Newer ROS 2 stacks (diff_drive_controller since Jazzy, simbridge with robot.cmd_vel_stamped)
// want geometry_msgs/msg/TwistStamped on /cmd_vel: ask rosapi which type it has.
const TWIST = 'geometry_msgs/msg/Twist';
const cmdVelType = await new Promise((resolve) => {
  ros.getTopicType('/cmd_vel', (type) => resolve(type || TWIST), () => resolve(TWIST));
});
const cmdVel = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: cmdVelType });
cmdVel.advertise();

let pose = null;
odom.subscribe((msg) => {
  const p = msg.pose.pose;
  const q = p.orientation;
  const yaw = Math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z));
  pose = [p.position.x, p.position.y, yaw];
});
const twist = (v, w) => {
  const t = { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } };
  if (!cmdVelType.endsWith('TwistStamped')) return t;
  const ms = Date.now();
  const stamp = { sec: Math.floor(ms / 1000), nanosec: (ms % 1000) * 1e6 };
  return { header: { stamp, frame_id: 'base_link' }, twist: t };
};

const start = performance.now();
while (pose === null) {
  if (performance.now() - start > 10000) throw new Error('no /odom within 10 s');
  await sleep(10);
}

const headingPid = new PID(2.0, 0.1, 0.1, 1.5);
const positionPid = new PID(0.8, 0.05, 0.05, maxSpeed);
const period = 0.1; // 10 Hz
const t0 = performance.now();
let tick = 0;
let reached = false;
while ((performance.now() - t0) / 1000 < timeoutS) {
  const [x, y, yaw] = pose;
  const dist = Math.hypot(gx - x, gy - y);
  const atGoal = dist < tolerance;
  let headingErr;
  let linear = 0;
  if (atGoal && heading === null) {
    reached = true;
    break;
  }
  if (atGoal) {
    headingErr = wrap(heading - yaw);
    if (Math.abs(headingErr) < headingTolerance) {
      reached = true;
      break;
    }
  } else {
    headingErr = wrap(Math.atan2(gy - y, gx - x) - yaw);
    linear = positionPid.update(dist, period) * Math.max(0, Math.cos(headingErr));
  }
  cmdVel.publish(twist(linear, headingPid.update(headingErr, period)));
  tick += 1;
  await sleep(Math.max(0, t0 + tick * period * 1000 - performance.now())); // absolute deadlines
}

cmdVel.publish(twist(0, 0));
await sleep(300); // let the stop command leave before closing
const [x, y, yaw] = pose;
const result = {
  reached,
  x,
  y,
  yaw,
  distance_error: Math.hypot(gx - x, gy - y),
  heading_error: heading === null ? 0 : Math.abs(wrap(heading - yaw)),
  seconds: Math.round((performance.now() - t0) / 10) / 100,
};
ros.close();
console.log(JSON.stringify(result));
process.exit(reached ? 0 : 1);
