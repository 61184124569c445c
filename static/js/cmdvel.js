// The velocity-command type: geometry_msgs/msg/Twist, or TwistStamped as newer ROS 2 robots
// expect (Jazzy's diff_drive_controller; lichtblick #941). In 'auto' the page asks the server
// which type the robot's cmd_vel has (/rosapi/topic_type, which real rosbridge serves too), so
// pointing the page at a real robot publishes what that robot takes. The override (auto,
// Twist, TwistStamped) lives in ?cmd_vel_type= like ?url=.

export const TWIST = 'geometry_msgs/msg/Twist';
export const TWIST_STAMPED = 'geometry_msgs/msg/TwistStamped';
export const CHOICES = ['auto', 'Twist', 'TwistStamped'];
const FIXED = { Twist: TWIST, TwistStamped: TWIST_STAMPED };

/** Whether a type name (either spelling) is TwistStamped. */
export const isStamped = (type) => /^geometry_msgs\/(msg\/)?TwistStamped$/.test(type || '');

/** Returns the choice in ?cmd_vel_type= ('auto' when absent or unknown). */
export function choiceFromUrl(loc = window.location) {
  const given = new URLSearchParams(loc.search).get('cmd_vel_type') || '';
  const short = given.replace(/^geometry_msgs\/(msg\/)?/, '');
  return CHOICES.includes(short) ? short : 'auto';
}

/** One command as a message of `type`; TwistStamped gets the page's clock and base_link. */
export function velocityMessage(type, v, w, nowMs = Date.now()) {
  const twist = { linear: { x: v, y: 0, z: 0 }, angular: { x: 0, y: 0, z: w } };
  if (!isStamped(type)) return twist;
  const sec = Math.floor(nowMs / 1000);
  const stamp = { sec, nanosec: Math.round((nowMs - sec * 1000) * 1e6) };
  return { header: { stamp, frame_id: 'base_link' }, twist };
}

/** The Twist inside a Twist or TwistStamped message. */
export const twistOf = (m) => (m && m.twist && m.twist.linear ? m.twist : m);

/**
 * The type the page publishes on the robot's cmd_vel. Event 'change' when it changes.
 * `ready` is false while 'auto' is still asking the server (nothing is published then).
 */
export class CmdVelType extends EventTarget {
  constructor(choice = 'auto') {
    super();
    this.choice = choice;
    this.detected = null;    // what the server said (null: unknown, use Twist)
    this.pending = -1;       // detection in flight (its generation), -1 not asked yet, 0 done
    this.generation = 0;
  }

  /** Forget the answer (the link was lost: the next server may differ). */
  forget() {
    this.generation += 1;
    this.pending = -1;
  }

  get type() {
    if (this.choice !== 'auto') return FIXED[this.choice];
    return this.detected || TWIST;
  }

  get ready() { return this.choice !== 'auto' || this.pending === 0; }

  setChoice(choice) {
    const before = this.type;
    this.choice = CHOICES.includes(choice) ? choice : 'auto';
    if (this.type !== before) this.dispatchEvent(new CustomEvent('change'));
  }

  /** Ask the server for `topic`'s type (conn: a Connection); a missing answer means Twist. */
  async detect(conn, topic) {
    const generation = ++this.generation;
    this.pending = generation;
    const before = this.type;
    let found = null;
    try {
      const res = await conn.call('/rosapi/topic_type', 'rosapi/TopicType', { topic });
      if (res && /Twist(Stamped)?$/.test(res.type || '')) found = isStamped(res.type) ? TWIST_STAMPED : TWIST;
    } catch (err) { /* no rosapi, or not connected: keep Twist */ }
    if (generation !== this.generation) return; // a newer question (reconnect, other robot)
    this.detected = found;
    this.pending = 0;
    if (this.type !== before) this.dispatchEvent(new CustomEvent('change'));
    this.dispatchEvent(new CustomEvent('ready'));
  }
}
