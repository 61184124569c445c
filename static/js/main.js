// The simbridge page: wires the connection, view, teleop, plots and PID lab together.
import { Connection, defaultUrl } from './connection.js';
import { View, scanToWorld, markerSegments, yawOf } from './view.js';
import {
  TeleopDriver, installKeyboard, installJoystick, installGamepad, gamepadSettingsFromUrl,
  gamepadSettingsToUrl, parseSetting, formatSetting,
} from './teleop.js';
import { TimeSeriesPlot } from './plots.js';
import { PidLab, exampleCode } from './pid.js';
import { spawnNear } from './spawn.js';
import { CmdVelType, TWIST, choiceFromUrl, velocityMessage, twistOf } from './cmdvel.js';

const $ = (id) => document.getElementById(id);
const NODE = '/virtual_robot';

const state = {
  ns: '',                       // robot namespace ('' = the un-namespaced robot)
  limits: { v: 0.5, w: 2.5 },   // from the robot's parameters when it has them
  pose: null,
  mounts: new Map(),            // child frame -> {x, y, yaw} (from /tf_static)
  cmd: { v: 0, w: 0 },          // last /cmd_vel seen (any publisher)
  meas: { v: 0, w: 0 },
  nearest: null,
  estopped: false,
  robots: [''],
  walls: 0,
};
const topic = (name) => (state.ns ? `/${state.ns}/${name}` : `/${name}`);
const now = () => performance.now() / 1000;

const conn = new Connection(defaultUrl());
const view = new View($('view'));

// ---- status --------------------------------------------------------------------------------
const statusEl = $('status');
$('url').value = conn.url;
$('linkUrl').textContent = conn.url;
function showState(detail) {
  statusEl.className = `status ${detail.state}`;
  let text = detail.state;
  if (detail.state === 'reconnecting' && detail.retryInMs !== undefined) {
    text = `reconnecting (try ${detail.attempt}, in ${(detail.retryInMs / 1000).toFixed(1)} s)`;
  }
  $('statusText').textContent = text;
  $('linkUrl').textContent = detail.url;
}
conn.addEventListener('state', (e) => showState(e.detail));
$('urlForm').addEventListener('submit', (e) => {
  e.preventDefault();
  const url = $('url').value.trim();
  if (!url) return;
  const params = new URLSearchParams(location.search);
  params.set('url', url);
  history.replaceState(null, '', `${location.pathname}?${params}`);
  releaseInputs();
  cmdVel.forget(); // another server (a real robot?) may take another type: ask it again
  subscribeCmd();
  conn.connect(url);
});

function fmtAge(ms) {
  if (!Number.isFinite(ms)) return '–';
  return ms < 1000 ? `${Math.round(ms)} ms` : `${(ms / 1000).toFixed(1)} s`;
}
setInterval(() => {
  const rows = conn.rates();
  const odom = rows.find((r) => r.name === topic('odom'));
  $('statusInfo').textContent = conn.connected && odom
    ? `${conn.url} · odom ${odom.rate.toFixed(0)} Hz, ${fmtAge(odom.ageMs)} old`
      + (state.simTime !== undefined ? ` · sim ${state.simTime.toFixed(1)} s` : '')
    : conn.url;
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
  toastTimer = setTimeout(() => { el.hidden = true; }, 4000);
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
  cmdVel.forget();
  subscribeCmd();
  showCmdVelType();
});

// ---- e-stop and reset ----------------------------------------------------------------------
async function estop() {
  driver.enabled = false;
  releaseInputs();
  lab.stop(false);
  publishTwist(0, 0); // a zero first, then the latch (joy2twist #15)
  if (!conn.connected) { toast('Not connected: the robot cannot be reached.'); return; }
  try {
    await conn.call('/estop', 'std_srvs/srv/Trigger', {});
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
}
$('estop').addEventListener('click', () => estop());
$('release').addEventListener('click', async () => {
  try { await conn.call('/estop/reset', 'std_srvs/srv/Trigger', {}); } catch (err) { toast(err.message); }
});
$('reset').addEventListener('click', async () => {
  try {
    await conn.call('/reset', 'std_srvs/srv/Empty', {});
    view.clearTrail();
    toast('World reset.');
  } catch (err) { toast(`Reset failed: ${err.message}`); }
});

// ---- view ----------------------------------------------------------------------------------
$('zoomIn').addEventListener('click', () => view.zoom(1.25));
$('zoomOut').addEventListener('click', () => view.zoom(0.8));
$('follow').addEventListener('click', () => view.setFollow(!view.follow));
$('fit').addEventListener('click', () => view.fit());
$('view').addEventListener('followchange', () => $('follow').setAttribute('aria-pressed', String(view.follow)));

// ---- plots ---------------------------------------------------------------------------------
const plots = {
  v: new TimeSeriesPlot($('plotV'), [{ label: 'v cmd', color: '#94a3b8', dash: [5, 3] }, { label: 'v meas', color: '#2563eb' }], { unit: 'm/s' }),
  w: new TimeSeriesPlot($('plotW'), [{ label: 'ω cmd', color: '#94a3b8', dash: [5, 3] }, { label: 'ω meas', color: '#ea580c' }], { unit: 'rad/s' }),
  heading: new TimeSeriesPlot($('plotHeading'), [{ label: 'heading', color: '#15803d' }], { unit: 'deg' }),
  range: new TimeSeriesPlot($('plotRange'), [{ label: 'nearest range', color: '#dc2626' }], { unit: 'm', min: 0 }),
  step: new TimeSeriesPlot($('plotStep'), [{ label: 'setpoint', color: '#94a3b8', dash: [5, 3] }, { label: 'measured', color: '#2563eb', width: 2 }], { window: 10, anchored: true, maxPoints: 6000 }),
};

// ---- subscriptions -------------------------------------------------------------------------
let robotSubs = [];
function subscribeRobot() {
  for (const off of robotSubs) off();
  view.clear();
  for (const p of [plots.v, plots.w, plots.heading, plots.range]) p.clear();
  state.pose = null;
  robotSubs = [
    conn.subscribe(topic('odom'), 'nav_msgs/msg/Odometry', (m) => {
      const p = m.pose.pose;
      const theta = yawOf(p.orientation);
      state.pose = { x: p.position.x, y: p.position.y, theta };
      state.meas = { v: m.twist.twist.linear.x, w: m.twist.twist.angular.z };
      state.odomStamp = `${m.header.stamp.sec}.${String(m.header.stamp.nanosec).padStart(9, '0').slice(0, 3)}`;
      view.setPose(p.position.x, p.position.y, theta);
      $('odomLine').textContent = `x ${p.position.x.toFixed(2)}  y ${p.position.y.toFixed(2)}  θ ${(theta * 180 / Math.PI).toFixed(0)}°`;
      const t = now();
      plots.v.push(t, [state.cmd.v, state.meas.v]);
      plots.w.push(t, [state.cmd.w, state.meas.w]);
      plots.heading.push(t, [theta * 180 / Math.PI]);
    }),
    conn.subscribe(topic('scan'), 'sensor_msgs/msg/LaserScan', (m) => {
      const mount = state.mounts.get(m.header.frame_id) || { x: 0, y: 0, yaw: 0 };
      const { points, nearest } = scanToWorld(m, mount, state.pose);
      state.nearest = Number.isFinite(nearest) ? nearest : null;
      view.setScan(points);
      plots.range.push(now(), [state.nearest]);
    }),
  ];
  subscribeCmd();
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
}, { throttle_rate: 200 });
conn.subscribe('/estop/state', 'std_msgs/msg/Bool', (m) => showEstop(Boolean(m.data)));
subscribeRobot();

// the other robots, drawn in grey (10 Hz is plenty for that)
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
    }, { throttle_rate: 100, queue_length: 1 }));
  }
}

// robots: every /<ns>/odom (and /odom) of type nav_msgs/Odometry
async function discoverRobots() {
  if (!conn.connected) return;
  try {
    const res = await conn.call('/rosapi/topics', 'rosapi/Topics', {});
    const found = [];
    res.topics.forEach((name, i) => {
      const type = res.types ? res.types[i] : '';
      const match = /^(?:\/([^/]+))?\/odom$/.exec(name);
      if (match && (!type || type.replace('/msg/', '/') === 'nav_msgs/Odometry')) found.push(match[1] || '');
    });
    if (found.includes('') && found.length > 1) {
      // '/odom' may only be our own subscription (a world of named robots): keep it only if
      // something publishes it.
      try {
        const pubs = await conn.call('/rosapi/publishers', 'rosapi/Publishers', { topic: '/odom' });
        if (!pubs.publishers || !pubs.publishers.length) found.splice(found.indexOf(''), 1);
      } catch (err) { /* a rosapi without publishers: keep it */ }
    }
    found.sort();
    if (found.join('|') === state.robots.join('|')) return;
    state.robots = found;
    subscribeOthers();
    const sel = $('robot');
    sel.replaceChildren(...found.map((ns) => new Option(ns || '(default)', ns)));
    if (!found.includes(state.ns)) {
      state.ns = found.includes('') || !found.length ? '' : found[0];
      detectCmdVel();
      subscribeRobot();
      subscribeOthers();
    }
    sel.value = state.ns;
  } catch (err) { /* a server without rosapi: keep the default robot */ }
}
// spawn: a robot of one's own, selected at once
function selectRobot(ns) {
  releaseInputs();
  lab.stop();
  state.ns = ns;
  $('robot').value = ns;
  detectCmdVel();
  subscribeRobot();
  loadLimits();
}
$('spawnForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  if (!conn.connected) { toast('Not connected: cannot spawn a robot.'); return; }
  const input = $('spawnName');
  try {
    const name = await spawnNear(conn, input.value.trim(), state.pose, state.wallSegments || []);
    input.value = '';
    await discoverRobots();
    if (!state.robots.includes(name)) {
      state.robots = [...state.robots, name].sort();
      $('robot').append(new Option(name, name));
    }
    selectRobot(name);
    toast(`Spawned robot '${name}': you are driving it.`);
  } catch (err) { toast(`Spawn failed: ${err.message}`); }
});
$('robot').addEventListener('change', (e) => {
  releaseInputs();
  lab.stop();
  state.ns = e.target.value;
  detectCmdVel();
  subscribeRobot();
  subscribeOthers();
  loadLimits();
});

async function loadLimits() {
  if (!conn.connected) return;
  try {
    const [v, w, radius] = await Promise.all(['robot.max_linear_velocity', 'robot.max_angular_velocity', 'robot.radius']
      .map((p) => conn.getParam(`${NODE}:${p}`)));
    if (typeof v === 'number' && v > 0) state.limits.v = v;
    if (typeof w === 'number' && w > 0) state.limits.w = w;
    if (typeof radius === 'number' && radius > 0) view.radius = radius;
  } catch (err) { /* a real robot may have no such parameters: keep the defaults */ }
  for (const [id, max] of [['speedV', state.limits.v], ['speedW', state.limits.w]]) {
    const el = $(id);
    const old = Number(el.max);
    el.max = String(max);
    if (Number(el.value) > max || old !== max) el.value = String(Math.min(Number(el.value), max));
  }
  showSpeeds();
}
conn.addEventListener('connected', () => { detectCmdVel(); discoverRobots(); loadLimits(); });
setInterval(() => { discoverRobots(); loadLimits(); }, 3000);

// ---- PID lab -------------------------------------------------------------------------------
const lab = new PidLab(publishTwist, () => state.limits);
const pidInputs = () => ({
  mode: $('pidMode').value,
  gains: { kp: Number($('kp').value), ki: Number($('ki').value), kd: Number($('kd').value) },
  setpoint: { theta: (Number($('spTheta').value) * Math.PI) / 180, x: Number($('spX').value), y: Number($('spY').value) },
});
function showExample() {
  const { mode, gains, setpoint } = pidInputs();
  $('example').textContent = exampleCode(mode, gains, setpoint, cmdVel.type);
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
lab.onSample = ([t, y, ys]) => {
  const k = scale();
  plots.step.push(t, [ys * k, y * k]);
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
  lab.start(mode, setpoint, gains, () => state.pose);
  $('pidFigures').textContent = 'running…';
});
$('pidStop').addEventListener('click', () => lab.stop());
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
    for (const p of Object.values(plots)) p.dirty = true;
  });
}

// for tests and curious students: the page's parts
window.simbridge = { conn, view, driver, lab, plots, state, cmdVel };
conn.connect();
