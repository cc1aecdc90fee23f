// rangeplan landing page: one-click example (plain JS, no build step).
"use strict";

(function () {
  const status = document.getElementById("status");
  const canvas = document.getElementById("plot");
  const button = document.getElementById("run");
  const editorLink = document.getElementById("editor-link");

  // the editor runs on the same host; its port comes from /ready (default 8080; a 503 while
  // the workers start still names it)
  fetch("/ready").then(r => r.json()).then(h => {
    const port = h.editor_port || 8080;
    editorLink.href = `${location.protocol}//${location.hostname}:${port}/`;
    editorLink.textContent = `Corridor editor (port ${port})` + (h.editor_port ? "" : " — not running");
  }).catch(() => {});

  function setStatus(text, isError) {
    status.textContent = text;
    status.className = isError ? "err" : "";
  }

  function draw(request, result) {
    const ctx = canvas.getContext("2d");
    const W = canvas.width, H = canvas.height, pad = 30;
    const segs = request.segments;
    const pose = result.pose;
    let xmin = Infinity, xmax = -Infinity, ymin = Infinity, ymax = -Infinity;
    const grow = (x, y) => { xmin = Math.min(xmin, x); xmax = Math.max(xmax, x); ymin = Math.min(ymin, y); ymax = Math.max(ymax, y); };
    segs.forEach(s => { grow(s.lower[0], s.lower[1]); grow(s.upper[0], s.upper[1]); });
    pose.forEach(p => grow(p[0], p[1]));
    const scale = Math.min((W - 2 * pad) / (xmax - xmin || 1), (H - 2 * pad) / (ymax - ymin || 1));
    const X = x => pad + (x - xmin) * scale;
    const Y = y => H - pad - (y - ymin) * scale;  // y up
    ctx.clearRect(0, 0, W, H);
    ctx.lineWidth = 1;
    segs.forEach(s => {
      const w = (s.upper[0] - s.lower[0]) * scale, h = (s.upper[1] - s.lower[1]) * scale;
      if (w > 0 && h > 0) {
        ctx.fillStyle = "rgba(60,130,220,0.18)";
        ctx.strokeStyle = "#3c82dc";
        ctx.fillRect(X(s.lower[0]), Y(s.upper[1]), w, h);
        ctx.strokeRect(X(s.lower[0]), Y(s.upper[1]), w, h);
      }
    });
    ctx.strokeStyle = "#d2461e";
    ctx.lineWidth = 2;
    ctx.beginPath();
    pose.forEach((p, i) => (i ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
    ctx.stroke();
    ctx.fillStyle = "#222";
    [segs[0].lower, segs[segs.length - 1].lower].forEach(p => {
      ctx.beginPath(); ctx.arc(X(p[0]), Y(p[1]), 4, 0, 2 * Math.PI); ctx.fill();
    });
    // scale bar: 10 mm
    ctx.fillStyle = "#555";
    ctx.fillRect(W - pad - 0.01 * scale, H - 12, 0.01 * scale, 2);
    ctx.fillText("10 mm", W - pad - 0.01 * scale, H - 16);
  }

  async function run() {
    button.disabled = true;
    setStatus("planning…");
    try {
      const request = await (await fetch("examples/table1.json")).json();
      const r = await fetch("/v1/plan", {
        method: "POST",
        headers: { "Content-Type": "application/json", "Accept": "application/json" },
        body: JSON.stringify(request),
      });
      const body = await r.json();
      if (!r.ok) {
        const e = body.error || {};
        setStatus(`error ${r.status} ${e.code || ""}: ${e.message || r.statusText}` + (e.field ? ` (field ${e.field})` : ""), true);
        return;
      }
      const m = body.metrics;
      setStatus(`plan ${body.plan_id}: ${m.steps} steps, duration ${m.duration_s.toFixed(2)} s, ` +
                `end error ${(m.end_error_m * 1e3).toFixed(3)} mm, max drive force ${m.max_drive_force_n.toFixed(1)} N, ` +
                `max corridor violation ${(m.max_corridor_violation_m * 1e3).toFixed(3)} mm, ` +
                `compute ${m.compute_ms.toFixed(0)} ms\nfetch it again: GET /v1/plans/${body.plan_id} (add ?format=csv for CSV)`);
      draw(request, body);
    } catch (err) {
      setStatus(`request failed: ${err}`, true);
    } finally {
      button.disabled = false;
    }
  }

  button.addEventListener("click", run);
})();
