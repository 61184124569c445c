// roslibjs' default TFClient (ROS 1 actionlib in roslib 1.x) asking for every transform: roslibjs
// replaces a zero threshold by its default (`angularThres || 2.0`), so "send every time" is a
// negative threshold, which tf2_web_republisher honours. The robot is parked: only a
// republisher that sends every tick delivers more than the first transform.
import { waitFor } from '../lib.mjs';

export default async function tfEvery(ROSLIB, ros, args) {
  const ms = args.timeout_ms ?? 5000;
  const want = args.count ?? 5;
  const tf = new ROSLIB.TFClient({ ros, fixedFrame: 'odom', angularThres: -1, transThres: -1, rate: 10 });
  const times = [];
  let last = null;
  tf.subscribe('base_link', (t) => {
    times.push(performance.now());
    last = { x: t.translation.x, y: t.translation.y, w: t.rotation.w };
  });
  await waitFor(() => times.length >= want, ms, `${want} transforms of a parked robot`);
  tf.dispose();
  return { count: times.length, seconds: (times[times.length - 1] - times[0]) / 1000, last };
}
