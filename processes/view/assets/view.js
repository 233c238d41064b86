// mole view: draws the frames the view sends over its WebSocket (docs/view.md, "Protocol").
"use strict";
(() => {
  const state = {
    frames: 0,
    connected: false,
    robot: null,
    filledCells: 0,
    errors: [],
    frame: null,
    arena: null,
    grids: {},
    latency: [],
    goalSent: null,
  };
  const LATENCY_HISTORY_MS = 60000;

  // What tests read: frames received, the true pose last drawn, explored cells, errors.
  Object.defineProperty(window, "moleView", {
    value: Object.freeze({
      get frames() { return state.frames; },
      get connected() { return state.connected; },
      get robot() { return state.robot && { ...state.robot }; },
      get filledCells() { return state.filledCells; },
      get tick() { return state.frame ? state.frame.tick : null; },
      get errors() { return state.errors.slice(); },
    }),
  });
  const fail = (what) => { state.errors.push(String(what)); };
  window.addEventListener("error", (e) => fail(e.message));
  window.addEventListener("unhandledrejection", (e) => fail(e.reason));

  const $ = (id) => document.getElementById(id);
  const arenaCanvas = $("arena");
  let socket = null;

  // ---- grids: one offscreen canvas per grid, painted tile by tile ----
  const PALETTE = {
    frontier: [[0, 0, 0, 0], [255, 255, 255, 255], [51, 51, 51, 255]],
    contact: [[0, 0, 0, 0], [224, 112, 0, 230]],
  };

  function newGrid(u) {
    const canvas = document.createElement("canvas");
    canvas.width = u.width;
    canvas.height = u.height;
    const ctx = canvas.getContext("2d");
    return {
      width: u.width, height: u.height, resolution: u.resolution,
      originX: u.origin_x, originY: u.origin_y, tick: u.tick,
      cells: new Uint8Array(u.width * u.height), filled: 0,
      canvas, ctx, image: ctx.createImageData(u.width, u.height),
    };
  }

  function applyGrid(name, u) {
    let g = state.grids[name];
    if (u.whole || !g || g.width !== u.width || g.height !== u.height) {
      g = state.grids[name] = newGrid(u);
    }
    g.tick = u.tick;
    const palette = PALETTE[name];
    const px = g.image.data;
    for (const t of u.tiles) {
      const bytes = atob(t.cells);
      for (let r = 0; r < t.h; r++) {
        // Grid row 0 is at the bottom (origin_y); the image's row 0 at the top.
        const imageRow = g.height - 1 - (t.y + r);
        for (let c = 0; c < t.w; c++) {
          const i = (t.y + r) * g.width + t.x + c;
          const value = bytes.charCodeAt(r * t.w + c);
          g.filled += (value !== 0) - (g.cells[i] !== 0);
          g.cells[i] = value;
          const color = palette[value] || palette[0];
          const p = 4 * (imageRow * g.width + t.x + c);
          px[p] = color[0]; px[p + 1] = color[1]; px[p + 2] = color[2]; px[p + 3] = color[3];
        }
      }
    }
    g.ctx.putImageData(g.image, 0, 0);
  }

  // ---- the arena ----
  function fitCanvas(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr));
    const h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    return [w, h, dpr];
  }

  // World (m, y up) to canvas pixels.
  function transform(arena, w, h) {
    const pad = 10;
    const scale = Math.min((w - 2 * pad) / arena.width, (h - 2 * pad) / arena.height);
    const x0 = (w - scale * arena.width) / 2;
    const y0 = (h + scale * arena.height) / 2;
    return {
      scale,
      x: (x) => x0 + scale * x,
      y: (y) => y0 - scale * y,
      toWorld: (px, py) => [(px - x0) / scale, (y0 - py) / scale],
    };
  }

  // The 2σ ellipse of the covariance [σxx, σxy, σyy] around (x, y).
  function ellipse(ctx, T, x, y, cov) {
    const [a, b, c] = cov;
    const mid = (a + c) / 2;
    const d = Math.sqrt(((a - c) / 2) ** 2 + b * b);
    const r1 = 2 * Math.sqrt(Math.max(mid + d, 0));
    const r2 = 2 * Math.sqrt(Math.max(mid - d, 0));
    const angle = 0.5 * Math.atan2(2 * b, a - c);
    if (!isFinite(r1) || !isFinite(r2)) return;
    ctx.beginPath();
    ctx.ellipse(T.x(x), T.y(y), Math.max(r1 * T.scale, 1), Math.max(r2 * T.scale, 1), -angle, 0, 2 * Math.PI);
    ctx.stroke();
  }

  function drawArena() {
    const f = state.frame;
    const arena = state.arena;
    if (!f || !arena) return;
    const ctx = arenaCanvas.getContext("2d");
    const [w, h, dpr] = fitCanvas(arenaCanvas);
    const T = transform(arena, w, h);
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, w, h);
    ctx.fillStyle = "#cfd8dc";
    ctx.fillRect(T.x(0), T.y(arena.height), arena.width * T.scale, arena.height * T.scale);
    ctx.imageSmoothingEnabled = false;
    for (const name of ["frontier", "contact"]) {
      const g = state.grids[name];
      if (!g) continue;
      ctx.drawImage(g.canvas, T.x(g.originX), T.y(g.originY + g.height * g.resolution),
        g.width * g.resolution * T.scale, g.height * g.resolution * T.scale);
    }
    ctx.lineWidth = Math.max(1, dpr);
    ctx.strokeStyle = "rgba(204,0,0,0.8)";
    for (const [cx, cy, side] of arena.obstacles) {
      ctx.strokeRect(T.x(cx - side / 2), T.y(cy + side / 2), side * T.scale, side * T.scale);
    }
    ctx.strokeStyle = "#555";
    ctx.strokeRect(T.x(0), T.y(arena.height), arena.width * T.scale, arena.height * T.scale);
    ctx.fillStyle = "#6d4c41";
    for (const [bx, by] of arena.beacons) {
      ctx.beginPath();
      ctx.moveTo(T.x(bx), T.y(by) - 6 * dpr);
      ctx.lineTo(T.x(bx) - 5 * dpr, T.y(by) + 4 * dpr);
      ctx.lineTo(T.x(bx) + 5 * dpr, T.y(by) + 4 * dpr);
      ctx.fill();
    }
    if (f.particles) {
      ctx.fillStyle = "rgba(142,36,170,0.5)";
      const xy = f.particles.xy;
      for (let i = 0; i + 1 < xy.length; i += 2) {
        ctx.fillRect(T.x(xy[i]) - dpr, T.y(xy[i + 1]) - dpr, 2 * dpr, 2 * dpr);
      }
    }
    if (f.scan) {
      const s = f.scan;
      ctx.strokeStyle = "rgba(249,168,37,0.25)";
      ctx.fillStyle = "rgba(230,81,0,0.9)";
      const ox = T.x(s.x), oy = T.y(s.y);
      ctx.beginPath();
      const ends = [];
      s.ranges.forEach((r, i) => {
        if (r === null) return;
        const a = s.theta + s.angle_min + i * s.angle_increment;
        const ex = T.x(s.x + r * Math.cos(a)), ey = T.y(s.y + r * Math.sin(a));
        ctx.moveTo(ox, oy);
        ctx.lineTo(ex, ey);
        if (r < s.range_max) ends.push([ex, ey]);
      });
      ctx.stroke();
      for (const [ex, ey] of ends) ctx.fillRect(ex - dpr, ey - dpr, 2 * dpr, 2 * dpr);
    }
    if (f.plan) {
      ctx.strokeStyle = "#2e7d32";
      ctx.lineWidth = 2 * dpr;
      ctx.beginPath();
      f.plan.path.forEach(([x, y], i) => (i ? ctx.lineTo(T.x(x), T.y(y)) : ctx.moveTo(T.x(x), T.y(y))));
      ctx.stroke();
      if (f.plan.frontier) {
        const [x, y] = f.plan.frontier;
        ctx.beginPath();
        ctx.arc(T.x(x), T.y(y), 6 * dpr, 0, 2 * Math.PI);
        ctx.stroke();
      }
      if (f.plan.goal) cross(ctx, T, f.plan.goal, "#d81b60", 8 * dpr);
    }
    if (arena.goal) cross(ctx, T, arena.goal, "rgba(216,27,96,0.5)", 6 * dpr);
    if (state.goalSent) cross(ctx, T, state.goalSent, "#1565c0", 5 * dpr);
    ctx.lineWidth = Math.max(1, dpr);
    ctx.strokeStyle = "#8e24aa";
    ctx.fillStyle = "#8e24aa";
    for (const l of f.landmarks) {
      ctx.fillRect(T.x(l.x) - 2 * dpr, T.y(l.y) - 2 * dpr, 4 * dpr, 4 * dpr);
      ellipse(ctx, T, l.x, l.y, l.cov);
    }
    if (f.pose) {
      ctx.strokeStyle = "#1565c0";
      ctx.lineWidth = 2 * dpr;
      ellipse(ctx, T, f.pose.x, f.pose.y, f.pose.cov);
      heading(ctx, T, f.pose, arena.robot_radius);
    }
    if (f.truth) {
      const t = f.truth;
      ctx.fillStyle = t.in_contact ? "#c62828" : "#000";
      ctx.beginPath();
      ctx.arc(T.x(t.x), T.y(t.y), Math.max(arena.robot_radius * T.scale, 3 * dpr), 0, 2 * Math.PI);
      ctx.fill();
      ctx.strokeStyle = "#fff";
      ctx.lineWidth = 2 * dpr;
      heading(ctx, T, t, arena.robot_radius);
      state.robot = { x: t.x, y: t.y, theta: t.theta, tick: t.tick };
    }
  }

  function cross(ctx, T, [x, y], color, size) {
    ctx.strokeStyle = color;
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(T.x(x) - size, T.y(y) - size); ctx.lineTo(T.x(x) + size, T.y(y) + size);
    ctx.moveTo(T.x(x) - size, T.y(y) + size); ctx.lineTo(T.x(x) + size, T.y(y) - size);
    ctx.stroke();
  }

  function heading(ctx, T, p, radius) {
    ctx.beginPath();
    ctx.moveTo(T.x(p.x), T.y(p.y));
    ctx.lineTo(T.x(p.x + 1.5 * radius * Math.cos(p.theta)), T.y(p.y + 1.5 * radius * Math.sin(p.theta)));
    ctx.stroke();
  }

  // ---- the plots ----
  function drawLatency() {
    const canvas = $("latency");
    const [w, h, dpr] = fitCanvas(canvas);
    const ctx = canvas.getContext("2d");
    ctx.clearRect(0, 0, w, h);
    const now = performance.now();
    const points = state.latency.filter((p) => now - p.t <= LATENCY_HISTORY_MS);
    state.latency = points;
    if (!points.length) return;
    const top = Math.max(...points.map((p) => p.p99), 1) * 1.1;
    const x = (t) => w * (1 - (now - t) / LATENCY_HISTORY_MS);
    const y = (v) => h - 4 * dpr - (h - 16 * dpr) * (v / top);
    for (const [key, color] of [["p99", "#c62828"], ["p50", "#1565c0"]]) {
      ctx.strokeStyle = color;
      ctx.lineWidth = 1.5 * dpr;
      ctx.beginPath();
      points.forEach((p, i) => (i ? ctx.lineTo(x(p.t), y(p[key])) : ctx.moveTo(x(p.t), y(p[key]))));
      ctx.stroke();
    }
    ctx.fillStyle = "#555";
    ctx.font = `${11 * dpr}px system-ui`;
    ctx.fillText(`${Math.round(top)} µs`, 4 * dpr, 12 * dpr);
    ctx.fillText("60 s", 4 * dpr, h - 4 * dpr);
  }

  function drawBars(id, rows, unit, scaleTo) {
    const canvas = $(id);
    const ctx = canvas.getContext("2d");
    const dpr = window.devicePixelRatio || 1;
    const rowHeight = 15 * dpr;
    canvas.style.height = `${Math.max(rows.length, 1) * 15 + 6}px`;
    const [w, h] = fitCanvas(canvas);
    ctx.clearRect(0, 0, w, h);
    const top = Math.max(scaleTo, ...rows.map(([, v]) => v));
    const labelWidth = 150 * dpr;
    ctx.font = `${11 * dpr}px system-ui`;
    ctx.textBaseline = "middle";
    rows.forEach(([label, value], i) => {
      const y = 3 * dpr + i * rowHeight;
      ctx.fillStyle = "#90a4ae";
      ctx.fillRect(labelWidth, y + 2 * dpr, (w - labelWidth - 60 * dpr) * (value / top), rowHeight - 4 * dpr);
      ctx.fillStyle = "#222";
      ctx.fillText(label, 4 * dpr, y + rowHeight / 2);
      ctx.fillText(`${value.toFixed(1)} ${unit}`, w - 56 * dpr, y + rowHeight / 2);
    });
  }

  function describe(e) {
    if (e.kind === "fault") {
      const how = e.fault === "delay" ? ` by ${e.delay_ms} ms`
        : e.fault === "drop" || e.fault === "corrupt" ? ` ${e.fraction} of the samples` : "";
      const long = e.duration_s > 0 ? ` for ${e.duration_s} s` : "";
      return `tick ${e.tick}: fault ${e.id}: ${e.fault} ${e.target}${how}${long}`;
    }
    const who = e.role || e.topic || "";
    const pids = e.old_pid ? ` (pid ${e.old_pid} → ${e.pid})` : e.pid ? ` (pid ${e.pid})` : "";
    const count = e.count ? ` ${e.count} samples` : "";
    return `tick ${e.tick}: ${e.kind} ${who}${pids}${count}`;
  }

  function drawPanel(f) {
    if (f.latency) {
      state.latency.push({ t: performance.now(), p50: f.latency.p50_us, p99: f.latency.p99_us });
      document.querySelector(".p50").textContent = f.latency.p50_us.toFixed(0);
      document.querySelector(".p99").textContent = f.latency.p99_us.toFixed(0);
    }
    drawLatency();
    drawBars("rates", f.topics.map((t) => [t.topic, t.rate_hz]), "Hz", 1);
    drawBars("cpu", f.cpu.map((c) => [c.process, c.percent]), "%", 100);
    const list = $("events");
    const items = f.events.slice().reverse().map(describe);
    if (list.dataset.total !== String(f.events_total)) {
      list.dataset.total = String(f.events_total);
      list.replaceChildren(...items.map((text) => {
        const li = document.createElement("li");
        li.textContent = text;
        return li;
      }));
    }
    const paused = f.ended ? " · ended" : "";
    $("status").textContent =
      `tick ${f.tick} · ${f.time_s.toFixed(2)} s · ${f.mode} · frame ${f.seq}` +
      ` · rejected inputs ${f.rejected_inputs}${paused}`;
    $("controls").hidden = !(f.controls && f.mode === "lockstep") || !!f.timeline;
    $("hint").textContent = f.timeline
      ? "A recording: play, pause, seek and set the speed in the timeline above."
      : f.controls
        ? "Click on the map to send a goal to a goal-seeking planner (operator/goal)."
        : "Controls are off (--no-controls).";
    drawTimeline(f);
  }

  // ---- a recording's timeline (absent in a live view) ----
  let seeking = false;
  function drawTimeline(f) {
    const t = f.timeline;
    $("timeline").hidden = !t;
    if (!t) return;
    const dt = state.arena ? state.arena.dt : 0;
    $("play").textContent = t.playing ? "pause" : "play";
    const seek = $("seek");
    seek.min = String(t.first_tick);
    seek.max = String(t.last_tick);
    if (!seeking) seek.value = String(t.tick);
    if (document.activeElement !== $("speed")) $("speed").value = String(t.speed);
    $("clock").textContent =
      `${(t.tick * dt).toFixed(2)} / ${(t.last_tick * dt).toFixed(2)} s (tick ${t.tick})`;
  }

  // ---- the connection ----
  function onFrame(f) {
    if (f.type !== "frame") return;
    state.frames += 1;
    if (f.full) { state.arena = f.arena; state.grids = {}; }
    for (const [name, update] of Object.entries(f.grids)) applyGrid(name, update);
    state.filledCells = state.grids.frontier ? state.grids.frontier.filled : 0;
    // A seek backwards: the latency plot starts afresh.
    if (f.timeline && state.frame && f.tick < state.frame.tick) state.latency = [];
    state.frame = f;
    drawArena();
    drawPanel(f);
  }

  function send(input) {
    if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(input));
  }

  function connect() {
    const url = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`;
    socket = new WebSocket(url);
    socket.onopen = () => { state.connected = true; };
    socket.onmessage = (m) => {
      try { onFrame(JSON.parse(m.data)); } catch (e) { fail(e && e.stack ? e.stack : e); }
    };
    socket.onclose = () => {
      state.connected = false;
      $("status").textContent = "disconnected: the view or the stack ended (retrying)";
      setTimeout(connect, 1000);
    };
  }

  arenaCanvas.addEventListener("click", (e) => {
    const f = state.frame;
    if (!f || !f.controls || !state.arena) return;
    const dpr = window.devicePixelRatio || 1;
    const rect = arenaCanvas.getBoundingClientRect();
    const T = transform(state.arena, arenaCanvas.width, arenaCanvas.height);
    const [x, y] = T.toWorld((e.clientX - rect.left) * dpr, (e.clientY - rect.top) * dpr);
    if (x < 0 || y < 0 || x > state.arena.width || y > state.arena.height) return;
    state.goalSent = [x, y];
    send({ goal: { x, y } });
  });
  $("pause").addEventListener("click", () => send({ pace: "pause" }));
  $("run").addEventListener("click", () => send({ pace: "run" }));
  $("step").addEventListener("click", () => {
    const steps = Math.min(100000, Math.max(1, Math.round(Number($("steps").value) || 1)));
    send({ pace: "step", steps });
  });
  $("play").addEventListener("click", () => {
    const t = state.frame && state.frame.timeline;
    send({ timeline: { op: t && t.playing ? "pause" : "play" } });
  });
  const seek = $("seek");
  seek.addEventListener("input", () => {
    seeking = true;
    send({ timeline: { op: "seek", tick: Number(seek.value) } });
  });
  seek.addEventListener("change", () => { seeking = false; });
  $("speed").addEventListener("change", () => {
    send({ timeline: { op: "speed", speed: Number($("speed").value) } });
  });
  window.addEventListener("resize", () => { drawArena(); if (state.frame) drawPanel(state.frame); });
  connect();
})();
