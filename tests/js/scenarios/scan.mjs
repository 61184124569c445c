// Subscribe /scan and return the first sensor_msgs/msg/LaserScan.
import { firstMessage, makeTopic } from '../lib.mjs';

export default async function scan(ROSLIB, ros, args) {
  const topic = makeTopic(ROSLIB, ros, '/scan', 'sensor_msgs/msg/LaserScan');
  return firstMessage(topic, args.timeout_ms ?? 5000);
}
