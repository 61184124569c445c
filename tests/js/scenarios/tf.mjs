// Subscribe /tf and /tf_static (tf2_msgs/msg/TFMessage) at the same time and
// return the first message of each: {tf, tf_static}.
import { firstMessage, makeTopic } from '../lib.mjs';

export default async function tf(ROSLIB, ros, args) {
  const timeoutMs = args.timeout_ms ?? 5000;
  const tfTopic = makeTopic(ROSLIB, ros, '/tf', 'tf2_msgs/msg/TFMessage');
  const staticTopic = makeTopic(ROSLIB, ros, '/tf_static', 'tf2_msgs/msg/TFMessage');
  const [tfMsg, staticMsg] = await Promise.all([
    firstMessage(tfTopic, timeoutMs),
    firstMessage(staticTopic, timeoutMs),
  ]);
  return { tf: tfMsg, tf_static: staticMsg };
}
