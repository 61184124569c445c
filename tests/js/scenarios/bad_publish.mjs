// Bad input through an unmodified roslibjs: publish ill-typed and non-finite /cmd_vel messages
// and an unadvertised, untyped topic; collect the server's status messages (roslibjs emits them
// as 'status' / 'status:<id>' events, recorded here by wrapping ros.emit), then prove the
// connection still works with a /chatter round trip and that the robot did not move.
import { makeMessage, makeTopic, waitFor } from '../lib.mjs';

export default async function badPublish(ROSLIB, ros, args, lib) {
  const ms = args.timeout_ms ?? 5000;
  const statuses = [];
  const emit = ros.emit.bind(ros);
  ros.emit = (name, ...rest) => {
    if (typeof name === 'string' && name.startsWith('status')) statuses.push(rest[0]);
    return emit(name, ...rest);
  };

  const odom = makeTopic(ROSLIB, ros, '/odom', 'nav_msgs/msg/Odometry');
  let last = null;
  odom.subscribe((m) => { last = m; });
  await waitFor(() => last, ms, 'first /odom');

  const cmd = makeTopic(ROSLIB, ros, '/cmd_vel', 'geometry_msgs/msg/Twist');
  cmd.publish(makeMessage(ROSLIB, lib, { linear: { x: 'fast' } }));
  cmd.publish(makeMessage(ROSLIB, lib, { linear: { x: NaN } }));       // JSON.stringify -> null
  cmd.publish(makeMessage(ROSLIB, lib, { linear: { x: 0.1 }, wings: 2 }));
  await waitFor(() => statuses.length >= 3, ms, 'three status messages');

  const chatter = makeTopic(ROSLIB, ros, '/chatter_after_bad', 'std_msgs/msg/String');
  let echoed = null;
  chatter.subscribe((m) => { echoed = m; });
  chatter.publish(makeMessage(ROSLIB, lib, { data: 'still alive' }));
  await waitFor(() => echoed, ms, 'round trip after bad input');

  const firstPose = last.pose.pose.position;
  const seen = last;
  await waitFor(() => last !== seen, ms, 'a later /odom');
  odom.unsubscribe();
  chatter.unsubscribe();
  return { statuses, echoed, x: last.pose.pose.position.x, x_before: firstPose.x };
}
