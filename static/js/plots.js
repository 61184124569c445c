// Small live time-series plots on Canvas 2D (no library): a rolling window of samples, one
// line per series, autoscaled y with optional fixed bounds, crisp on high-DPI screens.

export class TimeSeriesPlot {
  /**
   * @param canvas  the <canvas>
   * @param series  [{label, color, dash?}]
   * @param opts    {window: seconds shown, unit, min, max (fixed bounds, optional)}
   */
  constructor(canvas, series, opts = {}) {
    this.canvas = canvas;
    this.series = series;
    this.window = opts.window ?? 20;
    this.unit = opts.unit ?? '';
    this.fixed = { min: opts.min, max: opts.max };
    this.anchored = opts.anchored ?? false; // x axis from t = 0 (a step response), not rolling
    this.data = [];  // [t, v0, v1, ...] (t in seconds)
    this.marks = []; // [{t, label}] vertical markers
    this.bands = []; // [{lo, hi}] shaded y ranges
    this.dirty = true;
    this.maxPoints = opts.maxPoints ?? 2000;
    new ResizeObserver(() => { this.dirty = true; }).observe(canvas);
    const loop = () => { if (this.dirty) this.draw(); requestAnimationFrame(loop); };
    requestAnimationFrame(loop);
  }

  push(t, values) {
    this.data.push([t, ...values]);
    const cutoff = this.anchored ? -Infinity : t - this.window * 1.5;
    let drop = 0;
    while (drop < this.data.length && this.data[drop][0] < cutoff) drop++;
    if (drop) this.data.splice(0, drop);
    if (this.data.length > this.maxPoints) this.data.splice(0, this.data.length - this.maxPoints);
    this.dirty = true;
  }

  clear() { this.data = []; this.marks = []; this.bands = []; this.dirty = true; }

  /** The latest value of series i, or null. */
  latest(i) {
    for (let k = this.data.length - 1; k >= 0; k--) {
      const v = this.data[k][i + 1];
      if (v !== null && Number.isFinite(v)) return v;
    }
    return null;
  }

  draw() {
    this.dirty = false;
    const c = this.canvas, ctx = c.getContext('2d');
    const dpr = window.devicePixelRatio || 1;
    const { width, height } = c.getBoundingClientRect();
    const pw = Math.max(1, Math.round(width * dpr)), ph = Math.max(1, Math.round(height * dpr));
    if (c.width !== pw || c.height !== ph) { c.width = pw; c.height = ph; }
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = '#ffffff';
    ctx.fillRect(0, 0, width, height);
    const left = 44, right = 6, top = 18, bottom = 16;
    const w = width - left - right, h = height - top - bottom;
    if (w <= 0 || h <= 0) return;
    const tLast = this.data.length ? this.data[this.data.length - 1][0] : 0;
    const span = this.anchored ? Math.max(this.window, tLast) : this.window;
    const tStart = this.anchored ? 0 : tLast - span;
    let lo = Infinity, hi = -Infinity;
    for (const row of this.data) {
      if (row[0] < tStart) continue;
      for (let i = 1; i < row.length; i++) {
        const v = row[i];
        if (v !== null && Number.isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      }
    }
    for (const b of this.bands) { lo = Math.min(lo, b.lo); hi = Math.max(hi, b.hi); }
    if (this.fixed.min !== undefined) lo = Math.min(lo, this.fixed.min);
    if (this.fixed.max !== undefined) hi = Math.max(hi, this.fixed.max);
    if (!Number.isFinite(lo)) { lo = -1; hi = 1; }
    if (hi - lo < 1e-6) { lo -= 0.5; hi += 0.5; }
    const pad = (hi - lo) * 0.08;
    lo -= pad; hi += pad;
    const X = (t) => left + ((t - tStart) / span) * w;
    const Y = (v) => top + (1 - (v - lo) / (hi - lo)) * h;
    // axes and ticks
    ctx.strokeStyle = '#e5e7eb';
    ctx.fillStyle = '#64748b';
    ctx.font = '11px system-ui, sans-serif';
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let k = 0; k <= 4; k++) {
      const v = lo + ((hi - lo) * k) / 4;
      const y = Y(v);
      ctx.moveTo(left, y); ctx.lineTo(left + w, y);
      ctx.fillText(v.toFixed(Math.abs(hi - lo) < 2 ? 2 : 1), 2, y + 4);
    }
    ctx.stroke();
    if (lo < 0 && hi > 0) {
      ctx.strokeStyle = '#94a3b8';
      ctx.beginPath(); ctx.moveTo(left, Y(0)); ctx.lineTo(left + w, Y(0)); ctx.stroke();
    }
    for (const b of this.bands) {
      ctx.fillStyle = 'rgba(34, 197, 94, 0.12)';
      ctx.fillRect(left, Y(b.hi), w, Y(b.lo) - Y(b.hi));
    }
    for (const m of this.marks) {
      if (m.t < tStart) continue;
      ctx.strokeStyle = '#a855f7';
      ctx.setLineDash([4, 3]);
      ctx.beginPath(); ctx.moveTo(X(m.t), top); ctx.lineTo(X(m.t), top + h); ctx.stroke();
      ctx.setLineDash([]);
      ctx.fillStyle = '#7e22ce';
      ctx.fillText(m.label, Math.min(X(m.t) + 3, left + w - 60), top + h - 4);
    }
    // series
    this.series.forEach((s, i) => {
      ctx.strokeStyle = s.color;
      ctx.lineWidth = s.width ?? 1.6;
      ctx.setLineDash(s.dash ?? []);
      ctx.beginPath();
      let pen = false;
      for (const row of this.data) {
        const v = row[i + 1];
        if (row[0] < tStart - 1 || v === null || !Number.isFinite(v)) { pen = false; continue; }
        if (pen) ctx.lineTo(X(row[0]), Y(v)); else { ctx.moveTo(X(row[0]), Y(v)); pen = true; }
      }
      ctx.stroke();
      ctx.setLineDash([]);
    });
    // legend
    let x = left;
    this.series.forEach((s, i) => {
      const val = this.latest(i);
      const text = `${s.label}${val === null ? '' : ` ${val.toFixed(2)}`}`;
      ctx.fillStyle = s.color;
      ctx.fillRect(x, 5, 10, 3);
      ctx.fillStyle = '#334155';
      ctx.fillText(text, x + 13, 11);
      x += ctx.measureText(text).width + 24;
    });
    ctx.fillStyle = '#64748b';
    if (this.anchored) ctx.fillText(`${span.toFixed(0)} s`, left + w - 24, top + h + 12);
    if (this.unit) ctx.fillText(this.unit, left + w - ctx.measureText(this.unit).width, 11);
  }
}
