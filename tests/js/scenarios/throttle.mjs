// Subscribe /odom with throttle_rate args.throttle_rate (ms) and collect args.count messages;
// returns receive times and header stamps (ms). rosbridge semantics: messages inside the window are dropped.
import { collect, makeTopic } from '../lib.mjs';

export default async function throttle(ROSLIB, ros, args) {
  const count = args.count ?? 6;
  const rate = args.throttle_rate ?? 200;
  const topic = makeTopic(ROSLIB, ros, '/odom', 'nav_msgs/msg/Odometry', { throttle_rate: rate, queue_length: 1 });
  const { messages, times } = await collect(topic, count, args.timeout_ms ?? 5000 + count * rate * 2);
  const stamps = messages.map((m) => m.header.stamp.sec * 1e3 + m.header.stamp.nanosec / 1e6);
  return { times, stamps };
}
