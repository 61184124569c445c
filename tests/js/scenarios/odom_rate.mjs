// Subscribe /odom and collect args.count (default 41) messages.
// Returns receive times (performance.now() ms), header stamps (ms) and the first and last message.
import { collect, makeTopic } from '../lib.mjs';

export default async function odomRate(ROSLIB, ros, args) {
  const count = args.count ?? 41;
  // 20 Hz nominal: allow 3x the nominal duration plus connection slack.
  const timeoutMs = args.timeout_ms ?? 5000 + count * 150;
  const topic = makeTopic(ROSLIB, ros, '/odom', 'nav_msgs/msg/Odometry');
  const { messages, times } = await collect(topic, count, timeoutMs);
  return {
    count: messages.length,
    times,
    stamps: messages.map((m) => m.header.stamp.sec * 1e3 + m.header.stamp.nanosec / 1e6),
    first: messages[0],
    last: messages[messages.length - 1],
  };
}
