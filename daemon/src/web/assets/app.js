// The ecmxfd dashboard (docs/web.md): one page, views chosen by the
// address's fragment, live data from the daemon's server-sent events.
// Hand-written, no framework and no build step: the daemon embeds this
// file as it is, and the page's policy allows no other script, no inline
// style and no other origin.
'use strict';

(() => {
  // ------------------------------------------------------------------
  // Small helpers
  // ------------------------------------------------------------------

  const $ = (selector, root = document) => root.querySelector(selector);
  const $$ = (selector, root = document) => Array.from(root.querySelectorAll(selector));

  // Sets what `attrs` says on `node`: properties for the few that are
  // properties (value, checked...), listeners for on*, attributes else.
  // Never a `style` attribute: the page's policy forbids inline style.
  function setAttrs(node, attrs) {
    for (const [key, value] of Object.entries(attrs || {})) {
      if (value === undefined || value === null || value === false) continue;
      if (key.startsWith('on') && typeof value === 'function') {
        node.addEventListener(key.slice(2), value);
      } else if (key === 'class') {
        node.setAttribute('class', value);
      } else if (['value', 'checked', 'disabled', 'hidden', 'selected'].includes(key)) {
        node[key] = value;
      } else {
        node.setAttribute(key, value === true ? '' : String(value));
      }
    }
  }

  function append(node, children) {
    for (const child of children.flat(Infinity)) {
      if (child === undefined || child === null || child === false) continue;
      node.append(child instanceof Node ? child : String(child));
    }
    return node;
  }

  // el('td', {'data-field': 'name'}, 'text', otherNode...)
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    setAttrs(node, attrs);
    return append(node, children);
  }

  const SVG_NS = 'http://www.w3.org/2000/svg';
  function svgEl(tag, attrs, ...children) {
    const node = document.createElementNS(SVG_NS, tag);
    setAttrs(node, attrs);
    return append(node, children);
  }

  // 0x%0Nx of a number (the daemon's identities fit in 32 bits).
  function hex(n, digits) {
    const v = Number(n);
    if (!Number.isFinite(v)) return String(n);
    return '0x' + Math.trunc(v).toString(16).padStart(digits, '0');
  }

  // A value as text: numbers and booleans as JSON writes them.
  function valueText(v) {
    if (v === undefined || v === null) return '—';
    if (typeof v === 'object') return JSON.stringify(v);
    return String(v);
  }

  const seconds = (ns) => (Number(ns) / 1e9).toFixed(3);
  const grouped = (n) => (typeof n === 'number' ? n.toLocaleString('en-US') : valueText(n));

  // JSON with integers past 2^53 kept as their exact digits (a string),
  // where the browser tells the number's source text: a u64 counter, a
  // frame time or an UNSIGNED64 value must not be rounded on the way.
  function keepBigIntegers(key, value, context) {
    if (typeof value === 'number' && Number.isInteger(value) && !Number.isSafeInteger(value) &&
        context && typeof context.source === 'string') {
      return context.source;
    }
    return value;
  }
  const parseJson = (text) => JSON.parse(text, keepBigIntegers);

  // What an operator typed, as the JSON text of a value: a number when it
  // reads as one (decimal digits verbatim, so big integers stay exact),
  // true/false, else the text itself.
  function typedJson(text) {
    const t = text.trim();
    if (t === 'true' || t === 'false') return t;
    if (/^[+-]?\d+$/.test(t)) return t.replace(/^\+/, '').replace(/^(-?)0+(?=\d)/, '$1');
    if (/^0[xX][0-9a-fA-F]+$/.test(t)) return BigInt(t).toString();
    if (t !== '' && Number.isFinite(Number(t)) && /^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$/.test(t)) {
      return JSON.stringify(Number(t));
    }
    return JSON.stringify(text);
  }

  // ------------------------------------------------------------------
  // The message area: errors and successes of any action
  // ------------------------------------------------------------------

  // `source` says who showed the message, so a poll that works again
  // clears its own error and never someone else's.
  const message = { source: null, timer: 0 };

  function say(text, kind = 'error', source = 'action') {
    const box = $('#message');
    clearTimeout(message.timer);
    box.textContent = text;
    box.className = kind;
    message.source = source;
    // Successes fade after a while; errors stay until read (or replaced).
    if (kind === 'ok') message.timer = setTimeout(() => unsay(source), 10000);
  }

  function unsay(source) {
    if (message.source !== source) return;
    const box = $('#message');
    box.textContent = '';
    box.className = '';
    message.source = null;
  }

  // ------------------------------------------------------------------
  // The daemon's HTTP API
  // ------------------------------------------------------------------

  // GET (or POST with `body`, a JSON value, or `json`, its text); the
  // answer's JSON, or null when it failed (and #message says why: the
  // daemon's {"error"} verbatim, else the status). Never throws.
  let lastStatus = 0; // the HTTP status of the last answer (0: none)

  async function api(path, opts = {}) {
    const init = { method: 'GET', credentials: 'same-origin', headers: { Accept: 'application/json' } };
    if (opts.body !== undefined || opts.json !== undefined || opts.method === 'POST') {
      init.method = 'POST';
      init.headers['Content-Type'] = 'application/json';
      init.body = opts.json !== undefined ? opts.json : JSON.stringify(opts.body === undefined ? {} : opts.body);
    }
    // Reads report as themselves (a poll clears its own error when it
    // works again); writes as actions.
    const source = opts.source || (init.method === 'GET' ? 'GET ' + path : 'action');
    let response;
    lastStatus = 0;
    try {
      response = await fetch(path, init);
      lastStatus = response.status;
    } catch (e) {
      say(`${path}: the daemon did not answer (${e.message})`, 'error', source);
      return null;
    }
    let data = null;
    try {
      const text = await response.text();
      data = text ? parseJson(text) : {};
    } catch (e) {
      data = null;
    }
    if (!response.ok) {
      const why = data && typeof data.error === 'string' ? data.error
        : `${path}: ${response.status} ${response.statusText}`.trim();
      say(why, 'error', source);
      return null;
    }
    if (data === null) {
      say(`${path}: the answer is not JSON`, 'error', source);
      return null;
    }
    unsay(source);
    return data;
  }

  // ------------------------------------------------------------------
  // Views: a context per open view, whose timers end when it closes
  // ------------------------------------------------------------------

  let view = null; // { name, alive, timers, onOverview, onEvent, onResize, cleanup }

  function openContext(name) {
    return { name, alive: true, timers: new Set(), onOverview: null, onEvent: null, onResize: null, cleanup: [] };
  }

  function closeContext(ctx) {
    if (!ctx) return;
    ctx.alive = false;
    for (const t of ctx.timers) clearTimeout(t);
    ctx.timers.clear();
    for (const f of ctx.cleanup) {
      try { f(); } catch (e) { /* a cleanup that fails leaves nothing to undo */ }
    }
  }

  // setTimeout bound to the view: cleared when the view closes.
  function later(ctx, ms, fn) {
    if (!ctx.alive) return;
    const t = setTimeout(() => {
      ctx.timers.delete(t);
      if (ctx.alive) fn();
    }, ms);
    ctx.timers.add(t);
  }

  const sleep = (ctx, ms) => new Promise((resolve) => later(ctx, ms, resolve));

  // Runs `fn` now and then every `ms` while the view is open: the next run
  // starts `ms` after the previous one started, and never before it ended
  // (a slow daemon is not asked again and again). `fn` returning false
  // stops it.
  function every(ctx, ms, fn) {
    const run = async () => {
      if (!ctx.alive) return;
      const started = performance.now();
      let again = true;
      try {
        again = (await fn()) !== false;
      } catch (e) {
        say(`the page failed: ${e.message}`, 'error', 'page');
      }
      if (again) later(ctx, Math.max(0, ms - (performance.now() - started)), run);
    };
    run();
  }

  const VIEWS = {
    overview: viewOverview,
    topology: viewTopology,
    slaves: viewSlaves,
    slave: viewSlave,
    plots: viewPlots,
    events: viewEvents,
    axes: viewAxes,
    config: viewConfig,
  };

  const TITLES = {
    overview: 'Overview', topology: 'Topology', slaves: 'Slaves', slave: 'Slave',
    plots: 'Plots', events: 'Events', axes: 'Axes', config: 'Configuration',
  };

  function route() {
    let match = /^#\/([a-z]+)(?:\/(\d+))?\/?$/.exec(location.hash);
    if (!match || !VIEWS[match[1]] || (match[1] === 'slave') !== (match[2] !== undefined)) {
      // Anything else is the overview, under its own address.
      history.replaceState(null, '', '#/overview');
      match = [null, 'overview', undefined];
    }
    const [, name, arg] = match;
    closeContext(view);
    view = openContext(name);
    const root = el('section', { id: 'view-' + name, class: 'view' });
    $('#view').replaceChildren(root);
    for (const a of $$('#nav a')) {
      const active = a.dataset.view === name || (name === 'slave' && a.dataset.view === 'slaves');
      if (active) a.setAttribute('aria-current', 'page');
      else a.removeAttribute('aria-current');
    }
    document.title = `${TITLES[name]}${arg !== undefined ? ' ' + arg : ''} · ecmxfd`;
    if (who.role === 'none') {
      // Visitors without a role may see nothing: asking would only be refused.
      root.append(el('h1', null, TITLES[name]), el('p', { class: 'notice' }, 'Log in (top right) to see the network.'));
      return;
    }
    try {
      VIEWS[name](view, root, arg);
    } catch (e) {
      say(`the ${name} view failed: ${e.message}`, 'error', 'page');
    }
  }

  // A table in a container that scrolls sideways when it is too wide, so
  // the page itself never does.
  const tableWrap = (table) => el('div', { class: 'table-wrap' }, table);

  function headRow(...names) {
    return el('thead', null, el('tr', null, names.map((n) => el('th', { scope: 'col' }, n))));
  }

  function stateBadge(state) {
    const s = state === undefined || state === null ? '—' : String(state);
    return el('span', { class: 'state', 'data-state': s }, s);
  }

  // ------------------------------------------------------------------
  // Who this browser is; logging in and out
  // ------------------------------------------------------------------

  let who = { name: 'anonymous', role: 'observer', login: false };

  async function refreshWho() {
    const w = await api('/api/whoami');
    if (!w) return false;
    const before = who.role;
    who = { name: String(w.name || 'anonymous'), role: String(w.role || 'none'), login: !!w.login };
    const loggedIn = who.name !== 'anonymous';
    $('#whoami').textContent = `${who.name} (${who.role})`;
    $('#login-form').hidden = !who.login || loggedIn;
    $('#logout-button').hidden = !loggedIn;
    if (who.role === 'none') closeLive();
    else openLive();
    return before !== who.role;
  }

  async function login(event) {
    event.preventDefault();
    const input = $('#login-token');
    const token = input.value;
    if (!token.trim()) {
      say('type an API token to log in');
      return;
    }
    const button = $('#login-button');
    button.disabled = true;
    const answer = await api('/api/login', { body: { token } });
    button.disabled = false;
    if (!answer) return;
    input.value = '';
    const changed = await refreshWho();
    say(`logged in as ${answer.name} (${answer.role})`, 'ok');
    if (changed) route();
  }

  async function logout() {
    const answer = await api('/api/logout', { method: 'POST' });
    if (!answer) return;
    const changed = await refreshWho();
    say('logged out', 'ok');
    if (changed) route();
  }

  // ------------------------------------------------------------------
  // The live feed: one EventSource for the whole page
  // ------------------------------------------------------------------

  const live = {
    source: null,
    overview: null,
    samples: [], // the last 5 minutes of overviews, for the charts
    trendAsked: false, // the daemon's past seconds were asked for
    events: [], // the daemon's events, oldest first
    retry: 0,
  };
  const SAMPLE_SPAN_NS = 300e9;
  const EVENTS_KEPT = 2000;

  function setLiveStatus(state, text) {
    const s = $('#live-status');
    s.dataset.live = state;
    s.textContent = text;
  }

  function openLive() {
    if (live.source) return;
    const es = new EventSource('/api/live');
    live.source = es;
    setLiveStatus('connecting', 'connecting');
    let dropped = false;
    es.addEventListener('open', () => {
      setLiveStatus('live', 'live');
      // Back after a cut: the daemon may have restarted, and its sessions
      // with it; show who this browser is now.
      if (dropped) {
        dropped = false;
        refreshWho().then((changed) => { if (changed) route(); });
      }
    });
    es.addEventListener('error', () => {
      dropped = true;
      if (es.readyState === EventSource.CLOSED) {
        // Refused (not just cut): the browser gives up, so try again
        // later, as who we are now.
        setLiveStatus('down', 'offline');
        if (live.source === es) live.source = null;
        clearTimeout(live.retry);
        live.retry = setTimeout(() => refreshWho().then((changed) => { if (changed) route(); }), 5000);
      } else {
        // EventSource reconnects by itself.
        setLiveStatus('down', 'reconnecting');
      }
    });
    es.addEventListener('overview', (e) => {
      let ov;
      try { ov = parseJson(e.data); } catch (err) { return; }
      takeOverview(ov);
    });
    es.addEventListener('event', (e) => {
      let ev;
      try { ev = parseJson(e.data); } catch (err) { return; }
      takeEvent(ev);
    });
  }

  function closeLive() {
    if (live.source) live.source.close();
    live.source = null;
    setLiveStatus('down', 'offline');
  }

  function takeOverview(ov) {
    if (!ov || typeof ov !== 'object' || !ov.slaves) return; // the feed's "{}" before the first summary
    const previous = live.overview;
    live.overview = ov;
    const t = Number(ov.time_ns);
    const last = live.samples[live.samples.length - 1];
    if (last && t < last.t) live.samples = []; // the daemon restarted: its clock too
    if (!last || t > last.t) {
      const c = ov.counters || {};
      live.samples.push({
        t,
        exchanges: Number(c.exchanges),
        alarms: Number(c.fifo_alarms),
        rx: Number(ov.rx_fifo),
        tx: Number(ov.tx_fifo),
      });
      while (live.samples.length && live.samples[0].t < t - SAMPLE_SPAN_NS) live.samples.shift();
    }
    if (!live.trendAsked) {
      live.trendAsked = true;
      loadTrend();
    }
    if (view && view.onOverview) view.onOverview(ov, previous);
  }

  // The charts open with the daemon's last minutes (one point a second),
  // put before what the feed brought since.
  async function loadTrend() {
    const d = await api('/api/trend');
    if (!d || !Array.isArray(d.trend)) return;
    const first = live.samples.length ? live.samples[0].t : Infinity;
    const past = d.trend
      .map((p) => ({ t: Number(p.time_ns), exchanges: Number(p.exchanges), alarms: Number(p.fifo_alarms), rx: Number(p.rx_fifo), tx: Number(p.tx_fifo) }))
      .filter((p) => p.t < first);
    live.samples = past.concat(live.samples);
  }

  const eventKey = (e) => `${e.time_ns}|${e.kind}|${e.slave}|${e.text}`;

  function takeEvent(ev) {
    if (!ev || typeof ev !== 'object') return;
    live.events.push(ev);
    if (live.events.length > EVENTS_KEPT) live.events.splice(0, live.events.length - EVENTS_KEPT);
    if (view && view.onEvent) view.onEvent(ev);
  }

  // ------------------------------------------------------------------
  // Charts on canvas (the overview's and the plots'), devicePixelRatio aware
  // ------------------------------------------------------------------

  const PALETTE = ['#1f6fb4', '#d62728', '#2a9d3a', '#e07b00', '#8c4fbf', '#8c564b', '#d6439c', '#138f9e',
    '#6b6b6b', '#a3a300'];

  function cssVar(name, fallback) {
    const v = getComputedStyle(document.documentElement).getPropertyValue(name).trim();
    return v || fallback;
  }

  // Tick values at 1, 2 or 5 times a power of ten, about `count` of them.
  function niceTicks(min, max, count) {
    const span = max - min;
    if (!(span > 0) || !Number.isFinite(span)) return [min];
    const raw = span / Math.max(1, count);
    const power = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) || 10 * power;
    const ticks = [];
    for (let v = Math.ceil(min / step) * step; v <= max + step * 1e-9; v += step) {
      ticks.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    }
    return ticks;
  }

  function tickText(v, step) {
    const decimals = step >= 1 ? 0 : Math.min(6, Math.ceil(-Math.log10(step)));
    const abs = Math.abs(v);
    if (abs >= 1e6 || (abs > 0 && abs < 1e-4)) return v.toExponential(1);
    return v.toFixed(decimals);
  }

  // The first index whose x is >= `x` (xs ascending).
  function lowerBound(xs, x) {
    let lo = 0;
    let hi = xs.length;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (xs[mid] < x) lo = mid + 1;
      else hi = mid;
    }
    return lo;
  }

  // Draws `series` ([{xs, ys, color}], xs ascending) over [xmin, xmax];
  // y autoscaled over what is visible unless `ymin`/`ymax` are given.
  // Returns the geometry, for mapping the mouse back to x.
  function drawChart(canvas, opt) {
    const dpr = window.devicePixelRatio || 1;
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    if (!w || !h) return null;
    const pw = Math.round(w * dpr);
    const ph = Math.round(h * dpr);
    if (canvas.width !== pw || canvas.height !== ph) {
      canvas.width = pw;
      canvas.height = ph;
    }
    const g = canvas.getContext('2d');
    g.setTransform(dpr, 0, 0, dpr, 0, 0);
    g.clearRect(0, 0, w, h);
    const fg = cssVar('--chart-text', '#333');
    const grid = cssVar('--chart-grid', '#ddd');
    const font = `11px ${cssVar('--font', 'system-ui, sans-serif')}`;
    const box = { left: opt.yLabel ? 62 : 50, right: 10, top: 8, bottom: opt.xLabel ? 34 : 20 };
    const width = Math.max(10, w - box.left - box.right);
    const height = Math.max(10, h - box.top - box.bottom);
    const { xmin, xmax } = opt;
    const xspan = xmax - xmin || 1;

    // The y range: what the visible points span, with a margin.
    let ymin = Infinity;
    let ymax = -Infinity;
    const ranges = opt.series.map((s) => {
      const i0 = Math.max(0, lowerBound(s.xs, xmin) - 1);
      const i1 = Math.min(s.xs.length, lowerBound(s.xs, xmax) + 1);
      for (let i = i0; i < i1; i++) {
        const y = s.ys[i];
        if (Number.isFinite(y)) {
          if (y < ymin) ymin = y;
          if (y > ymax) ymax = y;
        }
      }
      return [i0, i1];
    });
    if (opt.zeroBased && ymin > 0) ymin = 0;
    if (!Number.isFinite(ymin)) {
      ymin = 0;
      ymax = 1;
    }
    if (opt.ymin !== undefined) ymin = opt.ymin;
    if (opt.ymax !== undefined) ymax = Math.max(opt.ymax, ymax);
    if (ymax === ymin) {
      const d = Math.abs(ymax) * 0.1 || 1;
      ymax += d;
      if (!(opt.zeroBased && ymin === 0)) ymin -= d;
    } else if (opt.ymax === undefined) {
      const pad = (ymax - ymin) * 0.05;
      ymax += pad;
      if (!(opt.zeroBased && ymin === 0)) ymin -= pad;
    }
    const X = (x) => box.left + ((x - xmin) / xspan) * width;
    const Y = (y) => box.top + height - ((y - ymin) / (ymax - ymin)) * height;

    // Grid, ticks and labels.
    g.font = font;
    g.lineWidth = 1;
    g.strokeStyle = grid;
    g.fillStyle = fg;
    const yt = niceTicks(ymin, ymax, Math.max(2, Math.floor(height / 28)));
    const ystep = yt.length > 1 ? yt[1] - yt[0] : 1;
    g.textAlign = 'right';
    g.textBaseline = 'middle';
    for (const v of yt) {
      const y = Math.round(Y(v)) + 0.5;
      g.beginPath();
      g.moveTo(box.left, y);
      g.lineTo(box.left + width, y);
      g.stroke();
      g.fillText(opt.yFormat ? opt.yFormat(v) : tickText(v, ystep), box.left - 5, y);
    }
    const xt = niceTicks(xmin, xmax, Math.max(2, Math.floor(width / 80)));
    const xstep = xt.length > 1 ? xt[1] - xt[0] : 1;
    g.textAlign = 'center';
    g.textBaseline = 'top';
    for (const v of xt) {
      const x = Math.round(X(v)) + 0.5;
      g.beginPath();
      g.moveTo(x, box.top);
      g.lineTo(x, box.top + height);
      g.stroke();
      const label = opt.xFormat ? opt.xFormat(v) : tickText(v, xstep);
      const half = g.measureText(label).width / 2;
      g.fillText(label, Math.min(w - half - 1, Math.max(half + 1, x)), box.top + height + 4);
    }
    g.strokeStyle = fg;
    g.strokeRect(box.left + 0.5, box.top + 0.5, width - 1, height - 1);
    if (opt.xLabel) g.fillText(opt.xLabel, box.left + width / 2, box.top + height + 19);
    if (opt.yLabel) {
      g.save();
      g.translate(12, box.top + height / 2);
      g.rotate(-Math.PI / 2);
      g.textBaseline = 'middle';
      g.fillText(opt.yLabel, 0, 0);
      g.restore();
    }

    // The lines, clipped to the plot area; many points in one pixel
    // column are drawn as that column's min..max (20000 points stay fast).
    g.save();
    g.beginPath();
    g.rect(box.left, box.top, width, height);
    g.clip();
    g.lineWidth = 1.5;
    g.lineJoin = 'round';
    opt.series.forEach((s, k) => {
      const [i0, i1] = ranges[k];
      g.strokeStyle = s.color;
      g.beginPath();
      let column = null;
      let lo = 0;
      let hi = 0;
      let lastY = 0;
      let drawing = false;
      const flush = () => {
        if (drawing && lo !== hi) {
          g.lineTo(column, lo);
          g.lineTo(column, hi);
          g.lineTo(column, lastY);
        }
      };
      for (let i = i0; i < i1; i++) {
        const yv = s.ys[i];
        if (!Number.isFinite(yv)) {
          flush();
          drawing = false;
          continue;
        }
        const px = Math.round(X(s.xs[i]));
        const py = Y(yv);
        if (drawing && px === column) {
          if (py < lo) lo = py;
          if (py > hi) hi = py;
          lastY = py;
          continue;
        }
        flush();
        if (drawing) g.lineTo(px, py);
        else g.moveTo(px, py);
        drawing = true;
        column = px;
        lo = hi = lastY = py;
      }
      flush();
      g.stroke();
    });
    // A selection being dragged (plots' zoom).
    if (opt.selection) {
      const [a, b] = opt.selection;
      g.fillStyle = 'rgba(31, 111, 180, 0.15)';
      g.fillRect(Math.min(a, b), box.top, Math.abs(b - a), height);
    }
    g.restore();
    return { left: box.left, width, xmin, xmax, toX: (px) => xmin + ((px - box.left) / width) * xspan };
  }

  // ------------------------------------------------------------------
  // 1. Overview
  // ------------------------------------------------------------------

  function viewOverview(ctx, root) {
    const card = (label, id, extra) => el('div', { class: 'card' },
      el('div', { class: 'card-label' }, label), el('div', { id, class: 'card-value' }, extra || ''));
    const chart = (id, title, now) => el('figure', { class: 'chart' },
      el('figcaption', null, el('span', null, title), now || el('span', { class: 'chart-now', id: id + '-now' })),
      el('canvas', { id, role: 'img', 'aria-label': title }));
    // The FIFO chart's two lines, named in their colours.
    const swatch = (color) => {
      const s = el('span', { class: 'swatch' });
      s.style.backgroundColor = color; // CSSOM, which the page's policy allows
      return s;
    };
    const fifoNow = el('span', { class: 'chart-now', id: 'chart-fifo-now' },
      swatch(PALETTE[0]), ' ', el('span', { id: 'fifo-rx' }, 'Rx'), ' ', swatch(PALETTE[3]), ' ', el('span', { id: 'fifo-tx' }, 'Tx'));
    root.append(
      el('h1', null, 'Overview'),
      el('section', { id: 'summary', 'data-healthy': 'false', 'aria-live': 'polite' },
        el('div', { class: 'summary-head' },
          el('span', { id: 'summary-health' }),
          el('span', { class: 'summary-detail' }, 'Network ', el('span', { id: 'summary-state' })),
          el('span', { class: 'summary-detail' }, 'Engine ', el('span', { id: 'summary-phase' }))),
        el('div', { class: 'cards' },
          card('Slaves', 'summary-slaves'),
          card('Lost slaves', 'summary-lost'),
          card('Axes', 'summary-axes'),
          card('Process data', 'summary-flowing'),
          card('Link health', 'summary-link'),
          card('Cycle', 'summary-cycle'))),
      el('h2', null, 'Problems'),
      el('ul', { id: 'problems' }),
      el('p', { id: 'problems-none', class: 'muted', hidden: true }, 'None: the network does what its configuration asks.'),
      el('h2', null, 'Last 5 minutes'),
      el('div', { class: 'charts' },
        chart('chart-exchanges', 'Link use: share of the SPI link'),
        chart('chart-fifo', 'RxFIFO / TxFIFO level', fifoNow),
        chart('chart-alarms', 'FIFO alarms')),
      el('h2', null, 'Counters'),
      el('div', { class: 'table-wrap narrow' }, el('table', { id: 'counters-table', class: 'kv' }, el('tbody'))));

    const fill = (ov) => {
      const slaves = ov.slaves || {};
      const axes = ov.axes || {};
      const lost = Array.isArray(slaves.lost) ? slaves.lost : [];
      $('#summary').dataset.healthy = String(!!ov.healthy);
      $('#summary-health').textContent = ov.healthy ? 'Healthy' : 'Problems';
      $('#summary-state').textContent = `${ov.state} (target ${ov.target_state})`;
      $('#summary-phase').textContent = valueText(ov.phase);
      $('#summary-slaves').textContent = `${slaves.op} / ${slaves.expected} slaves in OP`;
      $('#summary-lost').textContent = lost.length ? `lost: ${lost.join(', ')}` : '';
      $('#summary-axes').textContent = `${axes.enabled} / ${axes.total} axes enabled`;
      $('#summary-flowing').textContent = ov.flowing ? 'process data flowing' : 'no process data';
      $('#summary-flowing').dataset.flowing = String(!!ov.flowing);
      $('#summary-link').textContent = valueText(ov.health);
      $('#summary-cycle').textContent = ov.cycle_us !== undefined ? `${ov.cycle_us} µs` : '—';
      const problems = Array.isArray(ov.problems) ? ov.problems.map(String) : [];
      const list = $('#problems');
      const shown = $$('li', list).map((li) => li.textContent);
      if (shown.join('\n') !== problems.join('\n') || shown.length !== problems.length) {
        list.replaceChildren(...problems.map((p) => el('li', null, p)));
      }
      $('#problems-none').hidden = problems.length > 0;
      const counters = ov.counters || {};
      const body = $('#counters-table tbody');
      for (const [name, value] of Object.entries(counters)) {
        let row = $(`tr[data-counter="${CSS.escape(name)}"]`, body);
        if (!row) {
          row = el('tr', { 'data-counter': name }, el('th', { scope: 'row' }, name.replace(/_/g, ' ')), el('td'));
          body.append(row);
        }
        row.cells[1].textContent = grouped(value);
      }
    };

    const draw = () => {
      const s = live.samples;
      if (!s.length) return;
      const end = s[s.length - 1].t;
      const x = (t) => (t - end) / 1e9;
      const rate = { xs: [], ys: [] };
      const alarms = { xs: [], ys: [] };
      for (let i = 1; i < s.length; i++) {
        const dt = (s[i].t - s[i - 1].t) / 1e9;
        const d = s[i].exchanges - s[i - 1].exchanges;
        if (dt > 0 && d >= 0) {
          rate.xs.push(x(s[i].t));
          rate.ys.push(d / dt);
        }
        const a = s[i].alarms - s[i - 1].alarms;
        alarms.xs.push(x(s[i].t));
        alarms.ys.push(a >= 0 ? a : NaN);
      }
      const xs = s.map((p) => x(p.t));
      const range = { xmin: -300, xmax: 0, zeroBased: true, xFormat: (v) => (v === 0 ? 'now' : `${v} s`) };
      // Each exchange holds the link for one packet's time (measured at
      // bring-up): the share in use. Before bring-up, exchanges per second.
      const packet = Number(live.overview && live.overview.packet_ns) / 1e9 || 0;
      const use = packet ? { xs: rate.xs, ys: rate.ys.map((r) => Math.min(100, r * packet * 100)) } : rate;
      drawChart($('#chart-exchanges'), { ...range, series: [{ ...use, color: PALETTE[0] }] });
      drawChart($('#chart-fifo'), {
        ...range,
        series: [{ xs, ys: s.map((p) => p.rx), color: PALETTE[0] }, { xs, ys: s.map((p) => p.tx), color: PALETTE[3] }],
      });
      drawChart($('#chart-alarms'), { ...range, series: [{ ...alarms, color: PALETTE[1] }] });
      const last = s[s.length - 1];
      const perSecond = rate.ys.length ? Math.round(rate.ys[rate.ys.length - 1]) : null;
      $('#chart-exchanges-now').textContent =
        perSecond === null ? '' : packet ? `${Math.round(use.ys[use.ys.length - 1])} % (${perSecond} exchanges/s)` : `${perSecond} exchanges/s`;
      $('#fifo-rx').textContent = `Rx ${valueText(last.rx)}`;
      $('#fifo-tx').textContent = `Tx ${valueText(last.tx)}`;
      $('#chart-alarms-now').textContent = `${grouped(last.alarms)} in all`;
    };

    ctx.onOverview = (ov) => {
      fill(ov);
      draw();
    };
    ctx.onResize = draw;
    if (live.overview) {
      fill(live.overview);
      draw();
    } else {
      // Before the feed's first message: ask once.
      api('/api/overview').then((ov) => { if (ov && ctx.alive && !live.overview) takeOverview(ov); });
    }
  }

  // ------------------------------------------------------------------
  // 2. Topology
  // ------------------------------------------------------------------

  function viewTopology(ctx, root) {
    const wrap = el('div', { class: 'svg-wrap' });
    const legend = el('ul', { class: 'legend', id: 'topology-legend' },
      ['OP', 'SAFEOP', 'PREOP', 'INIT', 'BOOT'].map((s) => el('li', null, stateBadge(s))),
      el('li', null, el('span', { class: 'state', 'data-state': 'LOST' }, 'lost')));
    root.append(el('h1', null, 'Topology'),
      el('p', { class: 'muted' }, 'The line of slaves as the master sees it; a lost slave stays where it was. Select a slave to open its page.'),
      wrap, legend);
    let slaves = null;
    let drawnKey = '';
    let drawnWidth = 0;
    let busy = false;
    let again = false;

    const draw = () => {
      if (!slaves) return;
      const width = Math.max(320, wrap.clientWidth || 800);
      const key = JSON.stringify(slaves);
      if (key === drawnKey && width === drawnWidth) return;
      drawnKey = key;
      drawnWidth = width;
      const boxW = 160;
      const boxH = 66;
      const gapX = 34;
      const gapY = 44;
      const margin = 12;
      const perRow = Math.max(1, Math.floor((width - 2 * margin + gapX) / (boxW + gapX)));
      const count = slaves.length + 1;
      const rows = Math.ceil(count / perRow);
      const used = Math.min(count, perRow) * (boxW + gapX) - gapX + 2 * margin;
      const height = rows * (boxH + gapY) - gapY + 2 * margin;
      const at = (i) => ({
        x: margin + (i % perRow) * (boxW + gapX),
        y: margin + Math.floor(i / perRow) * (boxH + gapY),
      });
      const svg = svgEl('svg', {
        id: 'topology', width: used, height, viewBox: `0 0 ${used} ${height}`, role: 'img',
        'aria-label': `the master and ${slaves.length} slave(s) in a line`,
      });
      // The cables first, under the boxes.
      for (let i = 0; i + 1 < count; i++) {
        const a = at(i);
        const b = at(i + 1);
        const lostLink = slaves[i] && slaves[i].lost;
        const cls = lostLink ? 'link lost' : 'link';
        if (a.y === b.y) {
          svg.append(svgEl('line', { class: cls, x1: a.x + boxW, y1: a.y + boxH / 2, x2: b.x, y2: b.y + boxH / 2 }));
        } else {
          const midY = a.y + boxH + gapY / 2;
          const points = [[a.x + boxW / 2, a.y + boxH], [a.x + boxW / 2, midY], [b.x + boxW / 2, midY], [b.x + boxW / 2, b.y]];
          svg.append(svgEl('polyline', { class: cls, points: points.map((p) => p.join(',')).join(' ') }));
        }
      }
      const fit = (text, max) => (text.length > max ? text.slice(0, max - 1) + '…' : text);
      const m = at(0);
      svg.append(svgEl('g', { class: 'master', transform: `translate(${m.x},${m.y})` },
        svgEl('rect', { width: boxW, height: boxH, rx: 6 }),
        svgEl('text', { x: boxW / 2, y: 28, class: 'title' }, 'ecmxfd'),
        svgEl('text', { x: boxW / 2, y: 48 }, 'ECM-XF')));
      slaves.forEach((s, k) => {
        const p = at(k + 1);
        const state = s.lost ? 'LOST' : String(s.state);
        const name = String(s.name || '');
        const g = svgEl('g', {
          class: 'slave', 'data-position': s.position, 'data-state': state, 'data-lost': String(!!s.lost),
          transform: `translate(${p.x},${p.y})`,
        },
        svgEl('a', { href: `#/slave/${s.position}`, 'aria-label': `slave ${s.position}: ${name}, ${state}` },
          svgEl('title', null, `slave ${s.position}: ${name} — ${s.lost ? 'lost' : state}`),
          svgEl('rect', { width: boxW, height: boxH, rx: 6 }),
          svgEl('text', { x: boxW / 2, y: 27, class: 'title' }, fit(`${s.position}: ${name}`, 24)),
          s.lost ? svgEl('text', { x: boxW / 2, y: 49, class: 'lost-label' }, 'lost')
            : svgEl('text', { x: boxW / 2, y: 49, class: 'state-label' }, fit(String(s.state), 24))));
        svg.append(g);
      });
      wrap.replaceChildren(svg);
      // Shorten what does not fit its box (the full text is in the title).
      for (const t of svg.querySelectorAll('g.slave text.title')) {
        let text = t.textContent;
        while (text.length > 4 && t.getComputedTextLength() > boxW - 12) {
          text = text.slice(0, -1);
          t.textContent = text.trimEnd() + '…';
        }
      }
    };

    const refresh = async () => {
      // One request at a time; a change asked meanwhile runs right after.
      if (busy) {
        again = true;
        return;
      }
      busy = true;
      const d = await api('/api/topology');
      busy = false;
      if (!ctx.alive) return;
      if (d && Array.isArray(d.slaves)) {
        slaves = d.slaves;
        draw();
      }
      if (again) {
        again = false;
        refresh();
      }
    };

    ctx.onOverview = (ov, previous) => {
      const lostNow = JSON.stringify((ov.slaves || {}).lost || []);
      const lostBefore = previous ? JSON.stringify((previous.slaves || {}).lost || []) : lostNow;
      if (lostNow !== lostBefore) refresh();
    };
    ctx.onResize = draw;
    every(ctx, 1000, refresh);
  }

  // ------------------------------------------------------------------
  // 3. Slaves
  // ------------------------------------------------------------------

  function dcText(dc) {
    if (!dc) return '—';
    if (dc.active) return 'active';
    if (dc.supported) return 'supported';
    return 'no';
  }

  // The ESC's error counters: their sum, each port's in the tooltip
  // (invalid frames / RX errors / forwarded), as `ecmxfctl crc` lists them.
  function errorsCell(e) {
    if (!e) return el('td', { 'data-field': 'errors', class: 'num muted', title: 'the slave did not answer the read' }, '—');
    const ports = (e.ports || []).map((p, n) => `port ${n}: ${p.join('/')}`).join(', ');
    const title = `invalid/RX/forwarded: ${ports}; processing unit ${e.processing_unit}, PDI ${e.pdi}`;
    return el('td', { 'data-field': 'errors', 'data-value': e.total, class: e.total ? 'num bad' : 'num', title }, grouped(e.total));
  }

  function viewSlaves(ctx, root) {
    const table = el('table', { id: 'slaves-table' },
      headRow('#', 'Name', 'State', 'Vendor', 'Product', 'Revision', 'AL status', 'Errors', 'Out bytes', 'In bytes', 'DC', 'Configuration'),
      el('tbody'));
    const notes = el('div', { id: 'slaves-notes' });
    root.append(el('h1', null, 'Slaves'),
      el('p', { class: 'muted' }, 'Read from the chip: states, AL status and clocks as the slaves report them now.'),
      tableWrap(table), notes);
    let shown = '';

    const render = (d) => {
      const key = JSON.stringify(d);
      if (key === shown) return;
      shown = key;
      const rows = (d.slaves || []).map((s) => {
        const code = Number(s.al_status_code);
        return el('tr', { 'data-position': s.position },
          el('td', { 'data-field': 'position', class: 'num' }, s.position),
          el('td', { 'data-field': 'name', class: 'name' }, el('a', { href: `#/slave/${s.position}` }, s.name)),
          el('td', { 'data-field': 'state' }, stateBadge(s.state)),
          el('td', { 'data-field': 'vendor_id', 'data-value': s.vendor_id, class: 'mono' }, hex(s.vendor_id, 8)),
          el('td', { 'data-field': 'product_code', 'data-value': s.product_code, class: 'mono' }, hex(s.product_code, 8)),
          el('td', { 'data-field': 'revision', 'data-value': s.revision, class: 'mono' }, hex(s.revision, 8)),
          el('td', { 'data-field': 'al_status', 'data-value': s.al_status_code, class: code ? 'al bad' : 'al' },
            `${hex(code, 4)} ${s.al_status_text || ''}`.trim()),
          errorsCell(s.errors),
          el('td', { 'data-field': 'output_bytes', class: 'num' }, s.output_bytes),
          el('td', { 'data-field': 'input_bytes', class: 'num' }, s.input_bytes),
          el('td', { 'data-field': 'dc' }, dcText(s.dc)),
          el('td', { 'data-field': 'mismatch', class: s.mismatch ? 'bad wrap' : 'muted wrap' },
            s.mismatch ? s.mismatch : (s.expected ? 'as configured' : 'not configured')));
      });
      $('tbody', table).replaceChildren(...rows);
      const lost = d.lost || [];
      const missing = d.missing || [];
      notes.replaceChildren(
        el('p', { id: 'slaves-lost', class: lost.length ? 'bad' : 'muted' },
          lost.length ? `Lost (the network had them and has no more): ${lost.join(', ')}` : 'No slave lost.'),
        el('p', { id: 'slaves-missing', class: missing.length ? 'bad' : 'muted' },
          missing.length ? `Configured but missing: ${missing.join(', ')}` : 'No configured slave missing.'),
        el('p', { id: 'slaves-matches', class: d.matches_config ? 'good' : 'bad' },
          d.matches_config ? 'The network is what the configuration expects.'
            : lost.length ? 'The network is not the one it was brought up as: it lost slaves.'
              : 'The network differs from the configuration.'));
    };

    every(ctx, 2000, async () => {
      const d = await api('/api/slaves');
      if (d && ctx.alive) render(d);
    });
  }

  // ------------------------------------------------------------------
  // 4. One slave
  // ------------------------------------------------------------------

  // Any JSON as nested key/value tables.
  function kvTable(value, id) {
    const cell = (v) => {
      if (v !== null && typeof v === 'object') {
        if (Array.isArray(v) && v.length === 0) return el('span', { class: 'muted' }, 'none');
        return kvTable(v);
      }
      return valueText(v);
    };
    const entries = Array.isArray(value) ? value.map((v, i) => [String(i), v]) : Object.entries(value);
    return el('table', { class: 'kv', id },
      el('tbody', null, entries.map(([k, v]) =>
        el('tr', null, el('th', { scope: 'row' }, k.replace(/_/g, ' ')), el('td', { class: 'wrap' }, cell(v))))));
  }

  function viewSlave(ctx, root, arg) {
    const p = Number(arg);
    const base = `/api/slaves/${p}`;
    const identity = el('div', { id: 'slave-identity' }, el('p', { class: 'muted' }, 'Reading…'));
    const entriesBox = el('div', { id: 'slave-entries' });
    const emergencies = el('div', { id: 'slave-emergencies' });
    const sii = el('div', { id: 'slave-sii' });
    const title = el('h1', null, `Slave ${p}`);

    // The SDO form and the object dictionary.
    const sdoIndex = el('input', { id: 'sdo-index', type: 'text', placeholder: '0x6041', value: '0x1000', autocomplete: 'off', spellcheck: 'false' });
    const sdoSub = el('input', { id: 'sdo-sub', type: 'text', placeholder: '0', value: '0', autocomplete: 'off', spellcheck: 'false' });
    const sdoValue = el('input', { id: 'sdo-value', type: 'text', placeholder: 'value', autocomplete: 'off', spellcheck: 'false' });
    const sdoResult = el('output', { id: 'sdo-result', for: 'sdo-index sdo-sub' });
    const sdoForm = el('form', { id: 'sdo-form', class: 'form-row', onsubmit: (e) => e.preventDefault() },
      el('label', null, 'Index ', sdoIndex),
      el('label', null, 'Subindex ', sdoSub),
      el('button', { id: 'sdo-read', type: 'button', onclick: () => sdoRead() }, 'Read'),
      el('label', null, 'Value ', sdoValue),
      el('button', { id: 'sdo-write', type: 'button', onclick: () => sdoWrite() }, 'Write'));
    const sdoAnswer = el('p', { class: 'sdo-answer' },
      'Value: ', sdoResult, ' ',
      el('span', { class: 'muted' }, 'type '), el('span', { id: 'sdo-type', class: 'mono' }), ' ',
      el('span', { class: 'muted' }, 'raw '), el('span', { id: 'sdo-raw', class: 'mono wrap' }));
    const odStatus = el('span', { id: 'od-status', class: 'muted' });
    const odFilter = el('input', { id: 'od-filter', type: 'search', placeholder: 'filter objects', hidden: true, oninput: () => filterOd() });
    const odBox = el('div', { id: 'od' });

    root.append(title,
      el('section', null, el('h2', null, 'Identity'), identity),
      el('section', null, el('h2', null, 'Process data entries'), entriesBox),
      el('section', null, el('h2', null, 'SDO'),
        el('p', { class: 'muted' }, 'Read or write one object of the slave\'s dictionary now (writing needs the operator role). Index and subindex take 0x for hex.'),
        sdoForm, sdoAnswer),
      el('section', null, el('h2', null, 'Object dictionary'),
        el('div', { class: 'form-row' },
          el('button', { id: 'od-load', type: 'button', onclick: () => loadOd() }, 'Load the dictionary'), odFilter, odStatus),
        odBox),
      el('section', null, el('h2', null, 'Emergencies'), emergencies),
      el('section', null, el('h2', null, 'SII (EEPROM)'), sii));

    const sdoPath = () => {
      const index = sdoIndex.value.trim();
      const sub = sdoSub.value.trim();
      if (!index || !sub) {
        say('give an index (e.g. 0x6041) and a subindex (e.g. 0)');
        return null;
      }
      return `${base}/sdo/${encodeURIComponent(index)}/${encodeURIComponent(sub)}`;
    };

    async function sdoRead() {
      const path = sdoPath();
      if (!path) return;
      const button = $('#sdo-read');
      button.disabled = true;
      const d = await api(path, { source: 'action' });
      button.disabled = false;
      if (!d || !ctx.alive) return;
      sdoResult.textContent = typeof d.value === 'string' ? d.value : valueText(d.value);
      $('#sdo-type').textContent = valueText(d.type);
      $('#sdo-raw').textContent = d.raw ? String(d.raw) : '';
    }

    async function sdoWrite() {
      const path = sdoPath();
      if (!path) return;
      if (!sdoValue.value.trim()) {
        say('type the value to write');
        return;
      }
      const value = typedJson(sdoValue.value);
      const button = $('#sdo-write');
      button.disabled = true;
      const d = await api(path, { json: `{"value":${value}}` });
      button.disabled = false;
      if (!d) return;
      say(`wrote ${valueText(d.written !== undefined ? d.written : value)} to ${sdoIndex.value.trim()}:${sdoSub.value.trim()} of slave ${p}`, 'ok');
    }

    function filterOd() {
      const needle = odFilter.value.trim().toLowerCase();
      for (const tr of $$('#od-table tbody tr')) {
        tr.hidden = needle !== '' && !tr.textContent.toLowerCase().includes(needle);
      }
    }

    async function loadOd() {
      const button = $('#od-load');
      button.disabled = true;
      const started = performance.now();
      try {
        while (ctx.alive) {
          const d = await api(`${base}/objects`, { source: 'action' });
          if (!d || !ctx.alive) return;
          if (d.pending) {
            // The daemon reads the dictionary in the background: ask again.
            if (performance.now() - started > 30000) {
              odStatus.textContent = '';
              say('the dictionary is still being read after 30 s; try again later');
              return;
            }
            odStatus.textContent = 'The daemon is reading the dictionary…';
            await sleep(ctx, 1000);
            continue;
          }
          renderOd(Array.isArray(d.objects) ? d.objects : []);
          return;
        }
      } finally {
        button.disabled = false;
      }
    }

    function renderOd(objects) {
      const rows = [];
      for (const o of objects) {
        for (const e of o.entries || []) {
          const key = `${hex(o.index, 4)}:${Number(e.subindex).toString(16).padStart(2, '0')}`;
          const pick = () => {
            sdoIndex.value = hex(o.index, 4);
            sdoSub.value = String(e.subindex);
            sdoForm.scrollIntoView({ block: 'nearest' });
          };
          rows.push(el('tr', {
            'data-object': key, tabindex: 0, class: 'pick', title: 'Use this object in the SDO form',
            onclick: pick, onkeydown: (ev) => { if (ev.key === 'Enter') pick(); },
          },
          el('td', { class: 'mono' }, key),
          el('td', { class: 'wrap' }, o.name || ''),
          el('td', { class: 'wrap' }, e.name || ''),
          el('td', null, e.type || ''),
          el('td', { class: 'num' }, valueText(e.bits)),
          el('td', null, e.access || '')));
        }
      }
      odStatus.textContent = `${objects.length} objects, ${rows.length} entries; select one to use it in the SDO form.`;
      odFilter.hidden = false;
      odBox.replaceChildren(tableWrap(el('table', { id: 'od-table' },
        headRow('Object', 'Name', 'Entry', 'Type', 'Bits', 'Access'), el('tbody', null, rows))));
      filterOd();
    }

    async function writeOutput(name) {
      const input = $(`input.output-value[data-entry="${CSS.escape(name)}"]`, entriesBox);
      if (!input || !input.value.trim()) {
        say(`type the value to write to ${name}`);
        return;
      }
      const value = typedJson(input.value);
      const d = await api(`/api/outputs/${encodeURIComponent(name)}`, { json: `{"value":${value}}` });
      if (!d) return;
      say(`wrote ${value} to ${name}${d.holder ? ` (lease held by ${d.holder})` : ''}`, 'ok');
    }

    let identityKey = null;
    const renderIdentity = (s) => {
      const key = JSON.stringify(s);
      if (key === identityKey) return;
      identityKey = key;
      if (!s) {
        identity.replaceChildren(el('p', { class: 'bad' }, 'This slave is not in the network now (lost?).'));
        return;
      }
      if (s.lost) {
        title.textContent = `Slave ${p}: ${s.name} (lost)`;
        identity.replaceChildren(el('p', { id: 'slave-lost', class: 'bad' },
          `Lost: the network had ${s.name} at position ${p} and has it no more (unplugged, a broken cable before it, or powered off). ` +
          'The network runs on without it; a re-init accepts the network as it is.'));
        return;
      }
      title.textContent = `Slave ${p}: ${s.name}`;
      const rows = [
        ['Position', s.position],
        ['Name', s.name],
        ['State', stateBadge(s.state)],
        ['AL status', `${hex(s.al_status_code, 4)} ${s.al_status_text || ''}`],
        ['Vendor id', hex(s.vendor_id, 8)],
        ['Product code', hex(s.product_code, 8)],
        ['Revision', hex(s.revision, 8)],
        ['Alias', valueText(s.alias)],
        ['Configured address', hex(s.configured_address, 4)],
        ['Outputs', `${s.output_bytes} bytes at ${s.output_offset}`],
        ['Inputs', `${s.input_bytes} bytes at ${s.input_offset}`],
        ['Distributed clock', s.dc ? `${dcText(s.dc)}${s.dc.active ? `, cycle ${s.dc.cycle_ns} ns, shift ${s.dc.shift_ns} ns` : ''}` : '—'],
        ['Configuration', s.mismatch ? s.mismatch : (s.expected ? 'as configured' : 'not configured')],
      ];
      identity.replaceChildren(el('table', { class: 'kv narrow', id: 'identity-table' },
        el('tbody', null, rows.map(([k, v]) => el('tr', null, el('th', { scope: 'row' }, k), el('td', { class: 'wrap' }, v))))));
    };

    let entryKey = null;
    const renderEntries = (entries) => {
      const key = entries.map((e) => e.name).join('\n');
      if (key !== entryKey) {
        entryKey = key;
        if (!entries.length) {
          entriesBox.replaceChildren(el('p', { class: 'muted' }, 'This slave has no process data entries.'));
          return;
        }
        const rows = entries.map((e) => {
          const output = e.direction === 'output';
          return el('tr', { 'data-entry': e.name, 'data-direction': e.direction },
            el('td', { class: 'mono entry-name' }, e.name),
            el('td', { class: 'wrap label' }, e.label || ''),
            el('td', { class: 'mono' }, `${hex(e.index, 4)}:${Number(e.subindex).toString(16).padStart(2, '0')}`),
            el('td', null, output ? 'out' : 'in'),
            el('td', null, e.data_type),
            el('td', { class: 'num' }, e.bit_length),
            el('td', { 'data-field': 'value', class: 'num value' }),
            el('td', { class: 'write' }, output ? el('span', { class: 'write-cell' },
              el('input', { class: 'output-value', 'data-entry': e.name, type: 'text', size: 8, 'aria-label': `value for ${e.name}`,
                onkeydown: (ev) => { if (ev.key === 'Enter') writeOutput(e.name); } }),
              el('button', { class: 'output-write', 'data-entry': e.name, type: 'button', onclick: () => writeOutput(e.name) }, 'Write')) : ''));
        });
        entriesBox.replaceChildren(tableWrap(el('table', { id: 'entries-table' },
          headRow('Entry', 'Label', 'Object', 'Dir', 'Type', 'Bits', 'Value', 'Write'), el('tbody', null, rows))));
      }
      // Only the values change each refresh: what an operator types stays.
      const cells = $$('#entries-table td[data-field="value"]', entriesBox);
      entries.forEach((e, i) => {
        if (cells[i]) cells[i].textContent = valueText(e.value);
      });
    };

    let emergencyKey = null;
    const renderEmergencies = (list) => {
      const key = JSON.stringify(list);
      if (key === emergencyKey) return;
      emergencyKey = key;
      if (!list.length) {
        emergencies.replaceChildren(el('p', { class: 'muted' }, 'None received since the daemon started.'));
        return;
      }
      emergencies.replaceChildren(tableWrap(el('table', { id: 'emergencies-table' },
        headRow('Time (s)', 'Code', 'Register', 'Data', 'Text'),
        el('tbody', null, list.map((m) => el('tr', null,
          el('td', { class: 'num' }, seconds(m.time_ns)),
          el('td', { class: 'mono' }, m.code),
          el('td', { class: 'mono' }, m.register),
          el('td', { class: 'mono wrap' }, m.data),
          el('td', { class: 'wrap' }, m.text)))))));
    };

    let siiKey = null;
    const renderSii = (value) => {
      const key = JSON.stringify(value);
      if (key === siiKey) return;
      siiKey = key;
      if (!value || typeof value !== 'object') {
        sii.replaceChildren(el('p', { class: 'muted' }, 'No SII.'));
      } else if (value.pending) {
        sii.replaceChildren(el('p', { class: 'muted' }, 'The daemon is reading the SII…'));
      } else if (typeof value.error === 'string' && Object.keys(value).length === 1) {
        sii.replaceChildren(el('p', { class: 'bad' }, `The SII could not be read: ${value.error}`));
      } else {
        sii.replaceChildren(tableWrap(kvTable(value, 'sii-table')));
      }
    };

    every(ctx, 500, async () => {
      const d = await api(base);
      if (!d && (lastStatus === 404 || lastStatus === 400)) {
        // No such slave: asking again would only be refused again.
        identity.replaceChildren(el('p', { class: 'bad' }, `There is no slave ${p} in this network.`));
        return false;
      }
      if (!d || !ctx.alive) return true;
      renderIdentity(d.slave);
      renderEntries(Array.isArray(d.entries) ? d.entries : []);
      renderEmergencies(Array.isArray(d.emergencies) ? d.emergencies : []);
      renderSii(d.sii);
    });
  }

  // ------------------------------------------------------------------
  // 5. Plots
  // ------------------------------------------------------------------

  const PLOT_CAP = 20000; // points kept per series
  const PLOT_MAX_VARS = 32; // what the daemon plots at most

  const plot = {
    source: null,
    names: [],
    x: [], // seconds since the first point
    timeRaw: [], // time_ns and seq as received, for the CSV
    seqRaw: [],
    t0: null,
    series: {}, // name -> { raw: [...], y: [...] }
    labels: {}, // name -> label, from /api/entries
    received: 0,
    paused: false,
    frozenMax: null, // while paused: the last x on screen
    zoom: null, // [x0, x1] or null: everything
    drag: null,
    geometry: null,
    queued: false,
  };

  // A CSV cell of a value as JSON wrote it.
  function csvCell(v) {
    if (v === undefined || v === null) return '';
    if (typeof v === 'boolean' || typeof v === 'number') return String(v);
    const s = String(v);
    return /[",\n\r]/.test(s) ? `"${s.replace(/"/g, '""')}"` : s;
  }

  function plotNumber(v) {
    if (typeof v === 'number') return v;
    if (typeof v === 'boolean') return v ? 1 : 0;
    if (typeof v === 'string' && /^-?\d+(\.\d+)?$/.test(v)) return Number(v);
    return NaN;
  }

  function plotRange() {
    if (plot.zoom) return plot.zoom;
    if (!plot.x.length) return [0, 1];
    const last = plot.paused && plot.frozenMax !== null ? plot.frozenMax : plot.x[plot.x.length - 1];
    const first = plot.x[0];
    return [first, last > first ? last : first + 1];
  }

  function plotCsv() {
    const [a, b] = plotRange();
    const lines = [['time_ns', 'seq', ...plot.names].map(csvCell).join(',')];
    const i0 = lowerBound(plot.x, a);
    for (let i = i0; i < plot.x.length && plot.x[i] <= b; i++) {
      const row = [plot.timeRaw[i], plot.seqRaw[i]];
      for (const n of plot.names) row.push(csvCell(plot.series[n].raw[i]));
      lines.push(row.join(','));
    }
    return lines.join('\n') + '\n';
  }

  window.ecmxfPlotCsv = () => plotCsv();
  window.ecmxfPlotPoints = () => (plot.names.length ? plot.series[plot.names[0]].y.length : 0);

  function stopPlot() {
    if (plot.source) plot.source.close();
    plot.source = null;
  }

  function takePoints(data) {
    const times = Array.isArray(data.time_ns) ? data.time_ns : [];
    const seqs = Array.isArray(data.seq) ? data.seq : [];
    const values = data.values || {};
    const n = times.length;
    if (!n) return;
    if (plot.t0 === null) plot.t0 = Number(times[0]);
    for (let i = 0; i < n; i++) {
      plot.x.push((Number(times[i]) - plot.t0) / 1e9);
      plot.timeRaw.push(String(times[i]));
      plot.seqRaw.push(String(seqs[i]));
    }
    for (const name of plot.names) {
      const column = Array.isArray(values[name]) ? values[name] : [];
      const s = plot.series[name];
      for (let i = 0; i < n; i++) {
        s.raw.push(column[i]);
        s.y.push(plotNumber(column[i]));
      }
    }
    plot.received += n;
    const excess = plot.x.length - PLOT_CAP;
    if (excess > 0) {
      for (const arr of [plot.x, plot.timeRaw, plot.seqRaw]) arr.splice(0, excess);
      for (const name of plot.names) {
        plot.series[name].raw.splice(0, excess);
        plot.series[name].y.splice(0, excess);
      }
    }
    const count = $('#plot-count');
    if (count) count.textContent = `${plot.received} points received, ${plot.x.length} kept`;
    // Paused: keep receiving, but the view stays as it was.
    if (!plot.paused) queueDraw();
  }

  function queueDraw() {
    if (plot.queued) return;
    plot.queued = true;
    requestAnimationFrame(() => {
      plot.queued = false;
      drawPlot();
    });
  }

  function drawPlot() {
    const canvas = $('#plot');
    if (!canvas) return;
    const [xmin, xmax] = plotRange();
    plot.geometry = drawChart(canvas, {
      xmin, xmax, xLabel: 'time (s) since the first point', yLabel: plot.names.length === 1 ? plot.names[0] : 'value',
      series: plot.names.map((n, k) => ({ xs: plot.x, ys: plot.series[n].y, color: PALETTE[k % PALETTE.length] })),
      selection: plot.drag ? [plot.drag.from, plot.drag.to] : null,
    });
  }

  function startPlot(names) {
    stopPlot();
    Object.assign(plot, {
      names, x: [], timeRaw: [], seqRaw: [], t0: null, received: 0, paused: false, frozenMax: null, zoom: null, drag: null,
    });
    plot.series = {};
    for (const n of names) plot.series[n] = { raw: [], y: [] };
    const es = new EventSource('/api/plot?vars=' + encodeURIComponent(names.join(',')));
    plot.source = es;
    const status = (text) => { const s = $('#plot-status'); if (s) s.textContent = text; };
    status('connecting…');
    es.addEventListener('open', () => status('recording'));
    es.addEventListener('error', () => {
      if (es.readyState === EventSource.CLOSED) {
        status('stopped: the daemon refused the plot');
        if (plot.source === es) plot.source = null;
      } else {
        status('reconnecting…');
      }
    });
    es.addEventListener('points', (e) => {
      let data;
      try { data = parseJson(e.data); } catch (err) { return; }
      if (plot.source === es) takePoints(data);
    });
  }

  function viewPlots(ctx, root) {
    const filter = el('input', { id: 'plot-filter', type: 'search', placeholder: 'filter by name or label', autocomplete: 'off' });
    const list = el('div', { id: 'plot-vars', class: 'var-list' }, el('p', { class: 'muted' }, 'Reading the entries…'));
    const canvas = el('canvas', { id: 'plot', role: 'img', 'aria-label': 'the plot; drag across it to zoom, double-click to reset' });
    const pauseButton = el('button', { id: 'plot-pause', type: 'button' }, plot.paused ? 'Resume' : 'Pause');
    const legend = el('ul', { id: 'plot-legend', class: 'legend' });
    root.append(el('h1', null, 'Plots'),
      el('div', { class: 'plot-layout' },
        el('aside', { class: 'plot-chooser' },
          el('h2', null, 'Variables'),
          filter, list),
        el('div', { class: 'plot-main' },
          el('div', { class: 'form-row' },
            el('button', { id: 'plot-start', type: 'button' }, 'Start'),
            pauseButton,
            el('button', { id: 'plot-reset', type: 'button', title: 'Show everything received' }, 'Reset zoom'),
            el('button', { id: 'plot-csv', type: 'button', title: 'What is on screen, as plot.csv' }, 'Download CSV'),
            el('span', { id: 'plot-status', class: 'muted' }, plot.source ? 'recording' : (plot.names.length ? 'stopped' : '')),
            el('span', { id: 'plot-count', class: 'muted' }, plot.received ? `${plot.received} points received, ${plot.x.length} kept` : '0 points')),
          el('div', { class: 'plot-box' }, canvas),
          el('p', { class: 'muted hint' }, 'Drag across the plot to zoom into a time range; double-click (or Reset zoom) to see everything.'),
          legend)));

    const renderLegend = () => {
      legend.replaceChildren(...plot.names.map((n, k) => {
        const swatch = el('span', { class: 'swatch' });
        swatch.style.backgroundColor = PALETTE[k % PALETTE.length]; // CSSOM: allowed by the policy
        const label = plot.labels[n];
        return el('li', null, swatch, el('span', { class: 'wrap' }, el('span', { class: 'mono' }, n),
          label && label !== n ? ` ${label}` : ''));
      }));
    };

    const applyFilter = () => {
      const needle = filter.value.trim().toLowerCase();
      for (const row of $$('.var-row', list)) {
        row.hidden = needle !== '' && !row.dataset.search.includes(needle);
      }
    };
    filter.addEventListener('input', applyFilter);

    api('/api/entries').then((d) => {
      if (!d || !ctx.alive) return;
      const entries = Array.isArray(d.entries) ? d.entries : [];
      if (!entries.length) {
        list.replaceChildren(el('p', { class: 'muted' }, 'The process image has no entries.'));
        return;
      }
      for (const e of entries) plot.labels[e.name] = e.label || '';
      renderLegend();
      list.replaceChildren(...entries.map((e) => {
        const output = e.direction === 'output';
        const label = e.label || e.name;
        return el('label', {
          class: 'var-row', 'data-search': `${e.name} ${e.label || ''} ${e.data_type || ''}`.toLowerCase(),
          title: `${e.name} (${e.data_type})`,
        },
        el('input', { type: 'checkbox', class: 'plot-var', value: e.name, checked: plot.names.includes(e.name) }),
        el('span', { class: 'var-text' },
          el('span', { class: 'var-label' }, label),
          el('span', { class: 'var-name mono' }, `${e.name} · slave ${e.slave} · ${output ? 'output' : 'input'} · ${e.data_type}`)));
      }));
      applyFilter();
    });

    $('#plot-start', root).addEventListener('click', () => {
      const chosen = $$('input.plot-var', list).filter((b) => b.checked && !b.disabled).map((b) => b.value);
      if (!chosen.length) {
        say('choose at least one variable to plot');
        return;
      }
      if (chosen.length > PLOT_MAX_VARS) {
        say(`${chosen.length} variables chosen; a plot shows ${PLOT_MAX_VARS} at most`);
        return;
      }
      startPlot(chosen);
      pauseButton.textContent = 'Pause';
      renderLegend();
      drawPlot();
    });
    pauseButton.addEventListener('click', () => {
      plot.paused = !plot.paused;
      plot.frozenMax = plot.paused && plot.x.length ? plot.x[plot.x.length - 1] : null;
      pauseButton.textContent = plot.paused ? 'Resume' : 'Pause';
      drawPlot();
    });
    const resetZoom = () => {
      plot.zoom = null;
      drawPlot();
    };
    $('#plot-reset', root).addEventListener('click', resetZoom);
    canvas.addEventListener('dblclick', resetZoom);
    $('#plot-csv', root).addEventListener('click', () => {
      if (!plot.names.length) {
        say('nothing plotted yet');
        return;
      }
      const url = URL.createObjectURL(new Blob([plotCsv()], { type: 'text/csv' }));
      const a = el('a', { href: url, download: 'plot.csv', hidden: true });
      document.body.append(a);
      a.click();
      a.remove();
      setTimeout(() => URL.revokeObjectURL(url), 1000);
    });

    // Zoom: drag horizontally across the plot.
    const xOf = (ev) => ev.clientX - canvas.getBoundingClientRect().left;
    canvas.addEventListener('pointerdown', (ev) => {
      if (ev.button !== 0 || !plot.geometry || !plot.x.length) return;
      plot.drag = { from: xOf(ev), to: xOf(ev), pointer: ev.pointerId };
      try {
        canvas.setPointerCapture(ev.pointerId); // the drag goes on outside the canvas
      } catch (e) {
        /* an inactive pointer: the drag just ends at the edge */
      }
    });
    canvas.addEventListener('pointermove', (ev) => {
      if (!plot.drag || ev.pointerId !== plot.drag.pointer) return;
      plot.drag.to = xOf(ev);
      queueDraw();
    });
    const endDrag = (ev) => {
      if (!plot.drag || ev.pointerId !== plot.drag.pointer) return;
      const { from, to } = plot.drag;
      plot.drag = null;
      const g = plot.geometry;
      if (g && Math.abs(to - from) >= 5) {
        const clamp = (px) => Math.min(g.left + g.width, Math.max(g.left, px));
        const a = g.toX(clamp(Math.min(from, to)));
        const b = g.toX(clamp(Math.max(from, to)));
        if (b > a) plot.zoom = [a, b];
      }
      drawPlot();
    };
    canvas.addEventListener('pointerup', endDrag);
    canvas.addEventListener('pointercancel', endDrag);

    renderLegend();
    drawPlot();
    ctx.onResize = drawPlot;
    // A plot streams only while its view is open; what it gathered stays.
    ctx.cleanup.push(() => {
      stopPlot();
      plot.drag = null;
    });
  }

  // ------------------------------------------------------------------
  // 6. Events
  // ------------------------------------------------------------------

  function severityWord(s) {
    const n = Number(s);
    if (n >= 800) return 'fault';
    if (n >= 700) return 'warning';
    return 'info';
  }

  function viewEvents(ctx, root) {
    const filter = el('input', { id: 'events-filter', type: 'search', placeholder: 'filter: text, kind or slave', autocomplete: 'off' });
    const count = el('span', { id: 'events-count', class: 'muted' });
    const table = el('table', { id: 'events-table' }, headRow('Time (s)', 'Severity', 'Kind', 'Slave', 'Text'), el('tbody'));
    root.append(el('h1', null, 'Events'),
      el('div', { class: 'form-row' }, filter, count),
      tableWrap(table));
    const SHOWN = 1000;

    const render = () => {
      const needle = filter.value.trim().toLowerCase();
      const rows = [];
      let matching = 0;
      // Newest first.
      for (let i = live.events.length - 1; i >= 0; i--) {
        const e = live.events[i];
        const slave = e.slave === null || e.slave === undefined ? '' : String(e.slave);
        if (needle && !`${e.kind} ${e.text} ${slave}`.toLowerCase().includes(needle)) continue;
        matching++;
        if (rows.length >= SHOWN) continue;
        const word = severityWord(e.severity);
        rows.push(el('tr', { class: 'sev-' + word },
          el('td', { class: 'num' }, seconds(e.time_ns)),
          el('td', { title: `severity ${e.severity}` }, el('span', { class: 'severity', 'data-severity': word }, word)),
          el('td', null, e.kind),
          el('td', { class: 'num' }, slave ? el('a', { href: `#/slave/${slave}` }, slave) : ''),
          el('td', { class: 'wrap' }, e.text)));
      }
      $('tbody', table).replaceChildren(...rows);
      if (!rows.length) {
        $('tbody', table).append(el('tr', null, el('td', { colspan: 5, class: 'muted' },
          live.events.length ? 'No event matches the filter.' : 'No events yet.')));
      }
      count.textContent = `${matching} of ${live.events.length} events${matching > SHOWN ? `, the newest ${SHOWN} shown` : ''}`;
    };
    filter.addEventListener('input', render);

    // Events that arrive while the log is read are kept, then merged.
    let loading = true;
    const arrived = [];
    ctx.onEvent = (ev) => {
      if (loading) arrived.push(ev);
      else render();
    };
    render();
    api('/api/events').then((d) => {
      loading = false;
      if (!ctx.alive) return;
      if (d && Array.isArray(d.events)) {
        const known = new Set(d.events.map(eventKey));
        live.events = d.events.concat(arrived.filter((e) => !known.has(eventKey(e))));
        if (live.events.length > EVENTS_KEPT) live.events.splice(0, live.events.length - EVENTS_KEPT);
      }
      render();
    });
  }

  // ------------------------------------------------------------------
  // 7. Axes
  // ------------------------------------------------------------------

  const MODES = [
    [1, 'profile position', 'PP'], [3, 'profile velocity', 'PV'], [4, 'profile torque', 'TQ'], [6, 'homing', 'HM'],
    [8, 'cyclic sync position', 'CSP'], [9, 'cyclic sync velocity', 'CSV'], [10, 'cyclic sync torque', 'CST'],
  ];
  const modeName = (m) => {
    const found = MODES.find(([n]) => n === Number(m));
    return found ? `${m} ${found[1]}` : valueText(m);
  };
  const modeShort = (m) => {
    const found = MODES.find(([n]) => n === Number(m));
    return found ? `${m} ${found[2]}` : valueText(m);
  };

  function viewAxes(ctx, root) {
    const table = el('table', { id: 'axes-table' },
      headRow('Axis', 'Slave', 'State', 'Statusword', 'Mode', 'Enabled', 'Fault', 'Actions'),
      el('tbody'));
    const empty = el('p', { id: 'axes-empty', class: 'muted', hidden: true }, 'No axes configured.');
    const wrap = tableWrap(table);
    wrap.hidden = true;
    root.append(el('h1', null, 'Axes'),
      el('p', { class: 'muted' }, 'The CiA 402 drives of the configuration, decoded from the newest input frame. Commands and modes need the operator role.'),
      empty, wrap);

    async function post(button, path, body, done) {
      button.disabled = true;
      const d = await api(path, { body });
      button.disabled = false;
      if (d) say(done(d), 'ok');
    }

    const rowOf = (a) => {
      const n = a.axis;
      const select = el('select', { class: 'axis-mode', 'data-axis': n, 'aria-label': `mode of operation of axis ${n}` },
        MODES.map(([m, name, short]) => el('option', { value: m }, `${m} ${short}: ${name}`)));
      if (MODES.some(([m]) => m === Number(a.mode_display))) select.value = String(a.mode_display);
      const command = (c, text) => el('button', {
        class: 'axis-command', 'data-axis': n, 'data-command': c, type: 'button',
        onclick: (ev) => post(ev.currentTarget, `/api/axes/${n}/command`, { command: c },
          (d) => `axis ${n}: ${c.replace('_', ' ')} done, now ${valueText(d.state)}`),
      }, text);
      const setMode = el('button', {
        class: 'axis-set-mode', 'data-axis': n, type: 'button',
        onclick: (ev) => post(ev.currentTarget, `/api/axes/${n}/mode`, { mode: Number(select.value) },
          (d) => `axis ${n}: mode ${modeName(Number(select.value))} set${d.mode_display !== undefined ? `, display ${valueText(d.mode_display)}` : ''}`),
      }, 'Set');
      return el('tr', { 'data-axis': n },
        el('td', { class: 'num' }, n),
        el('td', { class: 'num' }, el('a', { href: `#/slave/${a.slave}` }, a.slave)),
        el('td', { 'data-field': 'state' }),
        el('td', { 'data-field': 'statusword', class: 'mono' }),
        el('td', { 'data-field': 'mode' }),
        el('td', { 'data-field': 'enabled' }),
        el('td', { 'data-field': 'fault' }),
        el('td', { class: 'actions' },
          el('div', { class: 'buttons' },
            command('enable', 'Enable'), command('disable', 'Disable'), command('fault_reset', 'Fault reset')),
          el('div', { class: 'buttons' }, select, setMode)));
    };

    const update = (row, a) => {
      const set = (field, text, cls) => {
        const td = $(`td[data-field="${field}"]`, row);
        td.textContent = text;
        td.className = cls || (field === 'statusword' ? 'mono' : '');
      };
      set('state', a.state === null || a.state === undefined ? 'unknown' : String(a.state));
      set('statusword', a.statusword === null || a.statusword === undefined ? '—' : hex(a.statusword, 4));
      const mode = a.mode_display !== undefined ? a.mode_display : a.mode;
      set('mode', mode === null || mode === undefined ? '—' : modeShort(mode));
      $('td[data-field="mode"]', row).title = mode === null || mode === undefined ? 'not mapped' : modeName(mode);
      set('enabled', a.enabled ? 'yes' : 'no', a.enabled ? 'good' : 'muted');
      set('fault', a.fault ? 'FAULT' : 'no', a.fault ? 'bad' : 'muted');
    };

    every(ctx, 500, async () => {
      const d = await api('/api/axes');
      if (!d || !ctx.alive) return;
      const axes = Array.isArray(d.axes) ? d.axes : [];
      empty.hidden = axes.length > 0;
      wrap.hidden = axes.length === 0;
      const body = $('tbody', table);
      const wanted = new Set(axes.map((a) => String(a.axis)));
      for (const tr of $$('tr[data-axis]', body)) if (!wanted.has(tr.dataset.axis)) tr.remove();
      // Rows are kept, so a mode being chosen is not reset by the refresh.
      for (const a of axes) {
        let row = $(`tr[data-axis="${CSS.escape(String(a.axis))}"]`, body);
        if (!row) {
          row = rowOf(a);
          body.append(row);
        }
        update(row, a);
      }
    });
  }

  // ------------------------------------------------------------------
  // 8. Configuration
  // ------------------------------------------------------------------

  function viewConfig(ctx, root) {
    const cycle = el('dd', { id: 'config-cycle' }, '—');
    const target = el('dd', { id: 'config-target' }, '—');
    const state = el('dd', { id: 'config-state' }, '—');
    root.append(el('h1', null, 'Configuration'),
      el('dl', { class: 'facts' },
        el('dt', null, 'Cycle'), cycle,
        el('dt', null, 'Target state'), target,
        el('dt', null, 'State now'), state),
      el('h2', null, 'Downloads'),
      el('ul', { class: 'downloads' },
        el('li', null,
          el('a', { id: 'download-toml', href: '/api/config.toml', download: 'ecmxfd.toml' }, 'ecmxfd.toml'),
          el('p', null, 'The network as an ecmxfd configuration: its link and cycle, and one [[slave]] per slave found, with the identity checked at bring-up. Start another ecmxfd with it to expect this same network.')),
        el('li', null,
          el('a', { id: 'download-eni', href: '/api/config.eni', download: 'network.xml' }, 'network.xml'),
          el('p', null, 'The EtherCAT Network Information (ENI) file this network runs from, if it runs from one; otherwise ',
            el('code', null, 'ecmxfctl config --format eni > network.xml'), ' writes one.'))));

    const fill = (ov) => {
      cycle.textContent = ov.cycle_us !== undefined ? `${ov.cycle_us} µs` : '—';
      target.replaceChildren(stateBadge(ov.target_state));
      state.replaceChildren(stateBadge(ov.state));
    };
    ctx.onOverview = fill;
    if (live.overview) fill(live.overview);
    else api('/api/overview').then((ov) => { if (ov && ctx.alive) fill(ov); });
  }

  // ------------------------------------------------------------------
  // Start
  // ------------------------------------------------------------------

  // A last guard: nothing the page does should end in an uncaught error.
  window.addEventListener('unhandledrejection', (e) => {
    e.preventDefault();
    const why = e.reason && e.reason.message ? e.reason.message : String(e.reason);
    say(`the page failed: ${why}`, 'error', 'page');
  });

  let resizeQueued = false;
  window.addEventListener('resize', () => {
    if (resizeQueued) return;
    resizeQueued = true;
    requestAnimationFrame(() => {
      resizeQueued = false;
      if (view && view.onResize) view.onResize();
    });
  });

  async function start() {
    $('#message').addEventListener('click', () => unsay(message.source));
    $('#login-form').addEventListener('submit', login);
    $('#logout-button').addEventListener('click', logout);
    window.addEventListener('hashchange', route);
    await refreshWho();
    route();
  }

  start();
})();
