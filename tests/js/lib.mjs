// Helpers shared by the scenarios in ./scenarios/.
//
// Every helper that waits does so for a *condition* and gives up after a
// timeout with a descriptive Error; nothing here sleeps and hopes.
// The helpers only use API that is identical in roslib 1.4.1 and 2.1.0
// (Topic.subscribe/unsubscribe/publish, Service.callService with
// success/failure callbacks); where the libraries differ the caller passes
// `lib` ("roslib1" | "roslib2").

/** Resolve after `ms` milliseconds. */
export function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

/** Milliseconds from a monotonic clock (same clock as the timestamps we report). */
export function now() {
  return performance.now();
}

/**
 * Race `promise` against a timer; reject with `Error("timeout: <what> ...")`.
 * The timer is always cleared, so it never keeps the process alive.
 */
export function withTimeout(promise, timeoutMs, what = 'operation') {
  let timer;
  const timeout = new Promise((_, reject) => {
    timer = setTimeout(
      () => reject(new Error(`timeout: ${what} did not finish within ${timeoutMs} ms`)),
      timeoutMs,
    );
  });
  return Promise.race([promise, timeout]).finally(() => clearTimeout(timer));
}

/**
 * Poll `predicate` (every `intervalMs`) until it returns a truthy value and
 * resolve with that value; reject after `timeoutMs`.
 */
export function waitFor(predicate, timeoutMs, what = 'condition', intervalMs = 5) {
  return new Promise((resolve, reject) => {
    const deadline = now() + timeoutMs;
    const tick = () => {
      let value;
      try {
        value = predicate();
      } catch (err) {
        reject(err);
        return;
      }
      if (value) {
        resolve(value);
      } else if (now() >= deadline) {
        reject(new Error(`timeout: ${what} not met within ${timeoutMs} ms`));
      } else {
        setTimeout(tick, intervalMs);
      }
    };
    tick();
  });
}

/** Create a ROSLIB.Topic (same constructor options in both versions). */
export function makeTopic(ROSLIB, ros, name, messageType, extra = {}) {
  return new ROSLIB.Topic({ ros, name, messageType, ...extra });
}

/**
 * Wrap a message the way each library's docs do it: roslib 1.4.1 has
 * ROSLIB.Message (a plain copy of the fields), 2.1.0 dropped it and takes
 * plain objects. Both end up JSON.stringify'd identically.
 */
export function makeMessage(ROSLIB, lib, fields) {
  return lib === 'roslib1' ? new ROSLIB.Message(fields) : fields;
}

/**
 * Subscribe to `topic` (a ROSLIB.Topic) and resolve with
 * `{messages, times}` once `n` messages have arrived (`times[i]` is the
 * performance.now() receive time of `messages[i]`). Unsubscribes when done
 * unless `keep` is set. `onMessage(msg, t)` sees every message as it arrives.
 */
export function collect(topic, n, timeoutMs, { keep = false, onMessage = null } = {}) {
  const messages = [];
  const times = [];
  let callback;
  let timer;
  const done = new Promise((resolve, reject) => {
    timer = setTimeout(() => {
      reject(
        new Error(
          `timeout: got ${messages.length} of ${n} message(s) on ${topic.name} within ${timeoutMs} ms`,
        ),
      );
    }, timeoutMs);
    callback = (msg) => {
      const t = now();
      if (messages.length >= n) return;
      messages.push(msg);
      times.push(t);
      try {
        if (onMessage) onMessage(msg, t);
      } catch (err) {
        reject(err);
        return;
      }
      if (messages.length >= n) resolve({ messages, times });
    };
    topic.subscribe(callback);
  });
  return done.finally(() => {
    clearTimeout(timer);
    if (!keep) topic.unsubscribe(callback);
  });
}

/** First message on `topic`. */
export async function firstMessage(topic, timeoutMs, opts = {}) {
  const { messages } = await collect(topic, 1, timeoutMs, opts);
  return messages[0];
}

/** Error raised when a service call's failure callback fires (`result: false`). */
export class ServiceFailure extends Error {
  constructor(service, values) {
    super(`service ${service} failed: ${typeof values === 'string' ? values : JSON.stringify(values)}`);
    this.name = 'ServiceFailure';
    this.values = values;
  }
}

/**
 * Promise wrapper for ROSLIB.Service.callService: resolves with the response
 * values, rejects with ServiceFailure(values) when the library calls the
 * failure callback, or with a timeout Error. (Neither library times out a
 * call by itself, so the timeout here is essential.)
 */
export function callService(service, request = {}, timeoutMs = 5000) {
  const p = new Promise((resolve, reject) => {
    service.callService(
      request,
      (response) => resolve(response),
      (values) => reject(new ServiceFailure(service.name, values)),
    );
  });
  return withTimeout(p, timeoutMs, `call of service ${service.name}`);
}

/**
 * Promisify a Ros rosapi helper that takes (callback, failedCallback) as its
 * last two arguments, e.g. `rosapi(ros, 'getTopics')`,
 * `rosapi(ros, 'getTopicType', ['/odom'])`.
 */
export function rosapi(ros, method, args = [], timeoutMs = 5000) {
  const p = new Promise((resolve, reject) => {
    ros[method](...args, resolve, (err) => reject(new ServiceFailure(`Ros.${method}`, err)));
  });
  return withTimeout(p, timeoutMs, `Ros.${method}`);
}

/** Yaw (rad) from a geometry_msgs/Quaternion {x,y,z,w}. */
export function yawFromQuaternion(q) {
  const { x = 0, y = 0, z = 0, w = 1 } = q || {};
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

/** {x, y, yaw} (plus the raw quaternion z, w) of a nav_msgs/Odometry message. */
export function poseOf(odom) {
  const p = odom.pose.pose;
  return {
    x: p.position.x,
    y: p.position.y,
    yaw: yawFromQuaternion(p.orientation),
    qz: p.orientation.z,
    qw: p.orientation.w,
  };
}

/** True when two nav_msgs/Odometry messages carry exactly the same pose. */
export function samePose(a, b) {
  const pa = a.pose.pose;
  const pb = b.pose.pose;
  return (
    pa.position.x === pb.position.x &&
    pa.position.y === pb.position.y &&
    pa.position.z === pb.position.z &&
    pa.orientation.x === pb.orientation.x &&
    pa.orientation.y === pb.orientation.y &&
    pa.orientation.z === pb.orientation.z &&
    pa.orientation.w === pb.orientation.w
  );
}
