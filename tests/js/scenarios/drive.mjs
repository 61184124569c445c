// Drive the robot: subscribe /odom, take the first pose, publish /cmd_vel
// {linear:{x: v}, angular:{z: w}} at 10 Hz for args.seconds, publish one zero
// twist, then wait (args.stop_timeout_ms, default 3000) until two consecutive
// /odom messages carry an identical pose.
//
// args: v (m/s, default 0.5), w (rad/s, default 0), seconds (default 1),
//       full_twist (send all six Twist fields instead of only x / z),
//       ns (a named robot: /NS/odom and /NS/cmd_vel; default: the un-namespaced robot).
// Returns {start, final, ticks, twist_during_motion, odom_during_motion,
//          stop_ms} where start/final are {x, y, yaw, qz, qw}.
import { makeMessage, makeTopic, now, poseOf, samePose, waitFor } from '../lib.mjs';

function twist(v, w, full) {
  if (full) return { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } };
  return { linear: { x: v }, angular: { z: w } };
}

export default async function drive(ROSLIB, ros, args, lib) {
  const v = args.v ?? 0.5;
  const w = args.w ?? 0;
  const seconds = args.seconds ?? 1;
  const full = Boolean(args.full_twist);
  const firstTimeoutMs = args.timeout_ms ?? 5000;
  const stopTimeoutMs = args.stop_timeout_ms ?? 3000;

  const ns = args.ns ? `/${args.ns}` : '';
  const odomTopic = makeTopic(ROSLIB, ros, `${ns}/odom`, 'nav_msgs/msg/Odometry');
  const cmdTopic = makeTopic(ROSLIB, ros, `${ns}/cmd_vel`, 'geometry_msgs/msg/Twist');

  // phase: 'wait' (before first pose) -> 'moving' -> 'stopping'
  let phase = 'wait';
  let first = null;
  let last = null;
  let stoppedAt = null; // the second of two identical consecutive poses
  const motion = { count: 0, max_linear_x: -Infinity, min_linear_x: Infinity, max_angular_z: -Infinity, min_angular_z: Infinity };

  odomTopic.subscribe((msg) => {
    if (first === null) first = msg;
    if (phase === 'moving') {
      const t = msg.twist.twist;
      motion.count += 1;
      motion.max_linear_x = Math.max(motion.max_linear_x, t.linear.x);
      motion.min_linear_x = Math.min(motion.min_linear_x, t.linear.x);
      motion.max_angular_z = Math.max(motion.max_angular_z, t.angular.z);
      motion.min_angular_z = Math.min(motion.min_angular_z, t.angular.z);
    } else if (phase === 'stopping' && stoppedAt === null && last !== null && samePose(last, msg)) {
      stoppedAt = msg;
    }
    last = msg;
  });

  await waitFor(() => first, firstTimeoutMs, 'first /odom message');
  cmdTopic.advertise();
  phase = 'moving';

  // Publish at 10 Hz until `seconds` have elapsed (first tick immediately).
  const cmd = makeMessage(ROSLIB, lib, twist(v, w, full));
  const t0 = now();
  let ticks = 0;
  // The stop is scheduled on its own timer (not on the 100 ms interval, whose drift would
  // add a whole period to the motion).
  await new Promise((resolve) => {
    const tick = () => {
      cmdTopic.publish(cmd);
      ticks += 1;
    };
    const interval = setInterval(tick, 100);
    tick();
    setTimeout(() => {
      clearInterval(interval);
      resolve();
    }, Math.max(0, seconds * 1000 - (now() - t0)));
  });

  cmdTopic.publish(makeMessage(ROSLIB, lib, twist(0, 0, full)));
  phase = 'stopping';
  const stopStart = now();
  await waitFor(() => stoppedAt, stopTimeoutMs, 'two consecutive /odom messages with identical pose');
  const stopMs = now() - stopStart;

  odomTopic.unsubscribe();
  cmdTopic.unadvertise();
  const finite = (x) => (Number.isFinite(x) ? x : null);
  return {
    start: poseOf(first),
    final: poseOf(stoppedAt),
    ticks,
    twist_during_motion: {
      max_linear_x: finite(motion.max_linear_x),
      min_linear_x: finite(motion.min_linear_x),
      max_angular_z: finite(motion.max_angular_z),
      min_angular_z: finite(motion.min_angular_z),
    },
    odom_during_motion: motion.count,
    stop_ms: stopMs,
  };
}
