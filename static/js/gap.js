// The sim-to-real gap (issue 26): the true pose (/ground_truth) drawn as a ghost beside the
// odometry pose, and the position and heading error of /odom against it over time, as a plot
// with CSV and PNG export like the others. Under the ideal model both are the same pose: the
// ghost hides under the robot and the errors read 0. /odom and /ground_truth of one step carry
// the same stamp; they are paired by it.
import { LivePlot } from './plots.js';
import { yawOf } from './view.js';
import { wrapAngle } from './pid.js';

const KEPT = 40; // poses of either kind kept waiting for their pair (2 s at 20 Hz)
const SAME = 1e-9; // m, rad: a ghost this close to the robot is not drawn

const stampKey = (h) => `${h.stamp.sec}.${String(h.stamp.nanosec).padStart(9, '0')}`;
const poseOf = (m) => {
  const p = m.pose.pose;
  return { x: p.position.x, y: p.position.y, theta: yawOf(p.orientation) };
};

export class Gap {
  /**
   * @param conn    the page's Connection
   * @param view    the View the ghost is drawn in
   * @param box     the element of the error plot
   * @param timeOf  stamp (s) -> the plots' time axis (s), shared with the other plots
   */
  constructor(conn, view, box, timeOf) {
    this.conn = conn;
    this.view = view;
    this.timeOf = timeOf;
    this.odoms = new Map();  // stamp -> odometry pose, waiting for its truth
    this.truths = new Map(); // stamp -> {pose, stamp (s)}, waiting for its odometry
    this.latest = null;      // {position, heading}: the last error (m, rad)
    this.pairs = 0;
    this.plot = new LivePlot(box, [
      { label: 'position error (m)', color: '#dc2626' },
      { label: 'heading error (rad)', color: '#7c3aed' },
    ], { title: 'odometry error: /odom against /ground_truth', unit: '', file: 'odometry-error', columns: ['odom stamp'] });
  }

  /** Subscribe to a robot's true pose (`/ground_truth`, `/r1/ground_truth`); returns the unsubscribe. */
  subscribe(name) {
    this.clear();
    return this.conn.subscribe(name, 'nav_msgs/msg/Odometry', (m) => {
      const key = stampKey(m.header);
      keep(this.truths, key, { pose: poseOf(m), t: m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 });
      this._pair(key);
    });
  }

  /** An /odom message of the same robot (the page's own subscription hands it over). */
  onOdom(m) {
    const key = stampKey(m.header);
    keep(this.odoms, key, poseOf(m));
    this._pair(key);
  }

  _pair(key) {
    const odom = this.odoms.get(key), truth = this.truths.get(key);
    if (!odom || !truth) return;
    this.odoms.delete(key); this.truths.delete(key);
    const position = Math.hypot(odom.x - truth.pose.x, odom.y - truth.pose.y);
    const heading = wrapAngle(odom.theta - truth.pose.theta);
    this.latest = { position, heading };
    this.pairs += 1;
    this.view.setGhost(position > SAME || Math.abs(heading) > SAME ? truth.pose : null);
    this.plot.push(this.timeOf(truth.t), [position, heading], [key]);
  }

  /** Another robot, a reconnect: forget what waits for its pair; the plot breaks. */
  clear() {
    this.odoms.clear(); this.truths.clear();
    this.view.setGhost(null);
    this.latest = null;
    this.plot.gap(this.timeOf());
  }
}

function keep(map, key, value) {
  map.set(key, value);
  if (map.size > KEPT) map.delete(map.keys().next().value);
}
