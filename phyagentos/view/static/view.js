// phyagentos view: keeps the page's panels live and sends signals. Plain JS, no build step.
(function () {
  "use strict";
  const meta = (name) => (document.querySelector(`meta[name="${name}"]`) || {}).content || "";
  const params = new URLSearchParams(location.search);
  if (params.get("token")) sessionStorage.setItem("phyagentos-token", params.get("token"));
  const token = meta("phyagentos-token") || sessionStorage.getItem("phyagentos-token") || "";
  const scope = meta("phyagentos-scope");

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

  // -- the robot in 3D: server-rendered MuJoCo frames, a timeline, orbit by drag ------
  const box = document.querySelector(".scene3d");
  if (box) {
    const sid = box.dataset.session, img = box.querySelector("img.scene"), slider = box.querySelector("input.frame");
    const info = box.querySelector(".frame-info");
    const cam = {az: 140, el: -25, dist: 1.9};
    let times = [], live = true, pending = null, loading = false, lastLive = 0;
    function src() {
      const f = live ? "live" : slider.value;
      return `/api/scene/${encodeURIComponent(sid)}.png?frame=${f}&az=${cam.az.toFixed(1)}&el=${cam.el.toFixed(1)}&dist=${cam.dist.toFixed(2)}`;
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
          img.dataset.source = s; img.dataset.t = t;
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
    slider.addEventListener("input", () => { live = false; show(); });
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
})();
