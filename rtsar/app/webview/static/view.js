// rtsar view --http: the live waterfall page.  Messages: rtsar/app/webview/frames.py.
"use strict";
(function () {
  const FLOOR_DB = -250; // at or below: a pixel that holds no line
  const WAITING = "waiting for the first strip";
  const IMAGE_TITLE = "|image| in dB re the peak of the lines shown";
  const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
  const S = {
    stream: null, tags: null, image: null, htags: null, heights: null,
    newest: -1, hnewest: -1, first: Infinity, hfirst: Infinity, // rows: newest, oldest received
    status: {}, connected: false, messages: 0, rendered: null, heightRendered: null,
  };
  window.rtsarView = S; // for tests and the curious: the page's state

  const $ = (id) => document.getElementById(id);
  const dr = $("dynamic-range");
  const aspect = $("true-aspect");
  const query = new URLSearchParams(location.search); // ?dr=40&aspect=1: a link keeps the view
  dr.value = query.get("dr") || document.body.dataset.dynamicRangeDb || "50";
  aspect.checked = ["1", "true", "yes"].includes(query.get("aspect"));
  dr.addEventListener("change", schedule);
  aspect.addEventListener("change", schedule);
  window.addEventListener("resize", schedule);

  function connect() {
    const scheme = location.protocol === "https:" ? "wss://" : "ws://";
    // rtsar view --http-token: the page's address carries the token; the socket asks for it too
    const token = query.get("token");
    const ask = token === null ? "" : "?token=" + encodeURIComponent(token);
    const ws = new WebSocket(scheme + location.host + "/ws" + ask);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => { S.connected = true; showState(); };
    ws.onclose = () => {
      S.connected = false;
      showState();
      setTimeout(connect, 1000);
    };
    ws.onmessage = (ev) => {
      S.messages += 1;
      if (typeof ev.data === "string") onText(JSON.parse(ev.data));
      else onRows(ev.data);
      schedule();
    };
  }

  function onText(m) {
    if (m.type === "stream") {
      S.stream = m;
      const n = m.rows * m.columns;
      S.tags = new Float64Array(m.rows).fill(-1);
      S.image = new Float32Array(n).fill(FLOOR_DB);
      S.htags = new Float64Array(m.rows).fill(-1);
      S.heights = new Float32Array(n).fill(NaN);
      S.newest = S.hnewest = -1;
      S.first = S.hfirst = Infinity;
      $("height-plot").hidden = true;
      $("stream").textContent = "stream " + m.stream_id + ": " + m.lines_per_row +
        " line(s) per row, " + m.bins_per_column + " bin(s) per column (largest |x|)";
    } else if (m.type === "status") {
      S.status = m;
      showStatus(m);
    }
    showState();
  }

  function onRows(buf) {
    const n = new DataView(buf).getUint32(0, true);
    const head = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
    const st = S.stream;
    if (!st || head.columns !== st.columns) return;
    const rows = new Float64Array(buf, 4 + n, head.count);
    const vals = new Float32Array(buf, 4 + n + 8 * head.count, head.count * head.columns);
    const image = head.kind === "image";
    const tags = image ? S.tags : S.htags;
    const data = image ? S.image : S.heights;
    const C = st.columns;
    for (let i = 0; i < head.count; i++) {
      const slot = rows[i] % st.rows;
      tags[slot] = rows[i];
      data.set(vals.subarray(i * C, (i + 1) * C), slot * C);
    }
    const oldest = rows.reduce((a, b) => Math.min(a, b), Infinity);
    if (image) {
      S.newest = Math.max(S.newest, head.newest);
      S.first = Math.min(S.first, oldest);
    } else {
      S.hnewest = Math.max(S.hnewest, head.newest);
      S.hfirst = Math.min(S.hfirst, oldest);
      $("height-plot").hidden = false;
    }
  }

  let pending = false;
  function schedule() {
    if (!pending) { pending = true; setTimeout(render, 40); }
  }

  function render() {
    pending = false;
    if (!S.stream) return;
    layout();
    renderImage();
    if (S.hnewest >= 0) renderHeights();
  }

  // The row shown at canvas line y (0 at the top, the newest row at the bottom).
  function rowAt(y, newest) { return newest - (S.stream.rows - 1 - y); }

  function renderImage() {
    const st = S.stream, R = st.rows, C = st.columns;
    const range = Math.max(1, Number(dr.value) || 50);
    let peak = -Infinity;
    for (let y = 0; y < R; y++) {
      const r = rowAt(y, S.newest), slot = r % R;
      if (r < 0 || S.tags[slot] !== r) continue;
      for (let c = 0; c < C; c++) {
        const v = S.image[slot * C + c];
        if (v > FLOOR_DB && v > peak) peak = v;
      }
    }
    const canvas = $("waterfall");
    if (canvas.width !== C || canvas.height !== R) { canvas.width = C; canvas.height = R; }
    const ctx = canvas.getContext("2d");
    const out = ctx.createImageData(C, R);
    for (let y = 0; y < R; y++) {
      const r = rowAt(y, S.newest), slot = r % R;
      const ok = r >= 0 && S.tags[slot] === r;
      for (let c = 0; c < C; c++) {
        const v = ok ? S.image[slot * C + c] : FLOOR_DB;
        let g = 0;
        if (v > FLOOR_DB && isFinite(peak)) {
          g = Math.round((255 * (Math.min(Math.max(v - peak, -range), 0) + range)) / range);
        }
        const k = 4 * (y * C + c);
        out.data[k] = out.data[k + 1] = out.data[k + 2] = g;
        out.data[k + 3] = 255;
      }
    }
    ctx.putImageData(out, 0, 0);
    if (S.newest < 0) { // a stream but no line yet: no axis to tell, no scale
      $("image-title").textContent = WAITING;
      for (const id of ["image-xticks", "image-yticks", "image-barticks"]) $(id).replaceChildren();
      S.rendered = null;
      return;
    }
    $("image-title").textContent = IMAGE_TITLE;
    axes("image", S.newest, S.first);
    greyBar(range);
    S.rendered = { newest: S.newest, peak_db: peak, dynamic_range_db: range, rows: R, columns: C };
  }

  function colour(t) {
    const x = Math.min(Math.max(t, 0), 1) * (VIRIDIS.length - 1);
    const i = Math.min(Math.floor(x), VIRIDIS.length - 2), f = x - i;
    return VIRIDIS[i].map((a, j) => Math.round(a + f * (VIRIDIS[i + 1][j] - a)));
  }

  function renderHeights() {
    const st = S.stream, R = st.rows, C = st.columns;
    let lo = Infinity, hi = -Infinity;
    for (let y = 0; y < R; y++) {
      const r = rowAt(y, S.hnewest), slot = r % R;
      if (r < 0 || S.htags[slot] !== r) continue;
      for (let c = 0; c < C; c++) {
        const v = S.heights[slot * C + c];
        if (isFinite(v)) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
      }
    }
    if (!(hi > lo)) { lo = (isFinite(lo) ? lo : 0) - 5e-4; hi = lo + 1e-3; }
    const canvas = $("heights");
    if (canvas.width !== C || canvas.height !== R) { canvas.width = C; canvas.height = R; }
    const ctx = canvas.getContext("2d");
    const out = ctx.createImageData(C, R);
    for (let y = 0; y < R; y++) {
      const r = rowAt(y, S.hnewest), slot = r % R;
      const ok = r >= 0 && S.htags[slot] === r;
      for (let c = 0; c < C; c++) {
        const v = ok ? S.heights[slot * C + c] : NaN;
        const rgb = isFinite(v) ? colour((v - lo) / (hi - lo)) : [153, 153, 153];
        const k = 4 * (y * C + c);
        out.data[k] = rgb[0]; out.data[k + 1] = rgb[1]; out.data[k + 2] = rgb[2];
        out.data[k + 3] = 255;
      }
    }
    ctx.putImageData(out, 0, 0);
    axes("height", S.hnewest, S.hfirst);
    colourBar(1e3 * lo, 1e3 * hi);
    S.heightRendered = { newest: S.hnewest, low_m: lo, high_m: hi };
  }

  function layout() {
    const st = S.stream;
    const both = S.hnewest >= 0;
    const maxW = Math.max(200, (window.innerWidth - 60) / (both ? 2 : 1) - 220);
    const maxH = Math.max(240, window.innerHeight - 260);
    const wM = st.columns * Math.abs(st.column_step_m);
    const hM = st.rows * Math.abs(st.row_step_m);
    let w = Math.min(maxW, 900), h = maxH;
    if (aspect.checked && wM > 0 && hM > 0) {
      const s = Math.min(maxW / wM, maxH / hM);
      w = wM * s; h = hM * s;
    }
    for (const id of ["waterfall", "heights"]) {
      $(id).style.width = w + "px";
      $(id).style.height = h + "px";
    }
    for (const id of ["image-bar", "height-bar"]) $(id).style.height = h + "px";
  }

  function niceTicks(a, b, count) {
    const lo = Math.min(a, b), hi = Math.max(a, b), span = hi - lo;
    if (!(span > 0)) return { step: 1, values: [] };
    const raw = span / count, mag = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw);
    const values = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) values.push(v);
    return { step, values };
  }

  function label(v, step) {
    const digits = Math.max(0, -Math.floor(Math.log10(step) + 1e-9));
    return (Math.abs(v) < step * 1e-6 ? 0 : v).toFixed(digits);
  }

  // Ticks along from…to (0…100 %), labelled only where lines are: within lo…hi.
  function ticks(box, from, to, count, vertical, lo = from, hi = to) {
    const t = niceTicks(from, to, count);
    const a = Math.min(lo, hi) - 1e-9 * t.step, b = Math.max(lo, hi) + 1e-9 * t.step;
    box.replaceChildren(...t.values.filter((v) => v >= a && v <= b).map((v) => {
      const s = document.createElement("span");
      s.textContent = label(v, t.step);
      s.style[vertical ? "top" : "left"] = (100 * (v - from)) / (to - from) + "%";
      return s;
    }));
  }

  // first: the oldest row received; the rows above it hold no line and get no label.
  function axes(kind, newest, first) {
    const st = S.stream;
    const left = st.column0_m - 0.5 * st.column_step_m;
    const right = st.column0_m + (st.columns - 0.5) * st.column_step_m;
    ticks($(kind + "-xticks"), left, right, 6, false);
    const top = st.row0_m + (newest - st.rows + 0.5) * st.row_step_m;
    const bottom = st.row0_m + (newest + 0.5) * st.row_step_m;
    const held = st.row0_m + (Math.max(first, newest - st.rows + 1) - 0.5) * st.row_step_m;
    ticks($(kind + "-yticks"), top, bottom, 8, true, held, bottom);
  }

  function greyBar(range) {
    const bar = $("image-bar"), ctx = bar.getContext("2d");
    const img = ctx.createImageData(1, bar.height);
    for (let y = 0; y < bar.height; y++) {
      const g = Math.round(255 * (1 - y / (bar.height - 1)));
      img.data.set([g, g, g, 255], 4 * y);
    }
    ctx.putImageData(img, 0, 0);
    ticks($("image-barticks"), 0, -range, 5, true);
  }

  function colourBar(lowMm, highMm) {
    const bar = $("height-bar"), ctx = bar.getContext("2d");
    const img = ctx.createImageData(1, bar.height);
    for (let y = 0; y < bar.height; y++) img.data.set([...colour(1 - y / (bar.height - 1)), 255], 4 * y);
    ctx.putImageData(img, 0, 0);
    ticks($("height-barticks"), highMm, lowMm, 5, true);
  }

  function fixed(v, digits, unit) {
    return typeof v === "number" ? v.toFixed(digits) + unit : "–";
  }

  function showStatus(m) {
    const c = m.counters || {};
    const rows = [
      ["source", m.source || ""],
      ["PRF (pulses processed)", fixed(m.pulse_rate_hz, 0, " Hz")],
      ["latency median / p99 (recent)", fixed(m.latency_recent_median_ms, 2, " ms") + " / " +
        fixed(m.latency_recent_p99_ms, 2, " ms")],
      ["pulses processed, lines", (c.pulses_processed ?? "–") + ", " + (c.lines_out ?? "–")],
    ];
    // The words and what is red come from the server (frames.py: losses, notes, link_words):
    // red only for what is missing, and for a source silent now.
    const link = m.link || { text: "–", alarm: false };
    const lost = m.lost || [], noted = m.noted || [];
    const red = new Set();
    rows.push(["link", link.text]);
    if (link.alarm) red.add("link");
    rows.push(["lost", lost.length ? lost.join("; ") : Object.keys(c).length ? "nothing" : "–"]);
    if (lost.length) red.add("lost");
    if (noted.length) rows.push(["noted, nothing lost", noted.join("; ")]);
    const v = m.viewer || {};
    rows.push(["this viewer", "strips " + (v.strips ?? 0) + ", missed strips " +
      (v.missed_strips ?? 0) + ", bad messages " + (v.bad_messages ?? 0) + "; browsers " +
      (m.browsers ?? 1)]);
    if (v.missed_strips) red.add("this viewer");
    const body = $("status").tBodies[0];
    body.replaceChildren(...rows.map(([k, val], i) => {
      const tr = document.createElement("tr");
      if (red.has(k)) tr.className = "problem";
      tr.id = "status-" + i;
      for (const text of [k, val]) {
        const td = document.createElement("td");
        td.textContent = text;
        tr.appendChild(td);
      }
      return tr;
    }));
  }

  function showState() {
    const text = S.connected ? (S.status.state || "connected") : "viewer not reachable: reconnecting…";
    $("state").textContent = text;
  }

  connect();
})();
