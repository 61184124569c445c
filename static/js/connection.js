// The link to a rosbridge server (roslib 1.4.1, global ROSLIB): reconnect with backoff,
// re-subscribe after every reconnect, per-topic message rates and ages, and a reason for every
// state a student can see.
//
// roslib 1.x does not reconnect by itself (roslibjs #497), so each attempt makes a fresh
// ROSLIB.Ros and the subscriptions recorded here are replayed on it. A browser is told nothing
// about a refused WebSocket upgrade (the socket just closes), so after a failed attempt the page
// asks the server why (GET /api/access on the same host and port, simbridge only): a refused
// token, a full server, or no server at all.
//
// The token is kept apart from the URL: the URL shown (status line, URL field, Link tab) never
// carries it; only the socket's URL does.

const BACKOFF_MIN_MS = 500;
const BACKOFF_MAX_MS = 8000;
const RATE_WINDOW_MS = 2000;
const TOKEN_KEY = 'simbridge-token';

// generous: on a loaded machine or a slow phone the answer may take seconds, and giving up
// means guessing port 9090
const ENDPOINT_TIMEOUT_MS = 10000;

const bracketed = (host) => (host.includes(':') ? `[${host}]` : host);

/** Returns the rosbridge URL the page starts with: ?url=, else ws://<page host>:9090. */
export function defaultUrl(loc = window.location) {
  const given = new URLSearchParams(loc.search).get('url');
  if (given) return given;
  return `ws://${bracketed(loc.hostname || '127.0.0.1')}:9090`;
}

/**
 * The rosbridge URL an answer of GET api/rosbridge names, or null: simbridge answers the port
 * it listens on ({port, tls}: ws://<page host>:<port>), a proxy in front of it the path it
 * forwards to the WebSocket ({path: "/ws"}: on the page's own host and port).
 */
export function endpointUrl(answer, loc = window.location) {
  if (!answer || typeof answer !== 'object') return null;
  const secure = loc.protocol === 'https:';
  const { port, path } = answer;
  if (Number.isInteger(port) && port > 0 && port < 65536) {
    const scheme = answer.tls === true || secure ? 'wss' : 'ws';
    return `${scheme}://${bracketed(loc.hostname || '127.0.0.1')}:${port}`;
  }
  if (typeof path === 'string' && path.startsWith('/') && !path.startsWith('//')) {
    return `${secure ? 'wss' : 'ws'}://${loc.host}${path}`;
  }
  return null;
}

/**
 * The rosbridge URL the page should use: ?url= if given; else where the server that served the
 * page says its rosbridge is (GET api/rosbridge beside the page, see endpointUrl), so a server
 * on another port than 9090 or behind a proxy needs no ?url=; else ws://<page host>:9090 (a
 * page served by another web server: a real robot's, say).
 */
export async function rosbridgeUrl(loc = window.location, fetchFn = (...args) => window.fetch(...args)) {
  const fallback = defaultUrl(loc);
  if (new URLSearchParams(loc.search).get('url')) return fallback;
  const abort = new AbortController();
  const timer = setTimeout(() => abort.abort(), ENDPOINT_TIMEOUT_MS);
  try {
    const reply = await fetchFn(new URL('api/rosbridge', loc.href).href,
      { cache: 'no-store', signal: abort.signal });
    if (!reply.ok) return fallback;
    return endpointUrl(await reply.json(), loc) ?? fallback;
  } catch (err) {
    return fallback; // not simbridge, or it did not answer in time
  } finally {
    clearTimeout(timer);
  }
}

/**
 * Split a token out of a URL (`ws://h:9090/?token=T`): returns {url, token} with the URL
 * free of it. A URL that does not parse is returned as it is.
 */
export function splitToken(url) {
  try {
    const u = new URL(url);
    const token = u.searchParams.get('token');
    if (token === null) return { url, token: null };
    u.searchParams.delete('token');
    let clean = u.toString();
    if (!u.search && clean.endsWith('?')) clean = clean.slice(0, -1);
    return { url: clean, token };
  } catch (err) {
    return { url, token: null };
  }
}

/**
 * The page's token, taken once from ?token= (or a ?url= carrying one) and then removed from the
 * address bar; kept in sessionStorage (this tab only) so a reload keeps it.
 */
export function takeToken(loc = window.location, history = window.history, storage = window.sessionStorage) {
  const params = new URLSearchParams(loc.search);
  let token = params.get('token');
  let changed = false;
  if (token !== null) { params.delete('token'); changed = true; }
  const url = params.get('url');
  if (url) {
    const split = splitToken(url);
    if (split.token !== null) {
      token = token ?? split.token;
      params.set('url', split.url);
      changed = true;
    }
  }
  if (changed) {
    const query = params.toString();
    history.replaceState(null, '', `${loc.pathname}${query ? `?${query}` : ''}${loc.hash}`);
  }
  try {
    if (token !== null) storage.setItem(TOKEN_KEY, token);
    else token = storage.getItem(TOKEN_KEY);
  } catch (err) { /* storage off: the token lives for this page only */ }
  return token || '';
}

export function storeToken(token, storage = window.sessionStorage) {
  try {
    if (token) storage.setItem(TOKEN_KEY, token); else storage.removeItem(TOKEN_KEY);
  } catch (err) { /* storage off */ }
}

/** Why `url` cannot be a rosbridge URL, or null when it can. */
export function urlProblem(url) {
  let u;
  try { u = new URL(url); } catch (err) {
    return `"${url}" is not a URL: use ws://HOST:9090 (the server's address and port)`;
  }
  if (u.protocol === 'http:' || u.protocol === 'https:') {
    const ws = u.protocol === 'https:' ? 'wss' : 'ws';
    return `"${url}" is a web address: the robot's link starts with ${ws}:// (${ws}://${u.host || 'HOST:9090'})`;
  }
  if (u.protocol !== 'ws:' && u.protocol !== 'wss:') {
    return `"${url}" is not a WebSocket URL: use ws://HOST:9090 (or wss:// behind TLS)`;
  }
  if (!u.hostname) return `"${url}" names no host: use ws://HOST:9090`;
  return null;
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
 * Events (EventTarget): 'state' (detail: {state, url, attempt, retryInMs, reason}),
 * 'connected', 'lost', 'refused' (detail: {topic, text}: the server refused to let the page
 * publish it).
 * state is one of 'connecting', 'connected', 'reconnecting' (a reason says why: the link was
 * lost, no server answers, the server is full), 'refused' (the token was refused: no retry
 * until a new token), 'badurl' (no retry until a new URL), 'disconnected'.
 */
export class Connection extends EventTarget {
  constructor(url, token = '') {
    super();
    this.url = url;            // as shown: never with the token
    this.token = token;
    this.state = 'disconnected';
    this.reason = '';
    this.attempt = 0;
    this.retryAt = 0;
    this.ros = null;
    this.opened = false;       // the current attempt's socket opened
    this.subs = new Set();     // {name, type, callback, options, topic}
    this.pubs = new Map();     // name -> ROSLIB.Topic on the current ros
    this.stats = new Map();    // name -> TopicStats
    this.timer = null;
    this.generation = 0;
  }

  /** (Re)connect to `url` (default: the current one) with `token`, resetting the backoff. */
  connect(url = this.url, token = this.token) {
    const split = splitToken(url);
    this.url = split.url;
    this.token = split.token ?? token;
    this.attempt = 0;
    this._teardown();
    this._open('connecting');
  }

  /** Close and stay closed. */
  disconnect() {
    this._teardown();
    this._setState('disconnected', { reason: '' });
  }

  get connected() { return this.state === 'connected' && this.ros !== null; }

  /** The socket's URL: the shown URL with the token. */
  socketUrl() {
    if (!this.token) return this.url;
    const u = new URL(this.url);
    u.searchParams.set('token', this.token);
    return u.toString();
  }

  _setState(state, extra = {}) {
    this.state = state;
    if (extra.reason !== undefined) this.reason = extra.reason;
    this.dispatchEvent(new CustomEvent('state', {
      detail: { state, url: this.url, attempt: this.attempt, reason: this.reason, ...extra },
    }));
  }

  _teardown() {
    this.generation += 1;
    clearTimeout(this.timer);
    this.timer = null;
    const ros = this.ros;
    this.ros = null;
    this.pubs.clear();
    for (const sub of this.subs) sub.topic = null;
    if (ros) { try { ros.close(); } catch (e) { /* already closed */ } }
  }

  _open(state) {
    const problem = urlProblem(this.url);
    if (problem) { this._setState('badurl', { reason: problem }); return; }
    this._setState(state);
    let ros;
    try {
      ros = new ROSLIB.Ros({ url: this.socketUrl() });
    } catch (err) {
      this._setState('badurl', { reason: `cannot open ${this.url}: ${err.message || err}` });
      return;
    }
    this.ros = ros;
    this.opened = false;
    ros.on('connection', () => {
      if (this.ros !== ros) return;
      this.opened = true;
      this.attempt = 0;
      for (const sub of this.subs) this._attach(sub);
      this._setState('connected', { reason: '' });
      this.dispatchEvent(new CustomEvent('connected'));
    });
    ros.on('error', () => { /* the close that follows says what happened */ });
    ros.on('close', () => {
      if (this.ros !== ros) return;
      const wasOpen = this.opened;
      // not connected any more before anyone hears of it: a publish from a 'lost' listener
      // (the teleop's zero) must not reach the closed socket
      this.ros = null;
      this.pubs.clear();
      for (const sub of this.subs) sub.topic = null;
      this.state = 'reconnecting';
      if (wasOpen) {
        this.dispatchEvent(new CustomEvent('lost'));
        this._scheduleRetry('the link to the server was lost (server stopped or restarting, or the network dropped)');
      } else {
        this._diagnose();
      }
    });
  }

  /** After an attempt that never opened: ask the server why, then retry or stop. */
  async _diagnose() {
    const generation = this.generation;
    const u = new URL(this.url);
    const where = u.host;
    let reason = `no server answers at ${where} (is simbridge running? is the address right?)`;
    let retry = true;
    try {
      const check = new URL(this.url);
      check.protocol = u.protocol === 'wss:' ? 'https:' : 'http:';
      check.pathname = '/api/access';
      check.search = '';
      if (this.token) check.searchParams.set('token', this.token);
      const ctl = new AbortController();
      const timer = setTimeout(() => ctl.abort(), 3000);
      const res = await fetch(check, { cache: 'no-store', signal: ctl.signal });
      clearTimeout(timer);
      const info = res.ok ? await res.json() : null;
      if (!info || info.server !== 'simbridge') {
        reason = `the server at ${where} refused the connection`;
      } else if (info.token === 'refused') {
        reason = 'the server refused this token: check the token your instructor gave you';
        retry = false;
      } else if (info.full) {
        reason = `the server is full (${info.clients} of ${info.max_clients} connections): trying again`;
      } else {
        reason = `the server at ${where} refused the connection`;
      }
    } catch (err) {
      // no answer at all (the fetch failed): a dead server or a wrong address
    }
    if (generation !== this.generation) return; // connect() was called meanwhile
    if (retry) this._scheduleRetry(reason);
    else this._setState('refused', { reason });
  }

  _scheduleRetry(reason) {
    const base = Math.min(BACKOFF_MAX_MS, BACKOFF_MIN_MS * 2 ** this.attempt);
    const delay = Math.round(base * (0.75 + Math.random() * 0.5));
    this.attempt += 1;
    this.retryAt = performance.now() + delay;
    this._setState('reconnecting', { retryInMs: delay, reason });
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
      if (sub.topic && this.ros) { try { sub.topic.unsubscribe(); } catch (e) { /* closed */ } }
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
