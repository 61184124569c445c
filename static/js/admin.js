// The instructor's console: every call carries the admin token; the server refuses changes
// without it. Nothing but the token field is shown until the token is accepted.
const $ = (id) => document.getElementById(id);
const EDITABLE = /^(robot|lidar|realism)\./;
let token = sessionStorage.getItem('simbridge-admin-token') || '';
let current = null;   // the last /api/admin/state
$('token').value = token;

/** Feedback next to what was clicked (`where`: a .feedback element id; default the top line). */
function say(text, ok, where = 'message') {
  const el = $(where);
  el.textContent = text;
  el.className = `${where === 'message' ? '' : 'feedback '}${ok ? 'ok' : 'error'}`;
}

async function api(path, body) {
  const init = { headers: {} };
  if (token) init.headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) {
    init.method = 'POST';
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  const res = await fetch(path, init);
  let data = {};
  try { data = await res.json(); } catch (e) { data = { error: `HTTP ${res.status}` }; }
  if (!res.ok) throw new Error(data.error || `HTTP ${res.status}`);
  return data;
}

/** Run an action, say how it went next to it, refresh. */
async function act(where, fn, done) {
  try {
    const res = await fn();
    say(done(res), true, where);
  } catch (err) { say(`Refused: ${err.message}`, false, where); }
  refresh();
}

const cell = (text) => { const td = document.createElement('td'); td.textContent = String(text); return td; };
const ago = (since) => {
  const s = Math.max(0, Date.now() / 1000 - since);
  return s < 60 ? `${Math.round(s)} s ago` : `${Math.floor(s / 60)} min ${Math.round(s % 60)} s ago`;
};

function paramLabel(state, name, value, { shared = null } = {}) {
  const label = document.createElement('label');
  const title = document.createElement('span');
  title.textContent = state.descriptions[name] || name;
  const input = document.createElement('input');
  input.name = name;
  if (shared === null) input.value = JSON.stringify(value);
  else { input.value = value === undefined ? '' : JSON.stringify(value); input.placeholder = `shared: ${JSON.stringify(shared)}`; }
  input.readOnly = (state.read_only || []).includes(name); // startup only (the description says)
  input.addEventListener('input', () => { input.dataset.dirty = '1'; });
  const code = document.createElement('small');
  code.className = 'name';
  code.textContent = name;
  label.append(title, input, code);
  const affects = state.affects && state.affects[name];
  if (affects) {
    const hint = document.createElement('small');
    hint.className = 'affects';
    hint.textContent = `affects ${affects}`;
    label.append(hint);
  }
  return label;
}

function renderParams(state) {
  const box = $('params');
  if (box.dataset.filled) {
    for (const [name, value] of Object.entries(state.params)) {
      const el = box.querySelector(`[name="${name}"]`);
      if (el && document.activeElement !== el && !el.dataset.dirty) el.value = JSON.stringify(value);
    }
    return;
  }
  box.replaceChildren(...Object.keys(state.params).filter((n) => EDITABLE.test(n))
    .map((name) => paramLabel(state, name, state.params[name])));
  box.dataset.filled = '1';
}

function renderRobotParams(state) {
  const pick = $('robotPick');
  const names = Object.keys(state.robots);
  if ([...pick.options].map((o) => o.value).join('|') !== names.join('|')) {
    const keep = pick.value;
    pick.replaceChildren(...names.map((n) => new Option(n || '(default)', n)));
    if (names.includes(keep)) pick.value = keep;
    delete $('robotParams').dataset.robot;
  }
  const robot = pick.value;
  const box = $('robotParams');
  const own = (state.robots[robot] || {}).own || {};
  if (box.dataset.robot === robot) {
    for (const name of state.per_robot) {
      const el = box.querySelector(`[name="${name}"]`);
      if (el && document.activeElement !== el && !el.dataset.dirty) {
        el.value = own[name] === undefined ? '' : JSON.stringify(own[name]);
        el.placeholder = `shared: ${JSON.stringify(state.params[name])}`;
      }
    }
    return;
  }
  box.replaceChildren(...state.per_robot.map((name) => paramLabel(state, name, own[name], { shared: state.params[name] })));
  box.dataset.robot = robot;
}

function renderRobots(state) {
  $('robots').replaceChildren(...Object.entries(state.robots).map(([name, r]) => {
    const tr = document.createElement('tr');
    if (r.held) tr.className = 'held';
    const own = Object.entries(r.own).map(([k, v]) => `${k.replace('robot.', '')} ${v}`).join(', ') || '–';
    tr.append(cell(name || '(default)'), cell(r.pose.map((v) => v.toFixed(2)).join(', ')),
      cell(r.clients.join('; ') || '–'), cell(own), cell(r.held ? 'HELD' : '–'));
    return tr;
  }));
}

function renderEstops(state) {
  $('noEstops').hidden = state.estops.length > 0;
  $('estops').replaceChildren(...state.estops.map((e) => {
    const tr = document.createElement('tr');
    const td = document.createElement('td');
    const b = document.createElement('button');
    b.type = 'button';
    b.textContent = 'Release';
    b.dataset.latch = String(e.id);
    b.addEventListener('click', () => act('estopMsg', () => api('/api/admin/estop', { action: 'release', id: e.id }),
      () => `Released the e-stop of ${e.covers} (latched by ${e.by}).`));
    td.append(b);
    tr.append(cell(e.global ? 'every robot (global)' : e.covers), cell(e.by), cell(ago(e.since)), td);
    return tr;
  }));
}

function renderClients(clients) {
  $('clients').replaceChildren(...clients.map((c) => {
    const tr = document.createElement('tr');
    const robot = c.any_robot ? 'any' : (c.robots.join(', ') || '–');
    tr.title = c.label;
    for (const td of [cell(c.name), cell(robot), cell(c.subscriptions.join(', ')), cell(c.publishing.join(', ')), cell(c.frames_sent), cell(c.dropped)]) tr.append(td);
    return tr;
  }));
}

async function refresh(quiet = true) {
  try {
    const state = await api('/api/admin/state');
    current = state;
    $('console').hidden = false;
    renderEstops(state);
    renderParams(state);
    renderRobotParams(state);
    renderRobots(state);
    renderClients(state.clients);
    if (document.activeElement !== $('model')) $('model').value = state.motion_model;
    $('worldInfo').textContent = `model: ${state.motion_model} · sim time ${state.sim_time_s.toFixed(1)} s · ${Object.keys(state.robots).length} robots · ${state.clients.length} clients`;
    if (!quiet) say('Unlocked.', true);
    return true;
  } catch (err) {
    $('console').hidden = true;
    if (!quiet) say(`Refused: ${err.message}`, false);
    return false;
  }
}

$('tokenForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  token = $('token').value.trim();
  sessionStorage.setItem('simbridge-admin-token', token);
  await refresh(false);
});
$('estopAll').addEventListener('click', () => act('estopMsg', () => api('/api/admin/estop', { action: 'latch' }),
  () => 'Every robot is stopped (global e-stop): release it here.'));
$('releaseAll').addEventListener('click', () => act('estopMsg', () => api('/api/admin/estop', { action: 'release_all' }),
  (res) => (res.released.length ? `Released ${res.released.length} e-stop(s).` : 'No e-stop was latched.')));
$('applyModel').addEventListener('click', () => act('worldMsg', () => api('/api/admin/motion', { model: $('model').value }),
  (res) => `Motion model: ${res.motion_model}.`));
$('reset').addEventListener('click', () => act('worldMsg', () => api('/api/admin/reset', {}), () => 'World reset.'));

function dirtyValues(box, where, { nullable = false } = {}) {
  const changes = {};
  for (const input of box.querySelectorAll('input[data-dirty]')) {
    if (nullable && input.value.trim() === '') { changes[input.name] = null; continue; }
    try { changes[input.name] = JSON.parse(input.value); } catch (err) {
      say(`${input.name}: "${input.value}" is not a number or list`, false, where);
      return null;
    }
  }
  return changes;
}
$('paramsForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  const changes = dirtyValues($('params'), 'paramsMsg');
  if (changes === null) return;
  if (!Object.keys(changes).length) { say('Nothing changed.', true, 'paramsMsg'); return; }
  await act('paramsMsg', async () => {
    const res = await api('/api/admin/params', { changes });
    for (const input of $('params').querySelectorAll('input[data-dirty]')) delete input.dataset.dirty;
    return res;
  }, () => `Applied: ${Object.entries(changes).map(([k, v]) => `${k} = ${JSON.stringify(v)}`).join(', ')}.`);
});
$('robotPick').addEventListener('change', () => { if (current) renderRobotParams(current); });
$('robotForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  const robot = $('robotPick').value;
  const changes = dirtyValues($('robotParams'), 'robotMsg', { nullable: true });
  if (changes === null) return;
  if (!Object.keys(changes).length) { say('Nothing changed.', true, 'robotMsg'); return; }
  await act('robotMsg', async () => {
    const res = await api('/api/admin/robot', { robot, changes });
    for (const input of $('robotParams').querySelectorAll('input[data-dirty]')) delete input.dataset.dirty;
    return res;
  }, (res) => `Robot ${robot}: ${Object.entries(res.own).map(([k, v]) => `${k} = ${v}`).join(', ') || 'shared values'}.`);
});
$('robotShared').addEventListener('click', async () => {
  const robot = $('robotPick').value;
  const own = current && current.robots[robot] ? Object.keys(current.robots[robot].own) : [];
  if (!own.length) { say(`Robot ${robot} already uses the shared values.`, true, 'robotMsg'); return; }
  const changes = Object.fromEntries(own.map((k) => [k, null]));
  delete $('robotParams').dataset.robot;
  await act('robotMsg', () => api('/api/admin/robot', { robot, changes }), () => `Robot ${robot}: back to the shared values.`);
});

if (token) refresh(false);
setInterval(() => { if (token) refresh(); }, 2000);
// for tests
window.simbridgeAdmin = { refresh, api };
