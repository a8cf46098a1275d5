// phyagentos view: keeps the page's panels live and sends signals. Plain JS, no build step.
(function () {
  "use strict";
  const meta = (name) => (document.querySelector(`meta[name="${name}"]`) || {}).content || "";
  const params = new URLSearchParams(location.search);
  if (params.get("token")) sessionStorage.setItem("phyagentos-token", params.get("token"));
  const token = meta("phyagentos-token") || sessionStorage.getItem("phyagentos-token") || "";
  const scope = meta("phyagentos-scope");
  const esc = (x) => String(x).replace(/[&<>"']/g, (c) => ({"&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;", "'": "&#39;"}[c]));

  // -- panels: re-fetch the [data-fragment]s the server says changed ------------------
  // The stream is told which fragments this page shows (?f=URL); each "change" event
  // carries the list of those whose inputs changed (null: all of them).
  const fragmentEls = () => [...document.querySelectorAll("[data-fragment]")];
  let inflight = false, queued = null;
  async function refresh(which) {
    const want = which ? new Set(which) : null;
    if (inflight) {
      queued = (want === null || queued === "all") ? "all" : new Set([...(queued || []), ...want]);
      return;
    }
    inflight = true;
    try {
      await Promise.all(fragmentEls().filter((el) => !want || want.has(el.dataset.fragment)).map(async (el) => {
        try {
          const r = await fetch(el.dataset.fragment, {cache: "no-store"});
          const html = await r.text();
          if (el.dataset.html !== html) { el.innerHTML = html; el.dataset.html = html; }
        } catch (e) { /* server gone: the live dot shows it */ }
      }));
      document.dispatchEvent(new Event("phyagentos:refreshed"));
    } finally {
      inflight = false;
      if (queued !== null) { const q = queued; queued = null; refresh(q === "all" ? null : [...q]); }
    }
  }
  const dot = document.getElementById("live");
  // One stream per visible page. A hidden page (another tab in front, or a page kept in the
  // back/forward cache) closes its stream: Chromium allows 6 connections per host, and
  // streams held by cached pages and background tabs would otherwise starve new loads.
  let es = null;
  function connect() {
    if (es) return;
    const q = new URLSearchParams();
    if (scope) q.set("session", scope);
    for (const el of fragmentEls()) q.append("f", el.dataset.fragment);
    es = new EventSource("/events?" + q.toString());
    es.onopen = () => { dot.className = "live on"; refresh(null); };
    es.addEventListener("change", (ev) => {
      let which = null;
      try { which = JSON.parse(ev.data); } catch (e) { which = null; }
      refresh(Array.isArray(which) ? which : null);
    });
    es.onerror = () => { dot.className = "live off"; };
  }
  function disconnect() {
    if (es) { es.close(); es = null; dot.className = "live paused"; }
  }
  window.addEventListener("pagehide", disconnect);
  window.addEventListener("pageshow", () => { if (document.visibilityState !== "hidden") connect(); });
  document.addEventListener("visibilitychange", () => {
    if (document.visibilityState === "hidden") disconnect(); else connect();
  });
  window.phyagentosStream = () => (es ? es.readyState : -1);  // tests: 0 connecting, 1 open, -1 closed
  refresh(null);
  if (document.visibilityState !== "hidden") connect();

  // -- signals ---------------------------------------------------------------------
  document.addEventListener("click", async (ev) => {
    const b = ev.target.closest("button.sig");
    if (!b) return;
    const kind = b.dataset.kind;
    // No confirmation dialog: an e-stop must never wait for one.
    const body = {kind: kind, reason: "from phyagentos view"};
    if (b.dataset.session) body.session_id = b.dataset.session;
    b.disabled = true;
    try {
      const r = await fetch("/api/signal", {method: "POST", headers: {"Content-Type": "application/json",
        "X-PhyAgentOS-Token": token}, body: JSON.stringify(body)});
      const j = await r.json();
      b.title = r.ok ? `sent ${j.kind} (${j.id})` : j.error;
      b.dataset.result = r.ok ? "sent" : "refused";
      if (!r.ok) alert(j.error);
    } finally { b.disabled = false; }
  });

  // -- one cursor on simulated time, shared by plots, 3D, images, video, transitions, tree --
  const cursor = {t: null, set(t, src) {
    if (t === null || Number.isNaN(t)) return;
    this.t = t;
    document.dispatchEvent(new CustomEvent("phyagentos:cursor", {detail: {t: t, src: src}}));
  }};
  window.phyagentosCursor = cursor;

  // -- the robot in 3D: server-rendered MuJoCo frames, a timeline, orbit by drag ------
  const box = document.querySelector(".scene3d");
  if (box) {
    const sid = box.dataset.session, img = box.querySelector("img.scene"), slider = box.querySelector("input.frame");
    const info = box.querySelector(".frame-info");
    const cam = {az: 140, el: -25, dist: 1.9};
    let times = [], live = true, pending = null, loading = false, lastLive = 0, requested = -1;
    function src() {
      const f = live ? "live" : slider.value;
      const ov = box.querySelector("input.overlays");
      return `/api/scene/${encodeURIComponent(sid)}.png?frame=${f}&az=${cam.az.toFixed(1)}&el=${cam.el.toFixed(1)}&dist=${cam.dist.toFixed(2)}` +
        (ov && ov.checked ? "&overlays=1" : "");
    }
    function show() {
      pending = src();
      if (loading) return;
      loading = true;
      const url = pending; pending = null;
      fetch(url, {cache: "no-store"}).then(async (r) => {
        if (r.ok) {
          const blob = await r.blob();
          const old = img.src; img.src = URL.createObjectURL(blob); if (old.startsWith("blob:")) URL.revokeObjectURL(old);
          const t = r.headers.get("X-Scene-Time"), s = r.headers.get("X-Scene-Source");
          info.textContent = `${s} · t = ${t} s` + (live ? "" : ` · frame ${slider.value}/${times.length - 1}`);
          img.dataset.source = s; img.dataset.t = t; img.dataset.overlays = r.headers.get("X-Scene-Overlays") || "0";
          img.dataset.overlayKinds = r.headers.get("X-Scene-Overlay-Kinds") || "";
          img.dataset.cloud = r.headers.get("X-Scene-Cloud") || "";
          const ovInfo = box.querySelector(".overlay-info");
          if (ovInfo) ovInfo.textContent = img.dataset.overlays !== "0" ? ` · drawn: ${img.dataset.overlayKinds.replace(/,/g, ", ")}` +
            (img.dataset.cloud ? ` · cloud of ${img.dataset.cloud.replace(/_cloud\.npz$/, "")}` : "") : "";
          const m = /frame=(\d+)/.exec(url); img.dataset.shown = m ? m[1] : "live";
        } else {
          info.textContent = await r.text();
        }
      }).finally(() => { loading = false; if (pending) show(); });
    }
    async function loadFrames() {
      try {
        const j = await (await fetch(`/api/frames/${encodeURIComponent(sid)}`, {cache: "no-store"})).json();
        times = j.t || [];
        if (times.length) {
          slider.disabled = false; slider.max = String(times.length - 1);
          if (live) { slider.value = slider.max; }
        }
      } catch (e) { /* keep the last */ }
    }
    const ovBox = box.querySelector("input.overlays");
    if (ovBox) ovBox.addEventListener("change", () => show());
    slider.addEventListener("input", () => {
      live = false; show();
      if (times.length) cursor.set(times[Number(slider.value)], "3d");
    });
    document.addEventListener("phyagentos:cursor", async (ev) => {
      if (ev.detail.src === "3d") return;
      if (!times.length) await loadFrames();
      if (!times.length) return;
      let best = 0;  // the recorded frame nearest to the cursor
      for (let i = 1; i < times.length; i++) if (Math.abs(times[i] - ev.detail.t) < Math.abs(times[best] - ev.detail.t)) best = i;
      live = false;
      if (requested !== best) { requested = best; slider.value = String(best); show(); }
    });
    let drag = null;
    img.addEventListener("mousedown", (e) => { drag = {x: e.clientX, y: e.clientY}; e.preventDefault(); });
    window.addEventListener("mouseup", () => { drag = null; });
    window.addEventListener("mousemove", (e) => {
      if (!drag) return;
      cam.az -= (e.clientX - drag.x) * 0.5; cam.el = Math.max(-89, Math.min(89, cam.el - (e.clientY - drag.y) * 0.5));
      drag = {x: e.clientX, y: e.clientY}; show();
    });
    img.addEventListener("wheel", (e) => { e.preventDefault(); cam.dist = Math.max(0.4, Math.min(6, cam.dist * (e.deltaY > 0 ? 1.1 : 0.9))); show(); });
    // While the session is live, follow its checkpoint; once finished, scrub the recording.
    document.addEventListener("phyagentos:refreshed", async () => {
      const st = document.getElementById("session-state");
      const terminal = st && st.dataset.finished === "true";  // the server's one set (changes.FINISHED_STATES)
      await loadFrames();
      if (terminal && times.length && live) { live = false; slider.value = slider.max; show(); return; }
      // Following a live session: at most one server render per second, whatever the event rate.
      const now = Date.now();
      if (live && now - lastLive >= 1000) { lastLive = now; show(); }
      else if (!img.src) { show(); }
    });
  }

  // -- signals on one timeline: canvas plots against simulated time --------------------
  // Every section.timeline (two on the compare page) follows the one cursor; what it
  // drives (transitions, video, tree, session state) is looked up in its own column.
  document.querySelectorAll("section.timeline").forEach((tl) => {
    const scopeEl = tl.closest(".compare-col") || document;
    const sid = tl.dataset.session, plotsBox = tl.querySelector(".tl-plots"), info = tl.querySelector(".tl-info");
    const imagesBox = tl.querySelector(".tl-images");
    const COLORS = ["#1565c0", "#c62828", "#2e7d32", "#6a1b9a", "#ef6c00", "#00838f", "#5d4037", "#9e9d24"];
    let sig = null, loadedFinal = false, lastFetch = 0, retryMs = 1000;
    const W = () => Math.max(320, Math.min(1100, plotsBox.clientWidth || 900)), H = 120, PADL = 52, PADR = 8;
    const xOf = (t, w) => PADL + (w - PADL - PADR) * (sig.t1 > sig.t0 ? (t - sig.t0) / (sig.t1 - sig.t0) : 0);
    const tOf = (x, w) => sig.t0 + (sig.t1 - sig.t0) * Math.max(0, Math.min(1, (x - PADL) / (w - PADL - PADR)));
    function draw(canvas) {
      const p = sig.plots[Number(canvas.dataset.index)], w = canvas.width, ctx = canvas.getContext("2d");
      ctx.clearRect(0, 0, w, H);
      let lo = Infinity, hi = -Infinity;
      for (const l of p.lines) for (const y of l.y) if (y !== null) { lo = Math.min(lo, y); hi = Math.max(hi, y); }
      if (!(hi > lo)) { hi = (lo === Infinity ? 1 : lo + 1); lo = hi - 2; }
      const pad = (hi - lo) * 0.08; lo -= pad; hi += pad;
      const yOf = (y) => 6 + (H - 22) * (1 - (y - lo) / (hi - lo));
      ctx.strokeStyle = "#cfd8dc"; ctx.strokeRect(PADL, 4, w - PADL - PADR, H - 18);
      ctx.fillStyle = "#546e7a"; ctx.font = "10px sans-serif";
      ctx.fillText(hi.toPrecision(3), 2, 12); ctx.fillText(lo.toPrecision(3), 2, H - 16);
      ctx.fillText(`${sig.t0.toFixed(2)} s`, PADL, H - 3); ctx.fillText(`${sig.t1.toFixed(2)} s`, w - PADR - 44, H - 3);
      for (const e of sig.events) {  // safety events: red lines
        ctx.strokeStyle = "#e53935"; ctx.beginPath(); ctx.moveTo(xOf(e.t, w), 4); ctx.lineTo(xOf(e.t, w), H - 14); ctx.stroke();
      }
      p.lines.forEach((l, k) => {
        ctx.strokeStyle = COLORS[k % COLORS.length]; ctx.lineWidth = 1.4; ctx.beginPath();
        let pen = false;
        for (let i = 0; i < l.t.length; i++) {
          if (l.y[i] === null) { pen = false; continue; }
          const x = xOf(l.t[i], w), y = yOf(l.y[i]);
          if (!pen) { ctx.moveTo(x, y); pen = true; } else ctx.lineTo(x, y);
        }
        ctx.stroke();
      });
      if (cursor.t !== null) {
        ctx.strokeStyle = "#000"; ctx.lineWidth = 1.5; ctx.beginPath();
        ctx.moveTo(xOf(cursor.t, w), 2); ctx.lineTo(xOf(cursor.t, w), H - 14); ctx.stroke();
      }
    }
    function valueAt(l, t) {  // the last sample at or before t
      let v = null;
      for (let i = 0; i < l.t.length && l.t[i] <= t + 1e-9; i++) v = l.y[i];
      return v;
    }
    function build() {
      plotsBox.innerHTML = "";
      const w = W();
      sig.plots.forEach((p, i) => {
        const box = document.createElement("div"); box.className = "tl-plot"; box.dataset.name = p.name;
        const head = document.createElement("div"); head.className = "small tl-legend";
        head.innerHTML = `<b>${esc(p.name)}</b> <span class="muted">(${esc(p.unit)})</span> ` + p.lines.map((l, k) =>
          `<span class="tl-key" style="color:${COLORS[k % COLORS.length]}">■ ${esc(l.label)} <span class="tl-val" data-k="${k}"></span></span>`).join(" ");
        const c = document.createElement("canvas"); c.width = w; c.height = H; c.dataset.index = String(i);
        c.className = "tl-canvas";
        let dragging = false;
        const move = (e) => { const r = c.getBoundingClientRect(); cursor.set(tOf(e.clientX - r.left, c.width), "plot"); };
        c.addEventListener("mousedown", (e) => { dragging = true; move(e); e.preventDefault(); });
        window.addEventListener("mouseup", () => { dragging = false; });
        c.addEventListener("mousemove", (e) => { if (dragging) move(e); });
        box.appendChild(head); box.appendChild(c); plotsBox.appendChild(box);
      });
      const ev = sig.events.map((e) => `<span class="tl-event" title="${esc(e.message)}">${e.t.toFixed(2)} s <code>${esc(e.code)}</code></span>`).join(" ");
      info.innerHTML = `${sig.t0.toFixed(2)}–${sig.t1.toFixed(2)} s simulated · ${sig.frames.length} recorded frames` +
        (ev ? ` · safety/target events (red): ${ev}` : " · no safety event") + (sig.notes.length ? ` · ${esc(sig.notes.join("; "))}` : "");
      info.className = "tl-info";
    }
    function update() {
      if (!sig) return;
      tl.dataset.cursorT = cursor.t === null ? "" : cursor.t.toFixed(4);
      for (const c of plotsBox.querySelectorAll("canvas")) draw(c);
      for (const box of plotsBox.querySelectorAll(".tl-plot")) {
        const p = sig.plots.find((q) => q.name === box.dataset.name);
        box.querySelectorAll(".tl-val").forEach((s) => {
          const v = valueAt(p.lines[Number(s.dataset.k)], cursor.t); s.textContent = v === null ? "" : `= ${v.toPrecision(4)}`;
        });
      }
      // camera images: for each camera, the latest image at or before the cursor
      const shown = {};
      for (const im of sig.images) {
        const cam = im.name.replace(/\.png$/, "").split("_").pop();
        if (im.t <= cursor.t + 1e-9 || !(cam in shown)) shown[cam] = im;
      }
      const html = Object.entries(shown).map(([cam, im]) =>
        `<figure><img src="${im.url}" alt="${esc(im.name)}" data-name="${esc(im.name)}"><figcaption>${esc(im.name)} · ${im.t.toFixed(2)} s</figcaption></figure>`).join("");
      if (imagesBox.dataset.html !== html) { imagesBox.innerHTML = html; imagesBox.dataset.html = html; }
      markTransitions();
      syncVideo();
    }
    function markTransitions() {
      const items = [...scopeEl.querySelectorAll("ol.timeline li")];
      if (!sig || !items.length) return;
      let at = 0;  // item 0 is the first state; item i + 1 follows transition i
      sig.transitions.forEach((x, i) => { if (x.t <= cursor.t + 1e-9) at = i + 1; });
      items.forEach((li, i) => li.classList.toggle("at-cursor", i === at));
    }
    function syncVideo() {
      const v = scopeEl.querySelector(".images video");
      if (!v || !v.paused || cursor.t === null) return;
      const want = Math.max(0, cursor.t - sig.t0);
      if (Math.abs((v.currentTime || 0) - want) > 0.05) { try { v.currentTime = want; } catch (e) { /* not loaded */ } }
    }
    document.addEventListener("timeupdate", (e) => {
      if (sig && e.target.matches && e.target.matches(".images video") && scopeEl.contains(e.target) && !e.target.paused) cursor.set(sig.t0 + e.target.currentTime, "video");
    }, true);
    // -- the tree's history (tree_history.json), replayed under the cursor ----------------
    let hist = null;
    const STATUS = {R: "running", S: "success", F: "failure", I: "invalid"};
    function replayTree() {
      const box = scopeEl.querySelector(".tree-graph"), label = scopeEl.querySelector(".tree-replay");
      if (!hist || !hist.entries.length || cursor.t === null || !box) return;
      let e = null;
      for (const x of hist.entries) { if (x[1] === null || x[1] <= cursor.t + 1e-9) e = x; else break; }
      if (!e) e = hist.entries[0];
      const codes = e[2];
      box.querySelectorAll("g.btn").forEach((g) => {
        const st = STATUS[codes[Number(g.dataset.i)]] || "invalid";
        g.setAttribute("class", `btn bt-${st}` + (st === "running" && g.dataset.kind === "leaf" ? " active-leaf" : ""));
      });
      scopeEl.querySelectorAll("table.tree tr.bt").forEach((tr, i) => {
        const st = STATUS[codes[i]] || "invalid"; tr.className = `bt bt-${st}`; tr.dataset.replayStatus = st;
      });
      box.dataset.replayTick = String(e[0]);
      if (label) label.textContent = ` · replaying tick ${e[0]} (t = ${e[1] === null ? "?" : e[1].toFixed(2)} s; ${hist.entries.length} changes kept` +
        (hist.decimated ? `, thinned ${hist.decimated}×` : "") + ")";
    }
    async function loadHistory() {
      if (hist) return;
      try {
        const r = await fetch(`/files/evidence/${encodeURIComponent(sid)}/tree_history.json`, {cache: "no-store"});
        if (r.ok) { hist = await r.json(); replayTree(); }
      } catch (e) { /* none (a session run before the history existed) */ }
    }
    let moved = false;  // until someone moves the cursor, it sits at the end of the session
    document.addEventListener("phyagentos:cursor", (ev) => { if (ev.detail.src !== "init") moved = true; });
    document.addEventListener("phyagentos:cursor", update);
    document.addEventListener("phyagentos:cursor", replayTree);
    document.addEventListener("phyagentos:refreshed", replayTree);
    async function load() {
      const st = scopeEl.querySelector("#session-state, .session-state");
      const finished = st && st.dataset.finished === "true";
      if (loadedFinal || Date.now() - lastFetch < 2000 && !finished) return;
      lastFetch = Date.now();
      try {
        const r = await fetch(`/api/signals/${encodeURIComponent(sid)}`, {cache: "no-store"});
        if (r.status >= 500) throw new Error(`HTTP ${r.status}`);
        const j = await r.json();
        if (!r.ok) { info.textContent = j.error || "no signals"; return; }
        if (scopeEl !== document) {  // compare page: each session's time from its own start (a replan child
          const z = j.t0;             // continues the same world, so its simulated clock starts later)
          const sh = (t) => Math.round((t - z) * 1e4) / 1e4;
          j.plots.forEach((p) => p.lines.forEach((l) => { l.t = l.t.map(sh); }));
          j.events.forEach((e) => { e.t = sh(e.t); }); j.transitions.forEach((x) => { x.t = sh(x.t); });
          j.images.forEach((im) => { im.t = sh(im.t); }); j.frames = j.frames.map(sh);
          j.t1 = sh(j.t1); j.t0 = 0; j.notes.push(`time from the session's start (its simulated clock began at ${z.toFixed(2)} s)`);
        }
        sig = j; loadedFinal = finished;
        if (finished) await loadHistory();
        build();
        if (!sig.plots.length && !finished) {
          info.textContent = "the signals appear when the session ends (its trace.jsonl and frames.npz are written then)";
        }
        if (!moved) cursor.set(sig.t1, "init"); else update();
        tl.dataset.ready = "true";
        retryMs = 1000;
      } catch (e) {
        // keep the last; a failed load (server busy or restarting, a network error) is tried
        // again, 1 s later and then up to every 8 s: a finished session's page gets no further
        // refresh events, so without this its timeline would stay empty
        info.textContent = sig ? info.textContent : `signals not loaded yet (${e.message || e}); retrying`;
        lastFetch = 0;
        setTimeout(load, retryMs);
        retryMs = Math.min(8000, retryMs * 2);
      }
    }
    document.addEventListener("phyagentos:refreshed", () => { load(); markTransitions(); });
    window.addEventListener("resize", () => { if (sig) { build(); update(); } });
  });
})();
