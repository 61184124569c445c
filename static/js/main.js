// The simbridge page: wires the connection, view, teleop, plots and PID lab together.
import { Connection, defaultUrl, rosbridgeUrl, takeToken, storeToken } from './connection.js';
import { View, scanToWorld, markerSegments, yawOf } from './view.js';
import {
  TeleopDriver, installKeyboard, installJoystick, installGamepad, gamepadSettingsFromUrl,
  gamepadSettingsToUrl, parseSetting, formatSetting,
} from './teleop.js';
import { LivePlot, download } from './plots.js';
import { PidLab, exampleCode, wrapAngle } from './pid.js';
import { spawnNear } from './spawn.js';
import { Gap } from './gap.js';
import { CmdVelType, TWIST, choiceFromUrl, velocityMessage, twistOf } from './cmdvel.js';

const $ = (id) => document.getElementById(id);
const NODE = '/virtual_robot';
const STALE_MS = 1500;              // /odom older than this while connected: greyed
const OTHERS_THROTTLE_MS = 250;     // other robots' /odom for the view: 4 Hz is plenty

const state = {
  ns: '',                       // robot namespace ('' = the un-namespaced robot)
  limits: { v: 0.5, w: 2.5 },   // from the robot's parameters when it has them
  pose: null,
  mounts: new Map(),            // child frame -> {x, y, yaw} (from /tf_static)
  cmd: { v: 0, w: 0 },          // last /cmd_vel seen (any publisher)
  meas: { v: 0, w: 0 },
  nearest: null,
  estopped: false,
  robots: [''],                 // robots found on the server
  walls: 0,
  access: null,                 // /simbridge/access (null: unknown, e.g. a real robot's rosbridge)
  needsToken: false,
  lastOdomAt: 0,
  t0: null,                     // stamp (s) of the plots' t = 0
  heading: null,                // {raw, unwrapped} (deg) for the heading plot
};
const topic = (name) => (state.ns ? `/${state.ns}/${name}` : `/${name}`);
const stampSeconds = (h) => h.stamp.sec + h.stamp.nanosec * 1e-9;
const stampText = (h) => `${h.stamp.sec}.${String(h.stamp.nanosec).padStart(9, '0')}`;

const token = takeToken();      // removes ?token= from the address bar
const conn = new Connection(defaultUrl(), token);
const view = new View($('view'));

// ---- status --------------------------------------------------------------------------------
const statusEl = $('status');
$('url').value = conn.url;
$('token').value = conn.token;
$('linkUrl').textContent = conn.url;
const STATE_WORDS = {
  connecting: 'connecting…', connected: 'connected', reconnecting: 'reconnecting',
  refused: 'token refused', badurl: 'wrong URL', disconnected: 'disconnected',
};
function showState(detail = { state: conn.state, url: conn.url, reason: conn.reason }) {
  let kind = detail.state;
  let text = STATE_WORDS[kind] || kind;
  let reason = detail.reason || '';
  if (state.needsToken && (kind === 'connected' || kind === 'disconnected')) {
    kind = 'refused';
    text = 'token needed';
    reason = 'this server needs a token: enter the one your instructor gave you under Server';
  } else if (kind === 'reconnecting' && detail.retryInMs !== undefined) {
    text = `reconnecting in ${(detail.retryInMs / 1000).toFixed(1)} s (try ${detail.attempt})`;
  }
  statusEl.className = `status ${kind}`;
  $('statusText').textContent = text;
  $('statusInfo').textContent = reason;
  $('statusInfo').dataset.reason = reason ? '1' : '';
  $('linkUrl').textContent = detail.url;
  // a link that needs the user (a token, a URL) opens the server form
  if (kind === 'refused' || kind === 'badurl') $('server').open = true;
}
conn.addEventListener('state', (e) => { showState(e.detail); markStale(); showExample(); });
$('urlForm').addEventListener('submit', (e) => {
  e.preventDefault();
  const url = $('url').value.trim();
  if (!url) return;
  const params = new URLSearchParams(location.search);
  params.set('url', url);
  history.replaceState(null, '', `${location.pathname}?${params}`);
  storeToken($('token').value.trim());
  releaseInputs();
  cmdVel.forget(); // another server (a real robot?) may take another type: ask it again
  subscribeCmd();
  state.needsToken = false;
  conn.connect(url, $('token').value.trim());
  $('url').value = conn.url; // a token pasted into the URL moves to the token field
  $('token').value = conn.token;
  $('server').open = false;
});

function fmtAge(ms) {
  if (!Number.isFinite(ms)) return '–';
  return ms < 1000 ? `${Math.round(ms)} ms` : `${(ms / 1000).toFixed(1)} s`;
}
function markStale() {
  const stale = !conn.connected || state.needsToken || !state.pose
    || performance.now() - state.lastOdomAt > STALE_MS;
  document.body.classList.toggle('stale', stale);
  view.setStale(stale && state.pose !== null);
}
setInterval(() => {
  markStale();
  const rows = conn.rates();
  if (!$('statusInfo').dataset.reason) {
    const odom = rows.find((r) => r.name === topic('odom'));
    $('statusInfo').textContent = conn.connected && odom
      ? `${conn.url} · odom ${odom.rate.toFixed(0)} Hz, ${fmtAge(odom.ageMs)} old`
        + (state.simTime !== undefined ? ` · sim ${state.simTime.toFixed(1)} s` : '')
      : conn.url;
  }
  if ($('tab-link').hidden) return; // the rates table only while it is shown
  $('rates').replaceChildren(...rows.map((r) => {
    const tr = document.createElement('tr');
    for (const text of [r.name, r.rate.toFixed(1), fmtAge(r.ageMs)]) {
      const td = document.createElement('td'); td.textContent = text; tr.append(td);
    }
    return tr;
  }));
  const sim = state.simTime !== undefined ? `sim time ${state.simTime.toFixed(2)} s · ` : '';
  $('linkTimes').textContent = `${sim}wall ${new Date().toISOString().slice(11, 19)} UTC · last odom stamp ${state.odomStamp ?? '–'}`;
}, 500);

let toastTimer = null;
function toast(text) {
  const el = $('toast');
  el.textContent = text; el.hidden = false;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => { el.hidden = true; }, 5000);
}

// ---- driving -------------------------------------------------------------------------------
// Every command (teleop, its zeros, the PID lab, the e-stop's zero) goes out in the type the
// robot takes: Twist or TwistStamped, asked of the server or chosen (cmdvel.js).
const cmdVel = new CmdVelType(choiceFromUrl());
function publishTwist(v, w) {
  if (!cmdVel.ready) return false; // still asking the server which type to send
  return conn.publish(topic('cmd_vel'), cmdVel.type, velocityMessage(cmdVel.type, v, w));
}
function showCmdVelType() {
  const sel = $('cmdVelType');
  const auto = cmdVel.pending === 0 ? (cmdVel.detected || TWIST).split('/').pop() : '…';
  sel.options[0].textContent = `auto (${auto})`;
  sel.value = cmdVel.choice;
}
$('cmdVelType').addEventListener('change', (e) => {
  releaseInputs();
  cmdVel.setChoice(e.target.value);
  const params = new URLSearchParams(location.search);
  if (cmdVel.choice === 'auto') params.delete('cmd_vel_type'); else params.set('cmd_vel_type', cmdVel.choice);
  const query = params.toString();
  history.replaceState(null, '', `${location.pathname}${query ? `?${query}` : ''}`);
  showCmdVelType();
});
cmdVel.addEventListener('change', () => { showCmdVelType(); subscribeCmd(); showExample(); });
cmdVel.addEventListener('ready', () => { showCmdVelType(); subscribeCmd(); });
function detectCmdVel() {
  if (conn.connected) cmdVel.detect(conn, topic('cmd_vel'));
  showCmdVelType();
}
const driver = new TeleopDriver(publishTwist);
const speeds = () => ({ v: Number($('speedV').value), w: Number($('speedW').value) });
function showSpeeds() {
  $('speedVOut').textContent = Number($('speedV').value).toFixed(2);
  $('speedWOut').textContent = Number($('speedW').value).toFixed(2);
}
$('speedV').addEventListener('input', showSpeeds);
$('speedW').addEventListener('input', showSpeeds);
showSpeeds();
const showCmd = (v, w) => { $('cmdV').textContent = v.toFixed(2); $('cmdW').textContent = w.toFixed(2); };
driver.addEventListener('command', (e) => showCmd(e.detail.v, e.detail.w));

const keyboard = installKeyboard(driver, speeds, () => estop());
const joystick = installJoystick($('joystick'), $('knob'), driver, speeds, showCmd);
const gamepadSettings = gamepadSettingsFromUrl();
driver.setRate(gamepadSettings.rate);
const gamepad = installGamepad(driver, speeds, (text) => { $('gamepad').textContent = text; }, gamepadSettings);
// the gamepad panel: axes, inversion, deadman buttons and the teleop rate, kept in the URL
const GAMEPAD_FIELDS = {
  gpLinearAxis: 'linearAxis', gpInvertLinear: 'invertLinear', gpAngularAxis: 'angularAxis',
  gpInvertAngular: 'invertAngular', gpDeadman: 'deadman', teleopRate: 'rate',
};
function showGamepadSettings() {
  for (const [id, key] of Object.entries(GAMEPAD_FIELDS)) {
    const el = $(id);
    if (el.type === 'checkbox') el.checked = gamepadSettings[key];
    else el.value = formatSetting(key, gamepadSettings[key]);
  }
}
$('gpSettings').addEventListener('change', (e) => {
  const key = GAMEPAD_FIELDS[e.target.id];
  if (!key) return;
  const value = parseSetting(key, e.target.type === 'checkbox' ? String(e.target.checked) : e.target.value);
  if (value === null) {
    toast(`${e.target.dataset.label}: "${e.target.value}" is not valid (${e.target.dataset.hint}).`);
  } else {
    gamepadSettings[key] = value;
    driver.setRate(gamepadSettings.rate);
    const params = gamepadSettingsToUrl(gamepadSettings, new URLSearchParams(location.search));
    const query = params.toString();
    history.replaceState(null, '', `${location.pathname}${query ? `?${query}` : ''}`);
  }
  showGamepadSettings();
});
showGamepadSettings();

function releaseInputs() {
  keyboard.release();
  joystick.release();
  gamepad.release();
  driver.stopAll();
}
window.addEventListener('blur', releaseInputs);
window.addEventListener('pagehide', releaseInputs);
document.addEventListener('visibilitychange', () => { if (document.hidden) releaseInputs(); });
conn.addEventListener('refused', (e) => toast(`${e.detail.topic} refused: ${e.detail.text}`));
conn.addEventListener('lost', () => {
  releaseInputs();
  lab.stop(false);
  showCmd(0, 0);
  state.meas = { v: 0, w: 0 };
  cmdVel.forget();
  subscribeCmd();
  showCmdVelType();
  view.breakTrail();
  for (const p of [plots.v, plots.w, plots.heading, plots.range]) p.gap(plotTime());
  markStale();
});

// ---- roles: what this connection may do ----------------------------------------------------
async function loadAccess() {
  if (!conn.connected) return;
  let access = null;
  try {
    const res = await conn.call('/simbridge/access', 'std_srvs/srv/Trigger', {});
    access = JSON.parse(res.message);
    state.needsToken = false;
  } catch (err) {
    // a server that wants a token refuses every call; a real robot's rosbridge has no such
    // service (then the page shows everything, as it cannot know)
    state.needsToken = /not authenticated/.test(err.message);
    // the server closes a connection that owes a token after a while: stay closed and say
    // why until the student enters one (no reconnect loop)
    if (state.needsToken) conn.disconnect();
  }
  state.access = access;
  showRole();
  showState();
  markStale();
  return access;
}
function mayDrive(ns) {
  const a = state.access;
  return !a || a.any_robot || a.robots.includes(ns);
}
function showRole() {
  const a = state.access;
  const admin = !a || a.admin;
  for (const el of document.querySelectorAll('.admin-only')) el.hidden = !admin || state.needsToken;
  const role = $('role');
  role.hidden = !a;
  if (a) {
    role.textContent = a.admin ? 'instructor' : (a.any_robot ? 'any robot' : `your robot: ${a.robots.join(', ') || 'none'}`);
    role.title = a.client;
  }
  showRobotInfo();
}
function showRobotInfo() {
  const a = state.access;
  const info = a && a.robot_info ? a.robot_info[state.ns] : null;
  if (!info) { $('robotInfo').textContent = a ? `model ${a.motion_model}` : 'model – · mass –'; return; }
  const own = info.own_params ? ' (this robot’s own)' : '';
  const model = info.realism ? 'realism profile (/odom drifts: see the ghost)' : a.motion_model;
  $('robotInfo').textContent = `model ${model} · mass ${info.mass} kg${own} · `
    + `limits ${info.max_linear_velocity} m/s, ${info.max_angular_velocity} rad/s`
    + (model === 'kinematic' ? ' · mass matters in the dynamic model only' : '');
  $('putBack').hidden = !mayDrive(state.ns) || !info.start;
  if (info.radius > 0) view.radius = info.radius;
}

// ---- e-stop and reset ----------------------------------------------------------------------
async function estop() {
  driver.enabled = false;
  releaseInputs();
  lab.stop(false);
  publishTwist(0, 0); // a zero first, then the latch (joy2twist #15)
  if (!conn.connected) { toast('Not connected: the robot cannot be reached.'); return; }
  try {
    const res = await conn.call('/estop', 'std_srvs/srv/Trigger', {});
    if (res && res.message) toast(res.message.split(';')[0] + '.');
  } catch (err) {
    toast(`E-stop service failed (${err.message}); sent a zero velocity instead.`);
  }
}
function showEstop(latched) {
  state.estopped = latched;
  driver.enabled = !latched;
  if (latched) releaseInputs();
  document.body.classList.toggle('estopped', latched);
  $('estopBanner').hidden = !latched;
  if (latched) describeEstop();
}
async function describeEstop() {
  const a = await loadAccess();
  const est = a && a.estop;
  if (!est || !state.estopped) {
    $('estopText').textContent = 'EMERGENCY STOP latched: the robot ignores /cmd_vel.';
    $('release').hidden = false;
    return;
  }
  const who = est.latches.map((l) => `${l.by}${l.global ? ' (every robot)' : ''}`).join('; ');
  $('estopText').textContent = `EMERGENCY STOP: ${state.ns || 'the robot'} is held by ${who || 'an e-stop'}; it ignores /cmd_vel.`;
  const mine = est.latches.length > 0 && est.latches.every((l) => est.releasable.includes(l.id));
  $('release').hidden = !mine;
  if (!mine) $('estopText').textContent += ' Only the instructor (or whoever latched it) can release it.';
}
$('estop').addEventListener('click', () => estop());
$('release').addEventListener('click', async () => {
  try {
    const service = state.access && !state.access.any_robot && state.ns ? `/${state.ns}/estop/reset` : '/estop/reset';
    const res = await conn.call(service, 'std_srvs/srv/Trigger', {});
    if (res && res.success === false) toast(res.message);
  } catch (err) { toast(err.message); }
});
$('reset').addEventListener('click', async () => {
  try {
    await conn.call('/reset', 'std_srvs/srv/Empty', {});
    view.breakTrail();
    toast('World reset.');
  } catch (err) { toast(`Reset failed: ${err.message}`); }
});
$('putBack').addEventListener('click', async () => {
  const info = state.access && state.access.robot_info && state.access.robot_info[state.ns];
  if (!info) return;
  const [x, y, theta] = info.start;
  try {
    await conn.call(topic('teleport_absolute'), 'turtlesim/srv/TeleportAbsolute', { x, y, theta });
    view.breakTrail();
    toast('Your robot is back at its start pose.');
  } catch (err) { toast(`Could not put the robot back: ${err.message}`); }
});

// ---- view ----------------------------------------------------------------------------------
$('zoomIn').addEventListener('click', () => view.zoom(1.25));
$('zoomOut').addEventListener('click', () => view.zoom(0.8));
$('follow').addEventListener('click', () => view.setFollow(!view.follow));
$('fit').addEventListener('click', () => view.fit());
$('rays').addEventListener('click', () => {
  const on = !view.showRays;
  view.setLayers({ rays: on, range: on });
  $('rays').setAttribute('aria-pressed', String(on));
});
$('view').addEventListener('followchange', () => $('follow').setAttribute('aria-pressed', String(view.follow)));

// ---- plots ---------------------------------------------------------------------------------
const ODOM_COLUMNS = ['odom stamp'];
const plots = {
  v: new LivePlot($('plotV'), [{ label: 'v cmd', color: '#94a3b8', dash: [5, 3] }, { label: 'v meas', color: '#2563eb' }],
    { title: 'linear velocity', unit: 'm/s', file: 'linear-velocity', columns: ODOM_COLUMNS }),
  w: new LivePlot($('plotW'), [{ label: 'ω cmd', color: '#94a3b8', dash: [5, 3] }, { label: 'ω meas', color: '#ea580c' }],
    { title: 'angular velocity', unit: 'rad/s', file: 'angular-velocity', columns: ODOM_COLUMNS }),
  heading: new LivePlot($('plotHeading'), [{ label: 'heading', color: '#15803d' }],
    { title: 'heading (unwrapped)', unit: 'deg', file: 'heading', columns: ODOM_COLUMNS }),
  range: new LivePlot($('plotRange'), [{ label: 'nearest range', color: '#c026d3' }],
    { title: 'nearest LiDAR range', unit: 'm', min: 0, file: 'nearest-range', columns: ['scan stamp'] }),
  step: new LivePlot($('plotStep'), [{ label: 'setpoint', color: '#94a3b8', dash: [5, 3] }, { label: 'measured', color: '#2563eb', width: 2 }],
    { title: 'step response', window: 10, anchored: true, maxPoints: 6000, file: 'step-response', columns: ['command'] }),
};
const gap = new Gap(conn, view, $('plotGap'), (stamp) => plotTime(stamp));
const liveTime = () => performance.now() / 1000;
/** The plots' time (s) for a stamp: from the first stamp seen; a stamp going back restarts. */
function plotTime(stamp) {
  if (stamp === undefined) return state.t0 === null ? 0 : (state.lastStamp ?? state.t0) - state.t0;
  if (state.t0 === null || stamp < (state.lastStamp ?? stamp) - 1) {
    if (state.t0 !== null) for (const p of [plots.v, plots.w, plots.heading, plots.range, gap.plot]) p.clear();
    state.t0 = stamp;
    state.heading = null;
  }
  state.lastStamp = stamp;
  return stamp - state.t0;
}
function showPlotsTab(on) {
  for (const p of [plots.v, plots.w, plots.heading, plots.range, gap.plot]) p.setVisible(on);
}

// ---- subscriptions -------------------------------------------------------------------------
let robotSubs = [];
function subscribeRobot() {
  for (const off of robotSubs) off();
  view.clear();
  const t = plotTime();
  for (const p of [plots.v, plots.w, plots.heading, plots.range]) p.gap(t);
  state.pose = null;
  state.heading = null;
  robotSubs = [
    conn.subscribe(topic('odom'), 'nav_msgs/msg/Odometry', (m) => {
      const p = m.pose.pose;
      const theta = yawOf(p.orientation);
      state.pose = { x: p.position.x, y: p.position.y, theta };
      state.meas = { v: m.twist.twist.linear.x, w: m.twist.twist.angular.z };
      state.odomStamp = stampText(m.header).slice(0, -6);
      state.lastOdomAt = performance.now();
      view.setPose(p.position.x, p.position.y, theta);
      $('odomLine').textContent = `x ${p.position.x.toFixed(2)}  y ${p.position.y.toFixed(2)}  θ ${(theta * 180 / Math.PI).toFixed(0)}°`;
      const t = plotTime(stampSeconds(m.header)); // first: a restarted clock resets the heading
      const deg = (theta * 180) / Math.PI;
      state.heading = state.heading === null
        ? { raw: deg, unwrapped: deg }
        : { raw: deg, unwrapped: state.heading.unwrapped + (wrapAngle((theta - (state.heading.raw * Math.PI) / 180)) * 180) / Math.PI };
      const stamp = [stampText(m.header)];
      plots.v.push(t, [state.cmd.v, state.meas.v], stamp);
      plots.w.push(t, [state.cmd.w, state.meas.w], stamp);
      plots.heading.push(t, [state.heading.unwrapped], stamp);
      gap.onOdom(m);
      if (document.body.classList.contains('stale')) markStale();
    }),
    conn.subscribe(topic('scan'), 'sensor_msgs/msg/LaserScan', (m) => {
      const mount = state.mounts.get(m.header.frame_id) || { x: 0, y: 0, yaw: 0 };
      const { points, nearest, laser } = scanToWorld(m, mount, state.pose);
      state.nearest = Number.isFinite(nearest) ? nearest : null;
      view.setScan(points, laser, m.range_max);
      if (state.t0 !== null) plots.range.push(plotTime(stampSeconds(m.header)), [state.nearest], [stampText(m.header)]);
    }, { compression: 'cbor' }), // ranges as float32: a fifth of the JSON bytes
    conn.subscribe(topic('contact'), 'simbridge_msgs/msg/Contact', (m) => {
      view.setContact({ x: m.point.x, y: m.point.y, other: m.other });
    }),
    conn.subscribe(state.ns ? `/${state.ns}/estop/state` : '/estop/state', 'std_msgs/msg/Bool', (m) => showEstop(Boolean(m.data))),
    gap.subscribe(topic('ground_truth')),
  ];
  subscribeCmd();
  subscribeOthers();
}
// /cmd_vel (any publisher) for the plots, in the type it has: subscribing with the other type
// would be refused, so only once the type is known
let cmdSub = null;
function subscribeCmd() {
  const key = cmdVel.ready ? `${topic('cmd_vel')} ${cmdVel.type}` : null;
  if (cmdSub && cmdSub.key === key) return;
  if (cmdSub) cmdSub.off();
  cmdSub = key && {
    key,
    off: conn.subscribe(topic('cmd_vel'), cmdVel.type, (m) => {
      const t = twistOf(m);
      state.cmd = { v: t.linear.x, w: t.angular.z };
    }),
  };
}
conn.subscribe('/tf_static', 'tf2_msgs/msg/TFMessage', (m) => {
  for (const tf of m.transforms) {
    const t = tf.transform;
    state.mounts.set(tf.child_frame_id, { x: t.translation.x, y: t.translation.y, yaw: yawOf(t.rotation) });
  }
});
conn.subscribe('/walls', 'visualization_msgs/msg/Marker', (m) => {
  const first = state.walls === 0;
  const segs = markerSegments(m);
  state.walls = segs.length;
  state.wallSegments = segs;
  view.setWalls(segs);
  if (first) { view.fit(); view.setFollow(false); }
});
conn.subscribe('/clock', 'rosgraph_msgs/msg/Clock', (m) => {
  state.simTime = m.clock.sec + m.clock.nanosec * 1e-9;
}, { throttle_rate: 1000 });

// the other robots, drawn in grey (throttled: the view needs no more)
const otherSubs = new Map();
function subscribeOthers() {
  for (const [ns, off] of otherSubs) {
    if (ns === state.ns || !state.robots.includes(ns)) { off(); otherSubs.delete(ns); view.setOther(ns, null); }
  }
  for (const ns of state.robots) {
    if (ns === state.ns || otherSubs.has(ns)) continue;
    const name = ns ? `/${ns}/odom` : '/odom';
    otherSubs.set(ns, conn.subscribe(name, 'nav_msgs/msg/Odometry', (m) => {
      const p = m.pose.pose;
      if (ns !== state.ns) view.setOther(ns, { x: p.position.x, y: p.position.y, theta: yawOf(p.orientation) });
    }, { throttle_rate: OTHERS_THROTTLE_MS, queue_length: 1 }));
  }
}

/** The one place the page changes robot: inputs released, subscriptions, limits, picker. */
function switchRobot(ns) {
  releaseInputs();
  lab.stop();
  state.ns = ns;
  const sel = $('robot');
  if (![...sel.options].some((o) => o.value === ns)) sel.append(new Option(ns || '(default)', ns));
  sel.value = ns;
  const params = new URLSearchParams(location.search);
  if (ns && state.access && state.access.robots.length > 1) params.set('robot', ns);
  const query = params.toString();
  history.replaceState(null, '', `${location.pathname}${query ? `?${query}` : ''}`);
  detectCmdVel();
  subscribeRobot();
  loadLimits();
  showRobotInfo();
  showExample();
}

/** The robot to open on: ?robot= if this connection may drive it, else its own. */
function preferredRobot(found) {
  const wanted = new URLSearchParams(location.search).get('robot');
  if (wanted !== null && found.includes(wanted) && mayDrive(wanted)) return wanted;
  if (found.includes(state.ns) && mayDrive(state.ns) && state.nsChosen) return state.ns;
  const a = state.access;
  if (a && a.robots.length && !a.any_robot) return a.robots[0];
  if (found.includes('')) return '';
  return found[0] ?? '';
}

// robots: every /<ns>/odom (and /odom) of type nav_msgs/Odometry
async function discoverRobots() {
  if (!conn.connected || state.needsToken) return;
  try {
    const found = [];
    const info = state.access && state.access.robot_info;
    // simbridge lists its robots in /simbridge/access: no need for the (long) topic list
    const res = info ? { topics: Object.keys(info).map((ns) => (ns ? `/${ns}/odom` : '/odom')) }
      : await conn.call('/rosapi/topics', 'rosapi/Topics', {});
    res.topics.forEach((name, i) => {
      const type = res.types ? res.types[i] : '';
      const match = /^(?:\/([^/]+))?\/odom$/.exec(name);
      if (match && (!type || type.replace('/msg/', '/') === 'nav_msgs/Odometry')) found.push(match[1] || '');
    });
    if (!info && found.includes('') && found.length > 1) {
      // '/odom' may only be our own subscription (a world of named robots): keep it only if
      // something publishes it.
      try {
        const pubs = await conn.call('/rosapi/publishers', 'rosapi/Publishers', { topic: '/odom' });
        if (!pubs.publishers || !pubs.publishers.length) found.splice(found.indexOf(''), 1);
      } catch (err) { /* a rosapi without publishers: keep it */ }
    }
    found.sort();
    const changed = found.join('|') !== state.robots.join('|');
    state.robots = found;
    // the picker lists the robots this connection may drive
    const mine = found.filter(mayDrive);
    const sel = $('robot');
    if (changed || sel.options.length !== mine.length) {
      sel.replaceChildren(...mine.map((ns) => new Option(ns || '(default)', ns)));
      sel.value = state.ns;
    }
    $('robot').closest('label').hidden = mine.length <= 1;
    const target = preferredRobot(found);
    if (!state.nsChosen || !found.includes(state.ns)) {
      state.nsChosen = true;
      if (target !== state.ns || !robotSubs.length) switchRobot(target);
    }
    if (changed) subscribeOthers();
  } catch (err) {
    // a server without rosapi: the default robot
    if (!robotSubs.length) switchRobot(state.ns);
  }
}
$('spawnForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  if (!conn.connected) { toast('Not connected: cannot spawn a robot.'); return; }
  const input = $('spawnName');
  try {
    const name = await spawnNear(conn, input.value.trim(), state.pose, state.wallSegments || []);
    input.value = '';
    await loadAccess();
    await discoverRobots();
    if (!state.robots.includes(name)) state.robots = [...state.robots, name].sort();
    switchRobot(name);
    toast(`Spawned robot '${name}': you are driving it.`);
  } catch (err) { toast(`Spawn failed: ${err.message}`); }
});
$('robot').addEventListener('change', (e) => switchRobot(e.target.value));

async function loadLimits() {
  if (!conn.connected || state.needsToken) return;
  const info = state.access && state.access.robot_info && state.access.robot_info[state.ns];
  if (info) {
    state.limits = { v: info.max_linear_velocity, w: info.max_angular_velocity };
  } else {
    try {
      const [v, w, radius] = await Promise.all(['robot.max_linear_velocity', 'robot.max_angular_velocity', 'robot.radius']
        .map((p) => conn.getParam(`${NODE}:${p}`)));
      if (typeof v === 'number' && v > 0) state.limits.v = v;
      if (typeof w === 'number' && w > 0) state.limits.w = w;
      if (typeof radius === 'number' && radius > 0) view.radius = radius;
    } catch (err) { /* a real robot may have no such parameters: keep the defaults */ }
  }
  for (const [id, max] of [['speedV', state.limits.v], ['speedW', state.limits.w]]) {
    const el = $(id);
    const old = Number(el.max);
    el.max = String(max);
    if (Number(el.value) > max || old !== max) el.value = String(Math.min(Number(el.value), max));
  }
  showSpeeds();
}
conn.addEventListener('connected', async () => {
  state.nsChosen = false;
  await loadAccess();
  detectCmdVel();
  await discoverRobots();
  loadLimits();
});
setInterval(async () => {
  if (!conn.connected) return;
  await loadAccess();
  discoverRobots();
  loadLimits();
}, 5000);

// ---- PID lab -------------------------------------------------------------------------------
const lab = new PidLab(publishTwist, () => state.limits);
const pidInputs = () => ({
  mode: $('pidMode').value,
  gains: { kp: Number($('kp').value), ki: Number($('ki').value), kd: Number($('kd').value) },
  setpoint: { theta: (Number($('spTheta').value) * Math.PI) / 180, x: Number($('spX').value), y: Number($('spY').value) },
});
function showExample() {
  const { mode, gains, setpoint } = pidInputs();
  const link = { url: conn.url, ns: state.ns, token: Boolean(conn.token) };
  $('example').textContent = exampleCode(mode, gains, setpoint, cmdVel.type, link);
}
$('pidMode').addEventListener('change', () => {
  const heading = $('pidMode').value === 'heading';
  for (const el of document.querySelectorAll('.sp-heading')) el.hidden = !heading;
  for (const el of document.querySelectorAll('.sp-position')) el.hidden = heading;
  showExample();
});
$('pidForm').addEventListener('input', showExample);
showExample();
const scale = () => (lab.mode === 'heading' ? 180 / Math.PI : 1);
lab.onSample = ([t, y, ys, u]) => {
  const k = scale();
  plots.step.push(t, [ys * k, y * k], [u]);
  const f = lab.figures();
  plots.step.bands = [{ lo: (lab.ys - f.band) * k, hi: (lab.ys + f.band) * k }];
  const unit = lab.mode === 'heading' ? '°' : ' m';
  const err = f.error === null ? '–' : `${(f.error * k).toFixed(lab.mode === 'heading' ? 1 : 3)}${unit}`;
  $('pidFigures').textContent = `overshoot ${f.overshootPct.toFixed(1)} % · settling ${f.settlingTime === null ? '(not yet)' : `${f.settlingTime.toFixed(1)} s`} (band ±${(f.band * k).toFixed(lab.mode === 'heading' ? 1 : 3)}${unit}) · error ${err}`;
  if (f.settlingTime !== null && !plots.step.marks.length && t - f.settlingTime > 1) {
    plots.step.marks = [{ t: f.settlingTime, label: `settled ${f.settlingTime.toFixed(1)} s` }];
  }
};
$('pidForm').addEventListener('submit', (e) => {
  e.preventDefault();
  if (state.estopped) { toast('Release the e-stop first.'); return; }
  if (!state.pose) { toast('No odometry yet.'); return; }
  releaseInputs();
  const { mode, gains, setpoint } = pidInputs();
  plots.step.clear();
  plots.step.unit = mode === 'heading' ? 'deg' : 'm along the line';
  plots.step.u.axes[1].label = plots.step.unit;
  lab.start(mode, setpoint, gains, () => state.pose);
  $('pidFigures').textContent = 'running…';
});
$('pidStop').addEventListener('click', () => lab.stop());
// As teleop (releaseInputs): a page that loses focus, is hidden or goes away must not leave the
// robot on the lab's last command (its timer is throttled or gone): stop, with one zero.
function stopLabUnseen(why) {
  if (!lab.running) return;
  lab.stop();
  $('pidFigures').textContent = `stopped: ${why} (Start runs the step again)`;
}
window.addEventListener('blur', () => stopLabUnseen('the window lost focus'));
window.addEventListener('pagehide', () => stopLabUnseen('the page was left'));
document.addEventListener('visibilitychange', () => { if (document.hidden) stopLabUnseen('the tab was hidden'); });
$('copyExample').addEventListener('click', async () => {
  const text = $('example').textContent;
  try { await navigator.clipboard.writeText(text); toast('Example copied.'); } catch (err) {
    const range = document.createRange();
    range.selectNodeContents($('example'));
    getSelection().removeAllRanges(); getSelection().addRange(range);
    toast('Selected: press Ctrl+C to copy.');
  }
});

// ---- tabs ----------------------------------------------------------------------------------
for (const tab of document.querySelectorAll('.tabs button')) {
  tab.addEventListener('click', () => {
    for (const other of document.querySelectorAll('.tabs button')) {
      const on = other === tab;
      other.setAttribute('aria-selected', String(on));
      $(`tab-${other.dataset.tab}`).hidden = !on;
    }
    showPlotsTab(tab.dataset.tab === 'plots');
    plots.step.setVisible(tab.dataset.tab === 'pid');
  });
}
showPlotsTab(false);
plots.step.setVisible(false);

// for tests and curious students: the page's parts
window.simbridge = { conn, view, driver, lab, plots, state, cmdVel, download, liveTime, gap };
// where the page's own server says its rosbridge is (unless ?url= said): then connect, unless
// the Server form connected somewhere meanwhile
rosbridgeUrl().then((url) => {
  if (conn.state !== 'disconnected') return;
  conn.connect(url); // its 'state' event shows the URL on the Link tab
  $('url').value = conn.url;
});
