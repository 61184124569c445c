// TF clients against simbridge's tf2_web_republisher: roslib 1.x TFClient in service mode
// (groovyCompatibility: false -> /republish_tfs), roslib 2.x ROS2TFClient (action). Reads
// odom -> base_link and odom -> laser, turns the robot, and waits for the update.
import { waitFor, withTimeout } from '../lib.mjs';

export default async function tfClients(ROSLIB, ros, args, lib, ctx) {
  const ms = args.timeout_ms ?? 5000;
  let tfRos = ros;
  let tf;
  const opts = { fixedFrame: 'odom', angularThres: 0.01, transThres: 0.001, rate: 20 };
  if (lib === 'roslib1') {
    tfRos = new ROSLIB.Ros({ url: ctx.url, groovyCompatibility: false, encoding: 'utf8' });
    await withTimeout(new Promise((resolve, reject) => { tfRos.on('connection', resolve); tfRos.on('error', reject); }), ms, 'tf connection');
    tf = new ROSLIB.TFClient({ ros: tfRos, ...opts });
  } else {
    tf = new ROSLIB.ROS2TFClient({ ros, ...opts });
  }
  const latest = {};
  const counts = { base_link: 0, laser: 0 };
  const plainTf = (t) => ({
    translation: { x: t.translation.x, y: t.translation.y, z: t.translation.z },
    rotation: { x: t.rotation.x, y: t.rotation.y, z: t.rotation.z, w: t.rotation.w },
  });
  tf.subscribe('base_link', (t) => { latest.base_link = plainTf(t); counts.base_link++; });
  tf.subscribe('/laser', (t) => { latest.laser = plainTf(t); counts.laser++; });
  await waitFor(() => latest.base_link && latest.laser, ms, 'first transforms');
  const first = { ...latest };
  const cmd = new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: 'geometry_msgs/msg/Twist' });
  const timer = setInterval(() => cmd.publish({ angular: { z: 1.0 } }), 50);
  try {
    await waitFor(() => latest.base_link.rotation.z > 0.1, ms, 'base_link to turn');
  } finally {
    clearInterval(timer);
    cmd.publish({});
  }
  const turned = { ...latest };
  tf.dispose();
  if (tfRos !== ros) tfRos.close();
  return { first, turned, counts };
}
