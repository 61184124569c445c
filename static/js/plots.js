// Live time-series plots a lab report can use, on uPlot (static/vendor, global uPlot): a time
// axis in seconds, readable ticks, a legend with the values under the cursor, pause, drag to
// zoom (double-click: back to live), CSV and PNG export. Drawn only while visible and at most
// ten times a second; nothing is drawn while nothing changed.

const DRAW_INTERVAL_MS = 100;

/** One CSV field: numbers in full precision, text quoted when needed. */
function field(v) {
  if (v === null || v === undefined || (typeof v === 'number' && !Number.isFinite(v))) return '';
  if (typeof v === 'number') return String(v);
  const s = String(v);
  return /[",\n]/.test(s) ? `"${s.replace(/"/g, '""')}"` : s;
}

/** Save `content` (a string or a data: URL) as a download called `name`. */
export function download(name, content, type = 'text/csv') {
  const a = document.createElement('a');
  a.download = name;
  if (typeof content === 'string' && content.startsWith('data:')) a.href = content;
  else a.href = URL.createObjectURL(new Blob([content], { type }));
  document.body.append(a);
  a.click();
  a.remove();
  if (a.href.startsWith('blob:')) setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

/**
 * Labels of axis ticks with as many decimals as the ticks need, so that no two read alike
 * (the default shows at most 3: ticks 0.0001 apart all read "0"); "-0" reads "0".
 */
export function tickLabels(splits) {
  let labels = [];
  for (let d = 0; d <= 8; d++) {
    labels = splits.map((v) => { const s = v.toFixed(d); return Number(s) === 0 ? s.replace('-', '') : s; });
    if (splits.every((v, i) => Math.abs(Number(labels[i]) - v) <= 1e-9 * Math.max(1, Math.abs(v)))) break;
  }
  return labels;
}

/** An axis as wide as its longest tick label (uPlot's `size` callback): labels never run into the unit. */
function axisSize(u, values, i, cycle) {
  const axis = u.axes[i];
  if (cycle > 1) return axis._size; // uPlot asks again after a resize: settle
  const longest = (values ?? []).reduce((a, v) => (String(v).length > a.length ? String(v) : a), '');
  u.ctx.font = axis.font[0];
  const ratio = window.devicePixelRatio || 1;
  return Math.ceil(axis.ticks.size + axis.gap + u.ctx.measureText(longest).width / ratio + 4);
}

export class LivePlot {
  /**
   * @param box     the element the plot lives in (a toolbar and the chart are added to it)
   * @param series  [{label, color, dash?, width?}]
   * @param opts    {title, unit, window (s shown while live), min (a floor of the y range),
   *                 minSpan (the y range shown at least, default 0.02: a residual of 1e-4
   *                 is not blown up to the plot's height), anchored (x from 0: a step response),
   *                 maxPoints (kept for export),
   *                 file (CSV/PNG name stem), columns (extra CSV columns, e.g. ['stamp'])}
   */
  constructor(box, series, opts = {}) {
    this.box = box;
    this.series = series;
    this.title = opts.title ?? '';
    this.unit = opts.unit ?? '';
    this.window = opts.window ?? 20;
    this.floor = opts.min;
    this.minSpan = opts.minSpan ?? 0.02;
    this.anchored = opts.anchored ?? false;
    this.maxPoints = opts.maxPoints ?? 6000;
    this.file = opts.file ?? 'plot';
    this.columns = opts.columns ?? [];
    this.xs = [];
    this.ys = series.map(() => []);
    this.extra = this.columns.map(() => []);
    this.bands = [];          // [{lo, hi}] shaded y ranges
    this.marks = [];          // [{t, label}] vertical markers
    this.paused = false;
    this.zoomed = false;
    this.visible = true;
    this.dirty = true;
    this.draws = 0;
    this._last = 0;
    this._timer = null;
    this._build();
  }

  _build() {
    const bar = document.createElement('div');
    bar.className = 'plotbar';
    const title = document.createElement('strong');
    title.textContent = this.title;
    const button = (text, hint, fn) => {
      const b = document.createElement('button');
      b.type = 'button'; b.textContent = text; b.title = hint;
      b.addEventListener('click', fn);
      bar.append(b);
      return b;
    };
    bar.append(title);
    this.pauseButton = button('Pause', 'freeze the plot (data keeps being recorded)', () => this.setPaused(!this.paused));
    button('Live', 'back to the last seconds, zoom reset', () => { this.zoomed = false; this.setPaused(false); });
    button('CSV', 'download the recorded samples as CSV', () => download(`${this.file}.csv`, this.csv()));
    button('PNG', 'download the plot as a PNG image', () => download(`${this.file}.png`, this.png(), 'image/png'));
    this.chartBox = document.createElement('div');
    this.chartBox.className = 'chart';
    this.box.append(bar, this.chartBox);
    const floor = this.floor, minSpan = this.minSpan;
    const opts = {
      width: Math.max(200, this.chartBox.clientWidth || 300),
      height: Math.max(80, this.chartBox.clientHeight || 130),
      pxAlign: 0,
      legend: { live: true },
      cursor: { drag: { x: true, y: false, setScale: true }, points: { size: 5 } },
      scales: {
        x: { time: false },
        y: {
          range: (u, lo, hi) => {
            let a = Number.isFinite(lo) ? lo : -1, b = Number.isFinite(hi) ? hi : 1;
            for (const band of this.bands) { a = Math.min(a, band.lo); b = Math.max(b, band.hi); }
            if (floor !== undefined) a = Math.max(floor, Math.min(a, floor));
            if (b - a < 1e-6) { a -= 0.5; b += 0.5; } else if (b - a < minSpan) {
              const mid = (a + b) / 2; a = mid - minSpan / 2; b = mid + minSpan / 2;
            }
            const pad = (b - a) * 0.08;
            const out = uPlot.rangeNum(a - pad, b + pad, 0.1, true);
            if (floor !== undefined && out[0] < floor) out[0] = floor;
            return out;
          },
        },
      },
      axes: [
        { label: 't (s)', labelSize: 16, size: 34, font: '11px system-ui', labelFont: '11px system-ui' },
        { label: this.unit, labelSize: 16, size: axisSize, font: '11px system-ui', labelFont: '11px system-ui',
          values: (u, splits) => tickLabels(splits) },
      ],
      series: [
        { label: 't (s)', value: (u, v) => (v === null || v === undefined ? '–' : v.toFixed(2)) },
        ...this.series.map((s) => ({
          label: s.label, stroke: s.color, width: s.width ?? 1.5, dash: s.dash, spanGaps: false,
          value: (u, v) => (v === null || v === undefined ? '–' : v.toFixed(3)),
        })),
      ],
      hooks: {
        setSelect: [(u) => { if (u.select.width > 0) { this.zoomed = true; this._showPause(); } }],
        draw: [(u) => this._decorate(u)],
      },
    };
    this.u = new uPlot(opts, [this.xs, ...this.ys], this.chartBox);
    this.u.over.addEventListener('dblclick', () => { this.zoomed = false; this.setPaused(false); });
    new ResizeObserver(() => {
      const w = this.chartBox.clientWidth, h = this.chartBox.clientHeight;
      if (w > 0 && h > 0 && w !== this.u.width) {
        const legend = this.u.root.querySelector('.u-legend');
        this.u.setSize({ width: w, height: Math.max(80, h - (legend ? legend.offsetHeight : 28)) });
      }
    }).observe(this.chartBox);
  }

  _decorate(u) {
    const ctx = u.ctx;
    const { left, top, width, height } = u.bbox;
    ctx.save();
    for (const b of this.bands) {
      const y1 = u.valToPos(b.hi, 'y', true), y2 = u.valToPos(b.lo, 'y', true);
      ctx.fillStyle = 'rgba(34, 197, 94, 0.14)';
      ctx.fillRect(left, Math.max(top, y1), width, Math.min(top + height, y2) - Math.max(top, y1));
    }
    for (const m of this.marks) {
      const x = u.valToPos(m.t, 'x', true);
      if (x < left || x > left + width) continue;
      ctx.strokeStyle = '#a855f7';
      ctx.setLineDash([4, 3]);
      ctx.beginPath(); ctx.moveTo(x, top); ctx.lineTo(x, top + height); ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = '#7e22ce';
      ctx.font = `${Math.round(11 * devicePixelRatio)}px system-ui`;
      ctx.fillText(m.label, x + 4, top + 12 * devicePixelRatio);
    }
    ctx.restore();
  }

  _showPause() {
    this.pauseButton.textContent = this.paused || this.zoomed ? 'Resume' : 'Pause';
    this.pauseButton.setAttribute('aria-pressed', String(this.paused || this.zoomed));
  }

  setPaused(on) {
    this.paused = on;
    if (!on) this.zoomed = false;
    this._showPause();
    this.dirty = true;
    this._schedule();
  }

  setVisible(on) {
    this.visible = on;
    if (on) { this.dirty = true; this._schedule(); }
  }

  /** Add one sample at time t (s): values per series (null: no value), extra CSV columns. */
  push(t, values, extra = []) {
    this.xs.push(t);
    values.forEach((v, i) => this.ys[i].push(v === null || v === undefined || !Number.isFinite(v) ? null : v));
    this.extra.forEach((col, i) => col.push(extra[i] ?? ''));
    if (this.xs.length > this.maxPoints) this._drop(this.xs.length - this.maxPoints);
    this.dirty = true;
    this._schedule();
  }

  /** A gap: the line breaks here (a reset, a reconnect, another robot). */
  gap(t) {
    if (!this.xs.length || this.ys[0][this.ys[0].length - 1] === null) return;
    this.push(t, this.series.map(() => null));
  }

  _drop(n) {
    this.xs.splice(0, n);
    for (const y of this.ys) y.splice(0, n);
    for (const c of this.extra) c.splice(0, n);
  }

  clear() {
    this._drop(this.xs.length);
    this.marks = []; this.bands = [];
    this.zoomed = false;
    this.dirty = true;
    this._schedule();
  }

  /** The latest value of series i, or null. */
  latest(i) {
    const y = this.ys[i];
    for (let k = y.length - 1; k >= 0; k--) if (y[k] !== null) return y[k];
    return null;
  }

  _schedule() {
    if (this._timer !== null || !this.visible || this.paused || this.zoomed) return;
    const wait = Math.max(0, DRAW_INTERVAL_MS - (performance.now() - this._last));
    this._timer = setTimeout(() => {
      this._timer = null;
      requestAnimationFrame(() => this.draw());
    }, wait);
  }

  draw() {
    if (!this.dirty || !this.visible || this.paused || this.zoomed) return;
    this.dirty = false;
    this._last = performance.now();
    this.draws += 1;
    const tLast = this.xs.length ? this.xs[this.xs.length - 1] : 0;
    const first = this.xs.length ? this.xs[0] : 0;
    const min = this.anchored ? 0 : Math.max(first, tLast - this.window);
    const max = this.anchored ? Math.max(this.window, tLast) : tLast;
    this.u.batch(() => {
      this.u.setData([this.xs, ...this.ys], false);
      this.u.setScale('x', { min, max: Math.max(max, min + 1e-3) });
    });
  }

  /** Every recorded sample as CSV: t_s, the extra columns, then one column per series. */
  csv() {
    const unit = this.unit ? ` (${this.unit})` : '';
    const head = ['t_s', ...this.columns, ...this.series.map((s) => `${s.label}${unit}`)];
    const rows = [head.map(field).join(',')];
    for (let k = 0; k < this.xs.length; k++) {
      if (this.ys.every((y) => y[k] === null)) continue; // a gap
      rows.push([this.xs[k], ...this.extra.map((c) => c[k]), ...this.ys.map((y) => y[k])].map(field).join(','));
    }
    return `${rows.join('\n')}\n`;
  }

  /** The plot as a PNG data URL: white background, title, legend, axes and lines. */
  png() {
    const src = this.u.ctx.canvas;
    const dpr = window.devicePixelRatio || 1;
    const head = Math.round(24 * dpr);
    const out = document.createElement('canvas');
    out.width = src.width; out.height = src.height + head;
    const ctx = out.getContext('2d');
    ctx.fillStyle = '#fff';
    ctx.fillRect(0, 0, out.width, out.height);
    ctx.font = `${Math.round(12 * dpr)}px system-ui, sans-serif`;
    ctx.fillStyle = '#111';
    let x = Math.round(8 * dpr);
    const y = Math.round(16 * dpr);
    ctx.fillText(this.title, x, y);
    x += ctx.measureText(this.title).width + 14 * dpr;
    for (const s of this.series) {
      ctx.fillStyle = s.color;
      ctx.fillRect(x, y - 8 * dpr, 14 * dpr, 3 * dpr);
      x += 18 * dpr;
      ctx.fillStyle = '#111';
      ctx.fillText(s.label, x, y);
      x += ctx.measureText(s.label).width + 12 * dpr;
    }
    ctx.drawImage(src, 0, head);
    return out.toDataURL('image/png');
  }
}
