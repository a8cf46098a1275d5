// phyagentos view: keeps the page's panels live and sends signals. Plain JS, no build step.
(function () {
  "use strict";
  const meta = (name) => (document.querySelector(`meta[name="${name}"]`) || {}).content || "";
  const params = new URLSearchParams(location.search);
  if (params.get("token")) sessionStorage.setItem("phyagentos-token", params.get("token"));
  const token = meta("phyagentos-token") || sessionStorage.getItem("phyagentos-token") || "";
  const scope = meta("phyagentos-scope");

  // -- panels: re-fetch every [data-fragment] on each change event --------------------
  let inflight = false, again = false;
  async function refresh() {
    if (inflight) { again = true; return; }
    inflight = true;
    try {
      await Promise.all([...document.querySelectorAll("[data-fragment]")].map(async (el) => {
        try {
          const r = await fetch(el.dataset.fragment, {cache: "no-store"});
          const html = await r.text();
          if (el.dataset.html !== html) { el.innerHTML = html; el.dataset.html = html; }
        } catch (e) { /* server gone: the live dot shows it */ }
      }));
      document.dispatchEvent(new Event("phyagentos:refreshed"));
    } finally {
      inflight = false;
      if (again) { again = false; refresh(); }
    }
  }
  const dot = document.getElementById("live");
  function connect() {
    const es = new EventSource("/events" + (scope ? "?session=" + encodeURIComponent(scope) : ""));
    es.onopen = () => { dot.className = "live on"; refresh(); };
    es.addEventListener("change", refresh);
    es.onerror = () => { dot.className = "live off"; };
  }
  refresh();
  connect();

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
      const terminal = st && ["succeeded", "failed", "cancelled", "rejected", "timed_out", "awaiting_replan"].includes(st.dataset.state);
      await loadFrames();
      if (terminal && times.length && live) { live = false; slider.value = slider.max; show(); return; }
      // Following a live session: at most one server render per second, whatever the event rate.
      const now = Date.now();
      if (live && now - lastLive >= 1000) { lastLive = now; show(); }
      else if (!img.src) { show(); }
    });
  }
})();
