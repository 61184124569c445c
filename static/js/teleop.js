// Teleop: keyboard, on-screen joystick and gamepad feed one driver that publishes /cmd_vel at a
// fixed rate while some input is active, then sends exactly one zero and stays silent (so a
// student's own node can drive /cmd_vel: dimos #4119). Every way of losing the input (key up,
// blur, hidden tab, page hide, disconnect) ends in that one zero.

export const RATE_HZ = 10;
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
        this.timer = setInterval(() => this._tick(), 1000 / RATE_HZ);
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

function typingIn(target) {
  if (!target || !target.tagName) return false;
  const tag = target.tagName;
  return tag === 'INPUT' || tag === 'TEXTAREA' || tag === 'SELECT' || target.isContentEditable;
}

/**
 * Keyboard: WASD (by physical key) and arrows. Auto-repeat is ignored: the held set changes only
 * on the first keydown and on keyup. speeds() returns {v, w} magnitudes (m/s, rad/s).
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
    if (typingIn(e.target) || e.ctrlKey || e.metaKey || e.altKey) return;
    if (e.code === 'Space' || e.key === 'Escape') {
      e.preventDefault();
      if (!e.repeat) onEstop();
      return;
    }
    const code = KEYS[e.code] ? e.code : (KEYS[e.key] ? e.key : null);
    if (!code) return;
    e.preventDefault();
    if (e.repeat || held.has(code)) return;
    held.add(code);
    apply();
  });
  window.addEventListener('keyup', (e) => {
    const code = KEYS[e.code] ? e.code : (KEYS[e.key] ? e.key : null);
    if (!code || !held.delete(code)) return;
    apply();
  });
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

/**
 * Gamepad (standard mapping): hold LB or RB (buttons 4/5) as deadman; left stick y drives,
 * left stick x turns. Releasing the deadman sends the one zero (teleop_tools #45).
 */
export function installGamepad(driver, speeds, onStatus) {
  let polling = false;
  const poll = () => {
    const pads = navigator.getGamepads ? [...navigator.getGamepads()].filter(Boolean) : [];
    const gp = pads[0];
    if (!gp) { driver.set('gamepad', null); polling = false; onStatus('no gamepad'); return; }
    const deadman = (gp.buttons[4] && gp.buttons[4].pressed) || (gp.buttons[5] && gp.buttons[5].pressed);
    if (deadman) {
      const dead = (x) => (Math.abs(x) < DEADZONE ? 0 : (x - Math.sign(x) * DEADZONE) / (1 - DEADZONE));
      const { v, w } = speeds();
      driver.set('gamepad', { v: -dead(gp.axes[1] || 0) * v, w: -dead(gp.axes[0] || 0) * w });
    } else {
      driver.set('gamepad', null);
    }
    onStatus(`${gp.id.slice(0, 40)}: ${deadman ? 'driving' : 'hold LB/RB to drive'}`);
    requestAnimationFrame(poll);
  };
  const start = () => { if (!polling) { polling = true; requestAnimationFrame(poll); } };
  window.addEventListener('gamepadconnected', start);
  window.addEventListener('gamepaddisconnected', () => driver.set('gamepad', null));
  return { release: () => driver.set('gamepad', null) };
}
