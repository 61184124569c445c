// The instructor's grading section of /admin: publish or withdraw tasks, every student's
// attempts (with the plot), the best attempt of each, CSV export. Self-contained: it reads the
// token admin.js keeps for the tab and calls /api/admin/grading* with it.
const $ = (id) => document.getElementById(id);
const token = () => sessionStorage.getItem('simbridge-admin-token') || '';

async function api(path, body) {
  const init = { headers: { Authorization: `Bearer ${token()}` } };
  if (body !== undefined) {
    init.method = 'POST';
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  const res = await fetch(path, init);
  const data = await res.json().catch(() => ({ error: `HTTP ${res.status}` }));
  if (!res.ok) throw new Error(data.error || `HTTP ${res.status}`);
  return data;
}

function say(text, ok) {
  const el = $('gradingMsg');
  el.textContent = text;
  el.className = `feedback ${ok ? 'ok' : 'error'}`;
}
const td = (text) => { const e = document.createElement('td'); e.textContent = text === null || text === undefined ? '–' : String(text); return e; };
const when = (t) => (t ? new Date(t * 1000).toLocaleTimeString() : '–');
const failedLines = (a) => (a.rubric || []).filter((l) => !l.passed).map((l) => l.metric).join(', ');

function attemptRow(a, best) {
  const tr = document.createElement('tr');
  tr.dataset.attempt = a.attempt;
  const verdict = a.status === 'running' ? 'running' : (a.passed ? 'pass' : `fail${failedLines(a) ? ` (${failedLines(a)})` : ''}`);
  tr.append(td(a.student), td(a.robot || '(default)'), td(a.task_id + (a.official ? '' : ' (own copy)')),
    td(when(a.time)), td(a.status), td(verdict), td(a.metrics ? a.metrics.overshoot_pct : null),
    td(a.metrics ? a.metrics.settling_time_s : null), td(best.has(a.attempt) ? 'best' : ''));
  const cell = document.createElement('td');
  if (a.status !== 'running') {
    const b = document.createElement('button');
    b.type = 'button'; b.textContent = 'Plot'; b.dataset.plot = a.attempt;
    b.addEventListener('click', () => showPlot(a.attempt));
    cell.append(b);
  }
  tr.append(cell);
  return tr;
}

async function showPlot(id) {
  try {
    const a = await api(`/api/admin/grading/attempt?id=${encodeURIComponent(id)}`);
    $('gradingPlotTitle').textContent = `${a.attempt}: ${a.student} · ${a.task_id} · ${a.status.replace('_', ' ')}`;
    // the server's drawing (numbers and escaped names only)
    $('gradingPlot').innerHTML = a.plot_svg || '';
  } catch (err) { say(`Plot: ${err.message}`, false); }
}

async function refresh() {
  if (!token() || $('console').hidden) return;
  let state;
  try { state = await api('/api/admin/grading'); } catch (err) { say(err.message, false); return; }
  $('gradingFile').textContent = state.results_file
    ? `Results are kept in ${state.results_file} (read back at every start).`
    : 'Results are kept in memory only: start simbridge with --results FILE to keep them across restarts.';
  $('gradingTasks').replaceChildren(...state.tasks.map((t) => {
    const tr = document.createElement('tr');
    tr.dataset.task = t.id;
    const b = document.createElement('button');
    b.type = 'button';
    b.textContent = t.published ? 'Withdraw' : 'Publish';
    b.dataset.publish = t.id;
    b.addEventListener('click', async () => {
      try {
        await api('/api/admin/grading/publish', { task: t.id, published: !t.published });
        say(`Task ${t.id} ${t.published ? 'withdrawn' : 'published'}.`, true);
      } catch (err) { say(`Refused: ${err.message}`, false); }
      refresh();
    });
    const cell = document.createElement('td'); cell.append(b);
    tr.append(td(t.id), td(t.name), td(t.goal), td(`${t.time_limit} s`), td(t.published ? 'published' : '–'), cell);
    return tr;
  }));
  const best = new Set(state.best.map((a) => a.attempt));
  $('gradingBest').replaceChildren(...state.best.map((a) => attemptRow(a, best)));
  $('gradingAttempts').replaceChildren(...state.attempts.slice().reverse().map((a) => attemptRow(a, best)));
  $('gradingNone').hidden = state.attempts.length > 0;
}

$('gradingCsv').addEventListener('click', async () => {
  try {
    const res = await fetch('/api/admin/grading.csv', { headers: { Authorization: `Bearer ${token()}` } });
    if (!res.ok) throw new Error(`HTTP ${res.status}`);
    const url = URL.createObjectURL(await res.blob());
    const a = document.createElement('a');
    a.href = url; a.download = 'grading.csv'; a.click();
    setTimeout(() => URL.revokeObjectURL(url), 1000);
    say('CSV downloaded.', true);
  } catch (err) { say(`CSV: ${err.message}`, false); }
});
setInterval(refresh, 2000);
refresh();
window.simbridgeGrading = { refresh, showPlot };
