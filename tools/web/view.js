// nao-formation live view (docs/view.md: a page in the browser with nothing to install).
//
// A client of the Foxglove WebSocket protocol as foxglove-sdk's server speaks it
// (subprotocol "foxglove.sdk.v1"): text frames are JSON ops (serverInfo, advertise,
// unadvertise, status), binary frames with opcode 1 are message data:
//   u8 opcode | u32 LE subscription id | u64 LE log time (ns) | payload (here: JSON).
// The page subscribes to every JSON channel it understands and draws:
//   /scene, /scene/obstacles, /scene/plan   foxglove.SceneUpdate, top-down on a canvas
//                                            (and each robot's track walked, from /scene)
//   /robots/{id}/status                      nao.Status: each robot's phase, wave, progress
//   /nao/{id}/camera                         foxglove.CompressedImage (JPEG/PNG)
//   /nao/{id}/camera/annotations             foxglove.ImageAnnotations over that image
//   /log                                     foxglove.Log, the latest lines
// window.naoView holds what the page knows (tests and the latency measurement read it).
"use strict";

(function () {
  const PROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"];
  const LAYERS = ["/scene/obstacles", "/scene/plan", "/scene"]; // drawn in this order
  const CAMERA = /^\/nao\/(\d+)\/camera$/;
  const ANNOTATIONS = /^\/nao\/(\d+)\/camera\/annotations$/;
  const STATUS = /^\/robots\/(\d+)\/status$/;
  const MAX_LOG = 40;

  const view = {
    connected: false,
    url: "",
    server: "",
    topics: [], // advertised topics
    received: 0, // message frames
    tSimNs: 0, // latest log time of /scene
    robots: {}, // id -> {x, y, h, phase, wave}
    entities: {}, // layer -> id -> entity
    draws: [], // [log time ns of the /scene drawn, Date.now() when drawn]
    targets: [], // the plan's targets on the map at the latest draw: [robot id, x, y] (world m)
    error: "",
  };
  window.naoView = view;

  const channels = new Map(); // channel id -> channel
  const subs = new Map(); // subscription id -> channel
  const heard = new Set(); // subscription ids that brought a message
  const asked = new Map(); // subscription id -> [Date.now() when asked, how many times before]
  let nextSub = 1;
  let dirty = false;
  let sceneNs = 0; // log time of the latest /scene not yet drawn
  const decoder = new TextDecoder();
  const $ = (id) => document.getElementById(id);

  // ------------------------------------------------------------- connection

  async function wsUrl() {
    const q = new URLSearchParams(location.search).get("ws");
    if (q) return q;
    try {
      const r = await fetch("config.json", { cache: "no-store" });
      if (r.ok) {
        const c = await r.json();
        if (c.ws) return c.ws;
      }
    } catch (e) {
      /* a page opened as a file: fall back to the default server */
    }
    return "ws://127.0.0.1:8765";
  }

  function setStatus(state, text) {
    const s = $("status");
    s.dataset.state = state;
    s.textContent = text;
  }

  function connect(url) {
    view.url = url;
    let ws;
    try {
      ws = new WebSocket(url, PROTOCOLS);
    } catch (e) {
      view.error = String(e);
      setStatus("error", "cannot connect to " + url);
      return;
    }
    ws.binaryType = "arraybuffer";
    ws.onopen = () => {
      view.connected = true;
      setStatus("live", "live: " + url);
    };
    // A subscription the server refused (it can reach the server before the channel it
    // just advertised: foxglove-sdk logs "attempted to subscribe to unknown channel")
    // brings nothing: ask again for every one still silent, 3 s after it was asked, then
    // 6, 12, 24, 48 s (a topic may also be silent because nothing is sent on it). The
    // latched topics (obstacles, plan) are re-sent every second, so a second try gets
    // them; `/scene` streams, so a silent one was refused (a browser test saw a page
    // draw nothing for a whole run when only `/scene/...` topics were asked again).
    // The loop runs over a copy: a Map's iterator also visits the entries added while it
    // runs, and each fresh subscription is silent too, so iterating `subs` itself never
    // ended (the tab's heap reached 3 GB in 40 s: chromium's "V8 javascript OOM").
    const retry = setInterval(() => {
      if (ws.readyState !== WebSocket.OPEN) return clearInterval(retry);
      const now = Date.now();
      const again = [];
      const drop = [];
      for (const [id, ch] of [...subs]) {
        if (heard.has(id) || !channels.has(ch.id)) continue;
        const [when, tries] = asked.get(id) || [now, 0];
        if (now - when < 3000 * 2 ** Math.min(tries, 4) - 500) continue;
        drop.push(id);
        subs.delete(id);
        asked.delete(id);
        const fresh = nextSub++;
        subs.set(fresh, ch);
        asked.set(fresh, [now, tries + 1]);
        again.push({ id: fresh, channelId: ch.id });
      }
      if (drop.length) ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: drop }));
      if (again.length) ws.send(JSON.stringify({ op: "subscribe", subscriptions: again }));
    }, 3000);
    ws.onclose = () => {
      view.connected = false;
      setStatus("closed", "disconnected (run over?) – retrying");
      channels.clear();
      subs.clear();
      asked.clear();
      setTimeout(() => connect(url), 2000);
    };
    ws.onerror = () => {
      view.error = "websocket error";
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === "string") onOp(ws, JSON.parse(ev.data));
      else onData(new DataView(ev.data));
    };
  }

  function wanted(ch) {
    return (
      ch.encoding === "json" &&
      (LAYERS.includes(ch.topic) ||
        ch.topic === "/log" ||
        STATUS.test(ch.topic) ||
        ANNOTATIONS.test(ch.topic) ||
        (CAMERA.test(ch.topic) && ch.schemaName === "foxglove.CompressedImage"))
    );
  }

  function onOp(ws, op) {
    if (op.op === "serverInfo") {
      view.server = op.name || "";
    } else if (op.op === "advertise") {
      const add = [];
      for (const ch of op.channels) {
        channels.set(ch.id, ch);
        if (!view.topics.includes(ch.topic)) view.topics.push(ch.topic);
        if (wanted(ch)) {
          const id = nextSub++;
          subs.set(id, ch);
          asked.set(id, [Date.now(), 0]);
          add.push({ id: id, channelId: ch.id });
        }
      }
      view.topics.sort();
      if (add.length) ws.send(JSON.stringify({ op: "subscribe", subscriptions: add }));
    } else if (op.op === "unadvertise") {
      for (const id of op.channelIds) channels.delete(id);
    } else if (op.op === "status" && op.level >= 2) {
      addLog(2, "server", op.message);
    }
  }

  function onData(dv) {
    if (dv.byteLength < 13 || dv.getUint8(0) !== 1) return;
    const sub = dv.getUint32(1, true);
    const ch = subs.get(sub);
    if (!ch) return;
    heard.add(sub);
    asked.delete(sub);
    const tNs = Number(dv.getBigUint64(5, true));
    let msg;
    try {
      msg = JSON.parse(decoder.decode(new Uint8Array(dv.buffer, dv.byteOffset + 13)));
    } catch (e) {
      return;
    }
    view.received++;
    take(ch.topic, msg, tNs);
  }

  // ------------------------------------------------------------- intake

  function take(topic, msg, tNs) {
    let m;
    if (LAYERS.includes(topic)) {
      const layer = (view.entities[topic] = view.entities[topic] || {});
      for (const d of msg.deletions || []) {
        if (d.type === 1) view.entities[topic] = {};
        else delete layer[d.id];
      }
      for (const e of msg.entities || []) {
        view.entities[topic][e.id] = e;
        if (topic === "/scene") robotFromEntity(e);
      }
      if (topic === "/scene") {
        view.tSimNs = Math.max(view.tSimNs, tNs);
        sceneNs = tNs;
      }
      redraw();
    } else if ((m = STATUS.exec(topic))) {
      const r = robot(Number(m[1]));
      Object.assign(r, {
        phase: msg.phase,
        wave: msg.wave,
        progress: msg.progress,
        detail: msg.detail,
        error: msg.error,
      });
      card(Number(m[1]));
    } else if ((m = CAMERA.exec(topic))) {
      cameraImage(Number(m[1]), msg);
    } else if ((m = ANNOTATIONS.exec(topic))) {
      cameraAnnotations(Number(m[1]), msg);
    } else if (topic === "/log") {
      addLog(msg.level, msg.name, msg.message, tNs);
    }
  }

  function robot(id) {
    if (!view.robots[id]) view.robots[id] = { id: id, phase: "-", wave: -1, progress: 0 };
    return view.robots[id];
  }

  function yawOf(q) {
    return 2 * Math.atan2(q.z, q.w);
  }

  function robotFromEntity(e) {
    const m = /^robot\/(\d+)$/.exec(e.id);
    if (!m || !e.cylinders.length) return;
    const r = robot(Number(m[1]));
    const p = e.cylinders[0].pose;
    r.x = p.position.x;
    r.y = p.position.y;
    r.trail = r.trail || [];
    const last = r.trail[r.trail.length - 1];
    if (!last || Math.hypot(last[0] - r.x, last[1] - r.y) > 0.01) r.trail.push([r.x, r.y]);
    if (r.trail.length > 5000) r.trail.splice(0, 1000);
    r.h = yawOf(p.orientation);
    r.colour = rgba(e.cylinders[0].color, 1);
    card(r.id);
  }

  // ------------------------------------------------------------- robots panel

  function card(id) {
    const r = view.robots[id];
    let li = document.querySelector(`#robots li[data-robot="${id}"]`);
    if (!li) {
      li = document.createElement("li");
      li.className = "robot";
      li.dataset.robot = String(id);
      li.innerHTML =
        '<span class="id"></span><span class="phase"></span>' +
        '<span class="bar"><b></b></span><span class="detail"></span>';
      const list = $("robots");
      const after = [...list.children].find((c) => Number(c.dataset.robot) > id);
      list.insertBefore(li, after || null);
    }
    if (r.colour) li.style.setProperty("--c", r.colour);
    li.querySelector(".id").textContent = String(id);
    li.querySelector(".phase").textContent =
      r.phase + (r.wave !== undefined && r.wave >= 0 ? " w" + r.wave : "");
    li.dataset.phase = r.phase;
    li.classList.toggle("failed", r.phase === "failed" || !!r.error);
    li.querySelector(".bar b").style.width = Math.round(100 * (r.progress || 0)) + "%";
    const d = li.querySelector(".detail");
    d.textContent = r.error || r.detail || (r.x !== undefined
      ? `x ${r.x.toFixed(2)} y ${r.y.toFixed(2)} m, heading ${(r.h * 180 / Math.PI).toFixed(0)}°`
      : "");
    d.classList.toggle("error", !!r.error);
  }

  // ------------------------------------------------------------- cameras

  function cameraCell(id) {
    let fig = document.querySelector(`#cameras figure[data-robot="${id}"]`);
    if (!fig) {
      const none = document.querySelector("#cameras .none");
      if (none) none.remove();
      fig = document.createElement("figure");
      fig.className = "camera";
      fig.dataset.robot = String(id);
      fig.style.margin = "0";
      fig.innerHTML = "<img alt=''><canvas></canvas><figcaption></figcaption>";
      fig.querySelector("figcaption").textContent = "robot " + id;
      const box = $("cameras");
      const after = [...box.children].find((c) => Number(c.dataset.robot) > id);
      box.insertBefore(fig, after || null);
    }
    return fig;
  }

  function cameraImage(id, msg) {
    const fig = cameraCell(id);
    const kind = (msg.format || "jpeg").replace(/^image\//, "");
    fig.querySelector("img").src = `data:image/${kind};base64,${msg.data}`;
  }

  function cameraAnnotations(id, msg) {
    const fig = cameraCell(id);
    const img = fig.querySelector("img");
    const cv = fig.querySelector("canvas");
    const w = img.naturalWidth || 320;
    const h = img.naturalHeight || 240;
    cv.width = w;
    cv.height = h;
    cv.style.height = (240 * h) / w + "px";
    const g = cv.getContext("2d");
    g.clearRect(0, 0, w, h);
    g.lineWidth = 2;
    for (const c of msg.circles || []) {
      g.strokeStyle = rgba(c.outline_color, 1);
      g.beginPath();
      g.arc(c.position.x, c.position.y, c.diameter / 2, 0, 2 * Math.PI);
      g.stroke();
    }
    for (const p of msg.points || []) {
      g.strokeStyle = rgba(p.outline_color, 1);
      g.lineWidth = p.thickness || 2;
      const pts = p.points;
      g.beginPath();
      if (p.type === 4) {
        for (let k = 0; k + 1 < pts.length; k += 2) {
          g.moveTo(pts[k].x, pts[k].y);
          g.lineTo(pts[k + 1].x, pts[k + 1].y);
        }
      } else {
        pts.forEach((q, k) => (k ? g.lineTo(q.x, q.y) : g.moveTo(q.x, q.y)));
        if (p.type === 2) g.closePath();
      }
      g.stroke();
    }
    for (const t of msg.texts || []) {
      g.font = `${t.font_size || 12}px sans-serif`;
      g.fillStyle = rgba(t.text_color, 1);
      g.fillText(t.text, t.position.x, t.position.y);
    }
  }

  // ------------------------------------------------------------- log

  function addLog(level, name, text, tNs) {
    const li = document.createElement("li");
    li.className = "l" + level;
    const t = tNs ? (tNs / 1e9).toFixed(1).padStart(6) + " s " : "";
    li.textContent = `${t}${name}: ${text}`;
    const log = $("log");
    log.insertBefore(li, log.firstChild);
    while (log.children.length > MAX_LOG) log.lastChild.remove();
  }

  // ------------------------------------------------------------- the map

  function rgba(c, alpha) {
    if (!c) return "#888";
    const k = (v) => Math.round(255 * v);
    return `rgba(${k(c.r)},${k(c.g)},${k(c.b)},${alpha === undefined ? c.a : alpha})`;
  }

  function redraw() {
    if (!dirty) {
      dirty = true;
      requestAnimationFrame(draw);
    }
  }

  function bounds() {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const grow = (x, y, r) => {
      x0 = Math.min(x0, x - r); x1 = Math.max(x1, x + r);
      y0 = Math.min(y0, y - r); y1 = Math.max(y1, y + r);
    };
    for (const layer of LAYERS) {
      for (const e of Object.values(view.entities[layer] || {})) {
        for (const c of e.cylinders) grow(c.pose.position.x, c.pose.position.y, c.size.x / 2);
        for (const l of e.lines) for (const p of l.points) grow(p.x, p.y, 0);
      }
    }
    if (!isFinite(x0)) return [-2, -2, 2, 2];
    const pad = 0.6;
    return [x0 - pad, y0 - pad, x1 + pad, y1 + pad];
  }

  function draw() {
    dirty = false;
    const cv = $("map");
    const g = cv.getContext("2d");
    const W = cv.width, H = cv.height;
    g.clearRect(0, 0, W, H);
    const [x0, y0, x1, y1] = bounds();
    const s = Math.min(W / (x1 - x0), H / (y1 - y0));
    const ox = (W - s * (x1 - x0)) / 2, oy = (H - s * (y1 - y0)) / 2;
    const X = (x) => ox + s * (x - x0);
    const Y = (y) => H - oy - s * (y - y0);
    grid(g, X, Y, x0, y0, x1, y1);
    const targets = [];
    for (const r of Object.values(view.robots)) {
      if (!r.trail || r.trail.length < 2) continue; // the track walked (ground truth)
      g.strokeStyle = r.colour || "#888";
      g.globalAlpha = 0.5;
      g.lineWidth = 1.5;
      g.beginPath();
      r.trail.forEach((q, k) => (k ? g.lineTo(X(q[0]), Y(q[1])) : g.moveTo(X(q[0]), Y(q[1]))));
      g.stroke();
      g.globalAlpha = 1;
    }
    for (const layer of LAYERS) {
      const plan = layer === "/scene/plan";
      const ents = view.entities[layer] || {};
      for (const id of Object.keys(ents).sort()) {
        const e = ents[id];
        for (const l of e.lines) {
          g.strokeStyle = rgba(l.color);
          g.lineWidth = Math.max(1, s * l.thickness);
          g.setLineDash(plan && id.startsWith("plan/robot/") ? [6, 4] : []);
          g.beginPath();
          const pts = l.points;
          if (l.type === 2) {
            for (let k = 0; k + 1 < pts.length; k += 2) {
              g.moveTo(X(pts[k].x), Y(pts[k].y));
              g.lineTo(X(pts[k + 1].x), Y(pts[k + 1].y));
            }
          } else {
            pts.forEach((p, k) => (k ? g.lineTo(X(p.x), Y(p.y)) : g.moveTo(X(p.x), Y(p.y))));
            if (l.type === 1) g.closePath();
          }
          g.stroke();
          if (plan && id.startsWith("plan/robot/") && pts.length) {
            g.setLineDash([]);
            g.beginPath(); // the believed start: where the fleet's records put the robot
            g.arc(X(pts[0].x), Y(pts[0].y), 4, 0, 2 * Math.PI);
            g.stroke();
          }
        }
        g.setLineDash([]);
        for (const c of e.cylinders) {
          const r = Math.max(2, (s * c.size.x) / 2);
          g.beginPath();
          g.arc(X(c.pose.position.x), Y(c.pose.position.y), r, 0, 2 * Math.PI);
          if (plan && id.startsWith("plan/robot/")) {
            g.strokeStyle = rgba(c.color, 1);
            g.lineWidth = 2;
            g.stroke();
            targets.push([Number(id.slice(11)), c.pose.position.x, c.pose.position.y]);
          } else {
            g.fillStyle = rgba(c.color);
            g.fill();
          }
        }
        for (const a of e.arrows) {
          const h = yawOf(a.pose.orientation);
          const L = s * (a.shaft_length + a.head_length);
          const px = X(a.pose.position.x), py = Y(a.pose.position.y);
          const qx = px + L * Math.cos(h), qy = py - L * Math.sin(h);
          g.strokeStyle = layer === "/scene" ? "#111" : rgba(a.color);
          g.lineWidth = 2;
          g.beginPath(); g.moveTo(px, py); g.lineTo(qx, qy); g.stroke();
          const hl = Math.min(10, 0.4 * L);
          g.beginPath();
          g.moveTo(qx, qy);
          g.lineTo(qx - hl * Math.cos(h - 0.5), qy + hl * Math.sin(h - 0.5));
          g.moveTo(qx, qy);
          g.lineTo(qx - hl * Math.cos(h + 0.5), qy + hl * Math.sin(h + 0.5));
          g.stroke();
        }
        for (const t of e.texts) {
          g.font = layer === "/scene" ? "bold 13px sans-serif" : "11px sans-serif";
          g.fillStyle = layer === "/scene" ? "#111" : rgba(t.color, 1);
          const dy = layer === "/scene" ? -9 : 16; // a target's label below it
          g.fillText(t.text, X(t.pose.position.x) + 9, Y(t.pose.position.y) + dy);
        }
      }
    }
    view.targets = targets;
    if (sceneNs) {
      view.draws.push([sceneNs, Date.now()]);
      if (view.draws.length > 2000) view.draws.splice(0, 1000);
      $("clock").textContent = `t_sim ${(sceneNs / 1e9).toFixed(1)} s`;
    }
  }

  function grid(g, X, Y, x0, y0, x1, y1) {
    g.strokeStyle = "#eceef1";
    g.lineWidth = 1;
    g.font = "10px sans-serif";
    g.fillStyle = "#999";
    for (let x = Math.ceil(x0); x <= x1; x++) {
      g.beginPath(); g.moveTo(X(x), Y(y0)); g.lineTo(X(x), Y(y1)); g.stroke();
      g.fillText(x + " m", X(x) + 2, Y(y0) - 2);
    }
    for (let y = Math.ceil(y0); y <= y1; y++) {
      g.beginPath(); g.moveTo(X(x0), Y(y)); g.lineTo(X(x1), Y(y)); g.stroke();
      g.fillText(y + " m", X(x0) + 2, Y(y) - 2);
    }
  }

  wsUrl().then(connect);
})();
