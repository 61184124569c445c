// Teleop: keyboard, on-screen joystick and gamepad feed one driver that publishes /cmd_vel at a
// fixed rate while some input is active, then sends exactly one zero and stays silent (so a
// student's own node can drive /cmd_vel: dimos #4119). Every way of losing the input (key up,
// blur, hidden tab, page hide, disconnect) ends in that one zero.

export const RATE_HZ = 10;
export const MAX_RATE_HZ = 50;
const DEADZONE = 0.12;

/** Source names -> {v, w} while active. */
export class TeleopDriver extends EventTarget {
  /** publish(v, w) sends one Twist and returns whether it went out. */
  constructor(publish) {
    super();
    this.publish = publish;
    this.sources = new Map();
    this.timer = null;
    this.enabled = true;
    this.last = { v: 0, w: 0 };
    this.sent = 0;
    this.rateHz = RATE_HZ;
  }

  /** Publish at `hz` while driving (1 to MAX_RATE_HZ); takes effect at once. */
  setRate(hz) {
    this.rateHz = Math.min(MAX_RATE_HZ, Math.max(1, Number(hz) || RATE_HZ));
    if (this.timer !== null) {
      clearInterval(this.timer);
      this.timer = setInterval(() => this._tick(), 1000 / this.rateHz);
    }
  }

  /** Set (or clear with null) the command wanted by one input source. */
  set(source, cmd) {
    if (cmd === null) {
      if (!this.sources.delete(source)) return;
    } else {
      if (!this.enabled) return;
      this.sources.set(source, cmd);
    }
    this._update();
  }

  /** Drop every input and send one zero (blur, hidden, page hide, disconnect, e-stop). */
  stopAll() {
    const wasActive = this.sources.size > 0 || this.timer !== null;
    this.sources.clear();
    if (wasActive) this._update();
  }

  get active() { return this.sources.size > 0; }

  _command() {
    let v = 0, w = 0;
    for (const cmd of this.sources.values()) { v += cmd.v; w += cmd.w; }
    return { v, w };
  }

  _tick() {
    const { v, w } = this._command();
    this.last = { v, w };
    if (this.publish(v, w)) this.sent += 1;
    this.dispatchEvent(new CustomEvent('command', { detail: { v, w, active: this.active } }));
  }

  _update() {
    if (this.active) {
      if (this.timer === null) {
        this._tick(); // respond at once, then at the fixed rate
        this.timer = setInterval(() => this._tick(), 1000 / this.rateHz);
      }
    } else if (this.timer !== null) {
      clearInterval(this.timer);
      this.timer = null;
      this._tick(); // the one zero
    }
  }
}

const KEYS = {
  ArrowUp: 'fwd', KeyW: 'fwd', ArrowDown: 'back', KeyS: 'back',
  ArrowLeft: 'left', KeyA: 'left', ArrowRight: 'right', KeyD: 'right',
};

const TEXT_TYPES = new Set(['text', 'number', 'url', 'password', 'search', 'email', 'tel', '']);

/** Whether keys typed at `target` are text (Space types a space there, letters letters). */
function typingIn(target) {
  if (!target || !target.tagName) return false;
  if (target.isContentEditable || target.tagName === 'TEXTAREA') return true;
  return target.tagName === 'INPUT' && TEXT_TYPES.has((target.getAttribute('type') || '').toLowerCase());
}

/** Whether arrow keys have a use at `target` (a slider, a picker): they keep it. */
function arrowsUsedBy(target) {
  if (!target || !target.tagName) return false;
  return target.tagName === 'SELECT' || (target.tagName === 'INPUT' && target.type === 'range');
}

/**
 * Keyboard: WASD (by physical key) and arrows. Auto-repeat is ignored: the held set changes only
 * on the first keydown and on keyup. speeds() returns {v, w} magnitudes (m/s, rad/s).
 * Esc is the e-stop wherever the focus is; Space too, but in a text field (where it types a
 * space). W/A/S/D drive wherever the focus is but in a text field; the arrows also but on a
 * slider or a picker, whose values they change.
 */
export function installKeyboard(driver, speeds, onEstop) {
  const held = new Set();
  const apply = () => {
    if (!held.size) { driver.set('keyboard', null); return; }
    const dirs = new Set([...held].map((k) => KEYS[k]));
    const { v, w } = speeds();
    const lin = (dirs.has('fwd') ? 1 : 0) - (dirs.has('back') ? 1 : 0);
    const ang = (dirs.has('left') ? 1 : 0) - (dirs.has('right') ? 1 : 0);
    driver.set('keyboard', { v: lin * v, w: ang * w });
  };
  window.addEventListener('keydown', (e) => {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    const typing = typingIn(e.target);
    if (e.key === 'Escape' || (e.code === 'Space' && !typing)) {
      e.preventDefault(); // a focused button or checkbox must not also be pressed
      if (!e.repeat) onEstop();
      return;
    }
    if (typing) return;
    const code = KEYS[e.code] ? e.code : (KEYS[e.key] ? e.key : null);
    if (!code) return;
    if (code.startsWith('Arrow') && arrowsUsedBy(e.target)) return;
    e.preventDefault();
    if (e.repeat || held.has(code)) return;
    held.add(code);
    apply();
  }, true);
  window.addEventListener('keyup', (e) => {
    if (e.code === 'Space' && !typingIn(e.target)) e.preventDefault(); // no click on keyup
    const code = KEYS[e.code] ? e.code : (KEYS[e.key] ? e.key : null);
    if (!code || !held.delete(code)) return;
    apply();
  }, true);
  return { release: () => { held.clear(); } , reapply: apply, held };
}

/** On-screen joystick (pointer events; works for touch, pen and mouse). */
export function installJoystick(pad, knob, driver, speeds, onValue) {
  let id = null;
  const centre = () => {
    knob.style.transform = 'translate(-50%, -50%)';
    onValue(0, 0);
  };
  const move = (e) => {
    const r = pad.getBoundingClientRect();
    const radius = r.width / 2;
    let dx = (e.clientX - (r.left + radius)) / radius;
    let dy = (e.clientY - (r.top + radius)) / radius;
    const mag = Math.hypot(dx, dy);
    if (mag > 1) { dx /= mag; dy /= mag; }
    knob.style.transform = `translate(calc(-50% + ${dx * radius * 0.6}px), calc(-50% + ${dy * radius * 0.6}px))`;
    const dead = (x) => (Math.abs(x) < DEADZONE ? 0 : (x - Math.sign(x) * DEADZONE) / (1 - DEADZONE));
    const { v, w } = speeds();
    const cmd = { v: -dead(dy) * v, w: -dead(dx) * w };
    onValue(cmd.v, cmd.w);
    driver.set('joystick', cmd);
  };
  pad.addEventListener('pointerdown', (e) => {
    if (id !== null) return;
    id = e.pointerId;
    pad.setPointerCapture(id);
    e.preventDefault();
    move(e);
  });
  pad.addEventListener('pointermove', (e) => { if (e.pointerId === id) move(e); });
  const end = (e) => {
    if (e.pointerId !== id) return;
    id = null;
    centre();
    driver.set('joystick', null);
  };
  pad.addEventListener('pointerup', end);
  pad.addEventListener('pointercancel', end);
  pad.addEventListener('lostpointercapture', end);
  centre();
  return { release: () => { if (id !== null) { id = null; centre(); } } };
}

/** The gamepad mapping as now: left stick (axis 1 drives, axis 0 turns), LB or RB held. */
export const GAMEPAD_DEFAULTS = Object.freeze({
  linearAxis: 1, angularAxis: 0, invertLinear: false, invertAngular: false, deadman: [4, 5],
  rate: RATE_HZ,
});
// the standard mapping's names of the buttons most used as deadman
const BUTTON_NAMES = { 0: 'A', 1: 'B', 2: 'X', 3: 'Y', 4: 'LB', 5: 'RB', 6: 'LT', 7: 'RT' };
// URL parameter of each setting (?gp_linear_axis=3&gp_deadman=7&teleop_rate=20)
const GAMEPAD_PARAMS = {
  linearAxis: 'gp_linear_axis', angularAxis: 'gp_angular_axis', invertLinear: 'gp_invert_linear',
  invertAngular: 'gp_invert_angular', deadman: 'gp_deadman', rate: 'teleop_rate',
};

/** Parse one setting from text ('3', '1', '4,5', 'none'); null when it is not valid. */
export function parseSetting(key, text) {
  const t = String(text).trim();
  if (key === 'invertLinear' || key === 'invertAngular') return t === '1' || t === 'true';
  if (key === 'deadman') {
    if (t === '' || t === 'none') return [];
    const list = t.split(',').map((x) => Number(x.trim()));
    return list.every((n) => Number.isInteger(n) && n >= 0 && n < 64) ? list : null;
  }
  const n = Number(t);
  if (key === 'rate') return t !== '' && n >= 1 && n <= MAX_RATE_HZ ? n : null;
  return t !== '' && Number.isInteger(n) && n >= 0 && n < 64 ? n : null;
}

export const formatSetting = (key, value) => {
  if (key === 'deadman') return value.length ? value.join(',') : 'none';
  if (typeof value === 'boolean') return value ? '1' : '0';
  return String(value);
};

/** The gamepad settings in `search` (a location.search), defaults for absent or bad ones. */
export function gamepadSettingsFromUrl(search = window.location.search) {
  const params = new URLSearchParams(search);
  const settings = { ...GAMEPAD_DEFAULTS, deadman: [...GAMEPAD_DEFAULTS.deadman] };
  for (const [key, name] of Object.entries(GAMEPAD_PARAMS)) {
    if (!params.has(name)) continue;
    const value = parseSetting(key, params.get(name));
    if (value !== null) settings[key] = value;
  }
  return settings;
}

/** Write the settings that differ from the defaults into `params` (URLSearchParams). */
export function gamepadSettingsToUrl(settings, params) {
  for (const [key, name] of Object.entries(GAMEPAD_PARAMS)) {
    const value = formatSetting(key, settings[key]);
    if (value === formatSetting(key, GAMEPAD_DEFAULTS[key])) params.delete(name);
    else params.set(name, value);
  }
  return params;
}

/**
 * Gamepad (standard mapping by default): while a deadman button is held (none configured:
 * always), settings.linearAxis drives and settings.angularAxis turns, pushed up / left meaning
 * forward / left unless inverted. Releasing the deadman sends the one zero (teleop_tools #45).
 * `settings` is read at every poll, so the settings panel applies at once.
 */
export function installGamepad(driver, speeds, onStatus, settings = GAMEPAD_DEFAULTS) {
  let polling = false;
  const dead = (x) => (Math.abs(x) < DEADZONE ? 0 : (x - Math.sign(x) * DEADZONE) / (1 - DEADZONE));
  const pressed = (gp, i) => Boolean(gp.buttons[i] && gp.buttons[i].pressed);
  const poll = () => {
    const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
    const gp = pads[0];
    if (!gp) { driver.set('gamepad', null); polling = false; onStatus('no gamepad'); return; }
    const s = settings;
    const { v, w } = speeds();
    const lin = -dead(gp.axes[s.linearAxis] || 0) * (s.invertLinear ? -1 : 1);
    const ang = -dead(gp.axes[s.angularAxis] || 0) * (s.invertAngular ? -1 : 1);
    // no deadman: drive while the stick is off centre, so centring it sends the one zero
    const held = s.deadman.length ? s.deadman.some((i) => pressed(gp, i)) : (lin !== 0 || ang !== 0);
    driver.set('gamepad', held ? { v: lin * v, w: ang * w } : null);
    const names = s.deadman.map((i) => BUTTON_NAMES[i] || `button ${i}`).join('/');
    const hint = s.deadman.length ? `hold ${names} to drive` : 'stick drives';
    const axes = [...gp.axes].map((a) => a.toFixed(1)).join(' ');
    onStatus(`${gp.id.slice(0, 40)}: ${held ? 'driving' : hint} · axes ${axes}`);
    requestAnimationFrame(poll);
  };
  const start = () => { if (!polling) { polling = true; requestAnimationFrame(poll); } };
  window.addEventListener('gamepadconnected', start);
  window.addEventListener('gamepaddisconnected', () => driver.set('gamepad', null));
  return { release: () => driver.set('gamepad', null), settings };
}
