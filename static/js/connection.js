// The link to a rosbridge server (roslib 1.4.1, global ROSLIB): reconnect with backoff,
// re-subscribe after every reconnect, per-topic message rates and ages.
//
// roslib 1.x does not reconnect by itself (roslibjs #497), so each attempt makes a fresh
// ROSLIB.Ros and the subscriptions recorded here are replayed on it.

const BACKOFF_MIN_MS = 500;
const BACKOFF_MAX_MS = 8000;
const RATE_WINDOW_MS = 2000;

/** Returns the rosbridge URL the page should use: ?url=, else ws://<page host>:9090. */
export function defaultUrl(loc = window.location) {
  const given = new URLSearchParams(loc.search).get('url');
  if (given) return given;
  const host = loc.hostname || '127.0.0.1';
  const bracketed = host.includes(':') ? `[${host}]` : host;
  return `ws://${bracketed}:9090`;
}

/** Per-topic message statistics. */
class TopicStats {
  constructor() { this.times = []; this.last = 0; this.count = 0; }
  hit(now) {
    this.last = now; this.count += 1; this.times.push(now);
    while (this.times.length && now - this.times[0] > RATE_WINDOW_MS) this.times.shift();
  }
  rate(now) {
    while (this.times.length && now - this.times[0] > RATE_WINDOW_MS) this.times.shift();
    // n messages span n - 1 periods; dividing by the time since the first of them also lets
    // the rate fall as soon as messages stop
    const n = this.times.length;
    return n >= 2 ? ((n - 1) * 1000) / Math.max(now - this.times[0], 1) : 0;
  }
}

/**
 * Events (EventTarget): 'state' (detail: {state, url, attempt, retryInMs}), 'connected',
 * 'lost', 'refused' (detail: {topic, text}: the server refused to let the page publish it).
 * state is one of 'connecting', 'connected', 'reconnecting', 'disconnected'.
 */
export class Connection extends EventTarget {
  constructor(url) {
    super();
    this.url = url;
    this.state = 'disconnected';
    this.attempt = 0;
    this.retryAt = 0;
    this.ros = null;
    this.subs = new Set();     // {name, type, callback, options, topic}
    this.pubs = new Map();     // name -> ROSLIB.Topic on the current ros
    this.stats = new Map();    // name -> TopicStats
    this.timer = null;
    this.lastError = '';
  }

  /** (Re)connect to `url` (default: the current one), resetting the backoff. */
  connect(url = this.url) {
    this.url = url;
    this.attempt = 0;
    this._teardown();
    this._open('connecting');
  }

  /** Close and stay closed. */
  disconnect() {
    this._teardown();
    this._setState('disconnected');
  }

  get connected() { return this.state === 'connected'; }

  _setState(state, extra = {}) {
    this.state = state;
    this.dispatchEvent(new CustomEvent('state', { detail: { state, url: this.url, attempt: this.attempt, ...extra } }));
  }

  _teardown() {
    clearTimeout(this.timer);
    this.timer = null;
    const ros = this.ros;
    this.ros = null;
    this.pubs.clear();
    for (const sub of this.subs) sub.topic = null;
    if (ros) { try { ros.close(); } catch (e) { /* already closed */ } }
  }

  _open(state) {
    this._setState(state);
    let ros;
    try {
      ros = new ROSLIB.Ros({ url: this.url });
    } catch (err) {
      this.lastError = String(err.message || err);
      this._scheduleRetry();
      return;
    }
    this.ros = ros;
    ros.on('connection', () => {
      if (this.ros !== ros) return;
      this.attempt = 0;
      this.lastError = '';
      for (const sub of this.subs) this._attach(sub);
      this._setState('connected');
      this.dispatchEvent(new CustomEvent('connected'));
    });
    ros.on('error', () => {
      if (this.ros === ros) this.lastError = 'cannot reach the server';
    });
    ros.on('close', () => {
      if (this.ros !== ros) return;
      this.ros = null;
      this.pubs.clear();
      for (const sub of this.subs) sub.topic = null;
      this.dispatchEvent(new CustomEvent('lost'));
      this._scheduleRetry();
    });
  }

  _scheduleRetry() {
    const base = Math.min(BACKOFF_MAX_MS, BACKOFF_MIN_MS * 2 ** this.attempt);
    const delay = Math.round(base * (0.75 + Math.random() * 0.5));
    this.attempt += 1;
    this.retryAt = performance.now() + delay;
    this._setState('reconnecting', { retryInMs: delay });
    this.timer = setTimeout(() => { this.timer = null; this._open('reconnecting'); }, delay);
  }

  _attach(sub) {
    const topic = new ROSLIB.Topic({
      ros: this.ros, name: sub.name, messageType: sub.type, ...sub.options,
    });
    sub.topic = topic;
    topic.subscribe((msg) => {
      if (sub.topic !== topic) return;
      this._stat(sub.name).hit(performance.now());
      sub.callback(msg);
    });
  }

  _stat(name) {
    let s = this.stats.get(name);
    if (!s) { s = new TopicStats(); this.stats.set(name, s); }
    return s;
  }

  /** Subscribe for as long as the page wants it (across reconnects). Returns an unsubscriber. */
  subscribe(name, type, callback, options = {}) {
    const sub = { name, type, callback, options, topic: null };
    this.subs.add(sub);
    if (this.connected) this._attach(sub);
    return () => {
      this.subs.delete(sub);
      if (sub.topic) { try { sub.topic.unsubscribe(); } catch (e) { /* closed */ } }
      sub.topic = null;
    };
  }

  /** Publish one message (advertising on first use). Returns false when not connected. */
  publish(name, type, msg) {
    if (!this.connected) return false;
    let topic = this.pubs.get(name);
    if (topic && topic.messageType !== type) { // the type changed (e.g. Twist -> TwistStamped)
      try { topic.unadvertise(); } catch (e) { /* closed */ }
      topic = null;
    }
    if (!topic) {
      topic = new ROSLIB.Topic({ ros: this.ros, name, messageType: type, queue_size: 1 });
      this.pubs.set(name, topic);
      topic.advertise();
      // a refused advertise (e.g. the wrong type) comes back as a status with its id
      this.ros.once(`status:${topic.advertiseId}`, (m) => {
        if (m.level !== 'error' && m.level !== 'warning') return;
        this.dispatchEvent(new CustomEvent('refused', { detail: { topic: name, text: String(m.msg) } }));
      });
    }
    topic.publish(msg);
    this._stat(name).hit(performance.now());
    return true;
  }

  /** Call a service; resolves with the response, rejects with a readable Error. */
  call(name, type, request = {}, timeoutMs = 4000) {
    return new Promise((resolve, reject) => {
      if (!this.connected) { reject(new Error('not connected')); return; }
      const service = new ROSLIB.Service({ ros: this.ros, name, serviceType: type });
      const timer = setTimeout(() => reject(new Error(`${name}: no answer in ${timeoutMs} ms`)), timeoutMs);
      service.callService(new ROSLIB.ServiceRequest(request), (res) => {
        clearTimeout(timer); resolve(res);
      }, (err) => { clearTimeout(timer); reject(new Error(`${name}: ${err}`)); });
    });
  }

  /** Read a ROS 2 parameter through rosapi ('/virtual_robot:robot.mass'); null if absent. */
  async getParam(name) {
    const res = await this.call('/rosapi/get_param', 'rosapi/GetParam', { name });
    if (!res || res.value === undefined || res.value === '') return null;
    try { return JSON.parse(res.value); } catch (e) { return null; }
  }

  /** Rows of {name, rate (Hz), ageMs} for every topic seen. */
  rates(now = performance.now()) {
    const rows = [];
    for (const [name, s] of this.stats) {
      rows.push({ name, rate: s.rate(now), ageMs: s.last ? now - s.last : Infinity, count: s.count });
    }
    rows.sort((a, b) => a.name.localeCompare(b.name));
    return rows;
  }
}
