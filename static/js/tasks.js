// The Tasks tab: the tasks the instructor published, Start, and the result with its plot.
// Everything goes through the grader's services (/simbridge/grade/*, simbridge_msgs/srv/Grade),
// the same path `simbridge grade` and any client take; the server scores the run on the true
// pose. Loaded after main.js, whose parts it uses (window.simbridge: conn, state).
const $ = (id) => document.getElementById(id);
const TYPE = 'simbridge_msgs/srv/Grade';
const POLL_MS = 500;

const { conn, state } = window.simbridge;
const tasks = { list: [], attempt: null, timer: null, shown: false };

async function grade(service, request = {}) {
  const res = await conn.call(`/simbridge/grade/${service}`, TYPE,
    { task: '', robot: '', attempt: '', task_yaml: '', ...request });
  return JSON.parse(res.message);
}

const el = (tag, text, cls) => {
  const e = document.createElement(tag);
  if (text !== undefined) e.textContent = text;
  if (cls) e.className = cls;
  return e;
};
const fmt = (v) => (v === null || v === undefined ? '–' : String(v));
const bounds = (t) => [t.max !== null && t.max !== undefined ? `≤ ${t.max}` : '', t.min !== null && t.min !== undefined ? `≥ ${t.min}` : '']
  .filter(Boolean).join(' and ');

function say(text, kind = '') {
  const p = $('taskStatus');
  p.textContent = text;
  p.className = `figures ${kind}`;
}

function renderList() {
  const box = $('taskList');
  if (!tasks.list.length) {
    box.replaceChildren(el('p', 'No task is published yet: your instructor publishes them from /admin.', 'muted'));
    return;
  }
  box.replaceChildren(...tasks.list.map((t) => {
    const item = el('div', undefined, 'task');
    item.dataset.task = t.id;
    const head = el('div', undefined, 'row');
    head.append(el('strong', t.name));
    const start = el('button', 'Start');
    start.type = 'button';
    start.dataset.start = t.id;
    start.disabled = Boolean(tasks.attempt);
    start.addEventListener('click', () => startTask(t));
    head.append(start);
    item.append(head);
    if (t.description) item.append(el('p', t.description, 'muted'));
    const rubric = Object.entries(t.rubric).map(([m, b]) => `${m} ${bounds(b)}`).join(' · ');
    item.append(el('p', `${t.goal} goal · ${t.time_limit} s from your first command · ${rubric}`, 'muted'));
    return item;
  }));
}

async function loadTasks() {
  if (!conn.connected) return;
  try {
    const res = await grade('tasks');
    tasks.list = res.tasks.filter((t) => t.published);
    renderList();
  } catch (err) {
    $('taskList').replaceChildren(el('p', `No tasks: ${err.message}`, 'muted'));
  }
}

async function startTask(t) {
  if (state.estopped) { say('Release the e-stop first.', 'bad'); return; }
  $('taskResult').replaceChildren();
  try {
    const run = await grade('start', { task: t.id, robot: state.ns });
    tasks.attempt = run.attempt;
    say(`Attempt ${run.attempt}: your robot is at the start pose. Start your controller `
      + `(the PID lab, or your own node): the ${run.time_limit} s begin with its first command.`);
    renderList();
    poll();
  } catch (err) { say(`Could not start: ${err.message}`, 'bad'); }
}

async function poll() {
  clearTimeout(tasks.timer);
  if (!tasks.attempt) return;
  let res;
  try { res = await grade('status', { attempt: tasks.attempt }); } catch (err) {
    tasks.timer = setTimeout(poll, POLL_MS * 2);
    return;
  }
  if (res.status === 'waiting') {
    say(`Attempt ${res.attempt}: waiting for your controller (${res.waited_s.toFixed(0)} of ${res.wait_for_controller} s)…`);
  } else if (res.status === 'running') {
    say(`Attempt ${res.attempt}: running, ${res.elapsed_s.toFixed(1)} of ${res.time_limit} s…`);
  } else {
    tasks.attempt = null;
    showResult(res);
    renderList();
    return;
  }
  tasks.timer = setTimeout(poll, POLL_MS);
}

function showResult(res) {
  const passed = res.passed;
  const why = ['passed', 'failed'].includes(res.status) ? '' : ` (${res.status.replace('_', ' ')})`;
  say(`Attempt ${res.attempt}: ${passed ? 'PASSED' : 'FAILED'}${why}${res.reason ? ` – ${res.reason}` : ''}`,
    passed ? 'ok' : 'bad');
  const box = $('taskResult');
  const table = el('table', undefined, 'rates');
  for (const line of res.rubric || []) {
    const tr = el('tr', undefined, line.passed ? 'ok' : 'bad');
    tr.dataset.metric = line.metric;
    tr.append(el('td', line.metric), el('td', fmt(line.value)), el('td', bounds(line)), el('td', line.passed ? 'pass' : 'FAIL'));
    table.append(tr);
  }
  const plot = el('div', undefined, 'gradeplot');
  // the server's drawing of the response with the thresholds (numbers and escaped names only)
  if (res.plot_svg) plot.innerHTML = res.plot_svg;
  box.replaceChildren(table, plot);
  window.dispatchEvent(new CustomEvent('simbridge-grade-result', { detail: res }));
}

// the tab: load when shown, refresh while shown
for (const tab of document.querySelectorAll('.tabs button')) {
  tab.addEventListener('click', () => {
    tasks.shown = tab.dataset.tab === 'tasks';
    if (tasks.shown) loadTasks();
  });
}
setInterval(() => { if (tasks.shown && !tasks.attempt) loadTasks(); }, 5000);
conn.addEventListener('connected', () => { if (tasks.shown) loadTasks(); if (tasks.attempt) poll(); });

window.simbridge.tasks = { tasks, loadTasks, startTask };
