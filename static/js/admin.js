// The instructor's page: every call carries the admin token; the server refuses changes without it.
const $ = (id) => document.getElementById(id);
const EDITABLE = /^(robot|lidar)\./;
let token = sessionStorage.getItem('simbridge-admin-token') || '';
let current = {};
$('token').value = token;

function say(text, ok) {
  $('message').textContent = text;
  $('message').className = ok ? 'ok' : 'error';
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

function renderParams(state) {
  current = state.params;
  const box = $('params');
  if (box.dataset.filled) {
    for (const [name, value] of Object.entries(current)) {
      const el = box.querySelector(`[name="${name}"]`);
      if (el && document.activeElement !== el && !el.dataset.dirty) el.value = JSON.stringify(value);
    }
    return;
  }
  box.replaceChildren(...Object.keys(current).filter((n) => EDITABLE.test(n)).map((name) => {
    const label = document.createElement('label');
    const input = document.createElement('input');
    input.name = name;
    input.value = JSON.stringify(current[name]);
    input.readOnly = (state.read_only || []).includes(name); // startup only (the description says)
    input.addEventListener('input', () => { input.dataset.dirty = '1'; });
    const hint = document.createElement('small');
    hint.textContent = state.descriptions[name] || '';
    label.append(name, input, hint);
    return label;
  }));
  box.dataset.filled = '1';
}

function renderClients(clients) {
  $('clients').replaceChildren(...clients.map((c) => {
    const tr = document.createElement('tr');
    for (const text of [c.label, c.subscriptions.join(', '), c.publishing.join(', '), c.frames_sent, c.dropped]) {
      const td = document.createElement('td'); td.textContent = String(text); tr.append(td);
    }
    return tr;
  }));
}

async function refresh(quiet = true) {
  try {
    const state = await api('/api/admin/state');
    renderParams(state);
    renderClients(state.clients);
    if (document.activeElement !== $('model')) $('model').value = state.motion_model;
    $('worldInfo').textContent = `model: ${state.motion_model} · sim time ${state.sim_time_s.toFixed(1)} s${state.estopped ? ' · E-STOP LATCHED' : ''}`;
    if (!quiet) say('Unlocked.', true);
    return true;
  } catch (err) {
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
$('applyModel').addEventListener('click', async () => {
  try {
    const res = await api('/api/admin/motion', { model: $('model').value });
    say(`Motion model: ${res.motion_model}.`, true);
  } catch (err) { say(`Refused: ${err.message}`, false); }
  refresh();
});
$('reset').addEventListener('click', async () => {
  try { await api('/api/admin/reset', {}); say('World reset.', true); } catch (err) { say(`Refused: ${err.message}`, false); }
  refresh();
});
$('paramsForm').addEventListener('submit', async (e) => {
  e.preventDefault();
  const changes = {};
  for (const input of $('params').querySelectorAll('input[data-dirty]')) {
    try { changes[input.name] = JSON.parse(input.value); } catch (err) {
      say(`${input.name}: "${input.value}" is not a number or list`, false); return;
    }
  }
  if (!Object.keys(changes).length) { say('Nothing changed.', true); return; }
  try {
    await api('/api/admin/params', { changes });
    for (const input of $('params').querySelectorAll('input[data-dirty]')) delete input.dataset.dirty;
    say(`Applied: ${Object.entries(changes).map(([k, v]) => `${k} = ${JSON.stringify(v)}`).join(', ')}.`, true);
  } catch (err) { say(`Refused: ${err.message}`, false); }
  refresh();
});

if (token) refresh(false);
setInterval(() => { if (token) refresh(); }, 2000);
// for tests
window.simbridgeAdmin = { refresh, api };
