// What the canvas shows, in the photograph's pixels: masks, strokes, boxes, the ground and gravity as the
// camera keys place them, and the conditions (regions, arrows for vectors, a curved arrow for torque).
"use strict";
const Draw = (() => {
  const OBJECT_COLOURS = ["#50c8ff", "#ff9f3c", "#78ff78", "#ff5ac8", "#c8c8c8"];
  const CONDITION_COLOURS = { impulse: "#ff4040", velocity: "#ff9000", force: "#ff40ff", torque: "#ffff40", fixed: "#b0b0b0" };
  const VECTOR_KEY = { impulse: "velocity", velocity: "velocity", force: "force", torque: "torque" };
  const G = 9.81;

  // The object's box in pixels: its mask's bounding box, else its scene box, else the photograph.
  function objectRect(app, k) {
    const m = app.masks[k];
    if (m && m.bbox) return m.bbox;
    const o = app.scene.objects[k] || {};
    return o.box || [0, 0, app.photo.width, app.photo.height];
  }

  // A region's rectangle and centre in pixels; x, y of the object's normalised box map onto its pixel box
  // (z, away from the camera, has no place on the photograph and is edited as numbers).
  function regionGeometry(app, c) {
    const [x0, y0, x1, y1] = objectRect(app, c.object || 0);
    const at = (u, v) => [x0 + u * (x1 - x0), y0 + v * (y1 - y0)];
    const r = c.region;
    if (r && r.box) {
      const [a, b] = [at(r.box[0], r.box[1]), at(r.box[3], r.box[4])];
      return { kind: "box", rect: [a[0], a[1], b[0], b[1]], centre: [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2] };
    }
    if (r && r.sphere) {
      const centre = at(r.sphere[0], r.sphere[1]);
      return { kind: "sphere", centre, rx: r.sphere[3] * (x1 - x0), ry: r.sphere[3] * (y1 - y0) };
    }
    return { kind: "all", rect: [x0, y0, x1, y1], centre: [(x0 + x1) / 2, (y0 + y1) / 2] };
  }

  function pitch(app) { return ((app.scene.camera || {}).pitch_deg ?? app.defaults.pitch) * Math.PI / 180; }

  // The frame a condition's vectors are read in: its own `frame` key when the models have one, else the camera's.
  function frameOf(app, c) {
    if (c.frame) return c.frame;
    const s = Forms.resolve(Forms.defs()[app.conditionDefs[c.type]]);
    const f = s && s.properties && s.properties.frame;
    return f ? Forms.plain(f).default : "camera";
  }

  // Image-plane direction (dx, dy) of a vector: camera frame x right, y down, z away; the gravity frame is the
  // camera's turned by the pitch about x (y along gravity, z horizontal).
  function toImage(app, c, v) {
    if (frameOf(app, c) !== "gravity") return [v[0], v[1]];
    const p = pitch(app);
    return [v[0], v[1] * Math.cos(p) - v[2] * Math.sin(p)];
  }

  function fromImage(app, c, dx, dy, v) {
    if (frameOf(app, c) !== "gravity") return [dx, dy, v[2]];
    const p = pitch(app);
    return [dx, (dy + v[2] * Math.sin(p)) / Math.cos(p), v[2]];
  }

  // How long an arrow is: half the object's box for 1 m/s, a quarter of its weight, or that weight times its size.
  function pixelsPerUnit(app, c) {
    const [x0, y0, x1, y1] = objectRect(app, c.object || 0);
    const o = app.scene.objects[c.object || 0] || {};
    const size = o.size_m ?? app.defaults.size;
    const density = (o.material || {}).density ?? app.materialDefault(o.material, "density");
    const weight = density * 0.5 * size ** 3 * G;
    const ref = { impulse: 1, velocity: 1, force: 0.25 * weight, torque: 0.25 * weight * size }[c.type];
    return 0.5 * Math.max(x1 - x0, y1 - y0) / ref;
  }

  function arrow(ctx, from, to, colour, width) {
    const [dx, dy] = [to[0] - from[0], to[1] - from[1]];
    const len = Math.hypot(dx, dy);
    if (len < 1e-6) return;
    const head = Math.min(14 * width / 2.5, len * 0.4);
    const [ux, uy] = [dx / len, dy / len];
    ctx.strokeStyle = ctx.fillStyle = colour;
    ctx.lineWidth = width;
    ctx.beginPath(); ctx.moveTo(...from); ctx.lineTo(to[0] - ux * head * 0.8, to[1] - uy * head * 0.8); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(...to);
    ctx.lineTo(to[0] - ux * head - uy * head * 0.5, to[1] - uy * head + ux * head * 0.5);
    ctx.lineTo(to[0] - ux * head + uy * head * 0.5, to[1] - uy * head - ux * head * 0.5);
    ctx.closePath(); ctx.fill();
  }

  // Handles the Move tool can drag, per condition: the arrow's tip, the torque arc's end, region corners/centre.
  function handles(app, i) {
    const c = app.scene.physics.conditions[i];
    const g = regionGeometry(app, c);
    const out = [];
    const key = VECTOR_KEY[c.type];
    const v = key ? (c[key] || [0, 0, 0]) : null;
    if (c.type === "torque") {
      const { end } = torqueArc(app, c, g.centre);
      out.push({ kind: "torque", at: end });
    } else if (v) {
      const d = toImage(app, c, v), s = pixelsPerUnit(app, c);
      out.push({ kind: "vector", at: [g.centre[0] + d[0] * s, g.centre[1] + d[1] * s] });
    }
    if (g.kind === "box" && c.region !== "all") {
      out.push({ kind: "corner0", at: [g.rect[0], g.rect[1]] }, { kind: "corner1", at: [g.rect[2], g.rect[3]] });
      out.push({ kind: "centre", at: g.centre });
    }
    if (g.kind === "sphere") out.push({ kind: "radius", at: [g.centre[0] + g.rx, g.centre[1]] }, { kind: "centre", at: g.centre });
    return out;
  }

  // The curved arrow of a torque: its turn about the view axis (z, away from the camera) as an arc, clockwise
  // on the screen for positive z (x right turning into y down); a full turn is four times the reference torque.
  function torqueArc(app, c, centre) {
    const [x0, y0, x1, y1] = objectRect(app, c.object || 0);
    const radius = 0.3 * Math.max(x1 - x0, y1 - y0);
    const tz = (c.torque || [0, 0, 0])[2];
    const sweep = Math.max(-1.9 * Math.PI, Math.min(1.9 * Math.PI, tz * pixelsPerUnit(app, c) / radius * Math.PI / 2));
    const start = -Math.PI / 2;
    const end = [centre[0] + radius * Math.cos(start + sweep), centre[1] + radius * Math.sin(start + sweep)];
    return { radius, start, sweep, end };
  }

  function torqueFromAngle(app, c, centre, p) {
    const arc = torqueArc(app, c, centre);
    let angle = Math.atan2(p[1] - centre[1], p[0] - centre[0]) - arc.start;
    // continue from the current sweep, so the arc can be wound past a half turn
    while (angle - arc.sweep > Math.PI) angle -= 2 * Math.PI;
    while (angle - arc.sweep < -Math.PI) angle += 2 * Math.PI;
    return angle * arc.radius / (Math.PI / 2) / pixelsPerUnit(app, c);
  }

  // Ground plane, horizon and gravity from camera.fov_deg and pitch_deg, with the object's depth estimated
  // from its size_m and its box (the pinhole camera pm-reconstruct uses: focal length from the vertical fov).
  function drawCamera(ctx, app, lw) {
    const { width: w, height: h } = app.photo;
    const cam = app.scene.camera || {};
    const fov = (cam.fov_deg ?? app.defaults.fov) * Math.PI / 180, p = pitch(app);
    const f = (h / 2) / Math.tan(fov / 2), [cx, cy] = [w / 2, h / 2];
    const project = (X) => [cx + f * X[0] / X[2], cy + f * X[1] / X[2]];
    const k = app.selObject, [x0, y0, x1, y1] = objectRect(app, k);
    const size = (app.scene.objects[k] || {}).size_m ?? app.defaults.size;
    const depth = f * size / Math.max(x1 - x0, y1 - y0, 1);
    const back = (u, v) => [(u - cx) / f * depth, (v - cy) / f * depth, depth];
    const gravity = (app.scene.physics || {}).gravity;
    const down = gravity ? normalise(gravity) : [0, Math.cos(p), Math.sin(p)];
    const across = cross(down, [0, 0, 1]); // horizontal, along the picture's x
    const e1 = Math.hypot(...across) > 1e-6 ? normalise(across) : [1, 0, 0];
    const e3 = cross(down, e1);
    const foot = back((x0 + x1) / 2, y1);
    ctx.save();
    ctx.lineWidth = lw;
    if ((app.scene.physics || {}).ground?.enabled !== false) {
      ctx.strokeStyle = "rgba(120, 220, 140, 0.55)";
      const ticks = [-1.5, -1, -0.5, 0, 0.5, 1, 1.5].map((t) => t * 2 * size);
      for (const a of ticks) for (const [d1, d2] of [[e1, e3], [e3, e1]]) {
        const pts = ticks.map((t) => add(foot, add(scale(d1, a), scale(d2, t)))).filter((X) => X[2] > 1e-3);
        if (pts.length < 2) continue;
        ctx.beginPath(); pts.map(project).forEach((q, i) => (i ? ctx.lineTo(...q) : ctx.moveTo(...q))); ctx.stroke();
      }
      ctx.strokeStyle = "rgba(120, 220, 140, 0.95)";
      ctx.lineWidth = 2 * lw;
      const ground = [add(foot, scale(e1, -3 * size)), add(foot, scale(e1, 3 * size))].map(project);
      ctx.beginPath(); ctx.moveTo(...ground[0]); ctx.lineTo(...ground[1]); ctx.stroke();
      label(ctx, "ground", [ground[1][0] - 50 * lw, ground[1][1] - 6 * lw], "rgba(120, 220, 140, 0.95)", lw);
    }
    if (Math.abs(p) > 1e-3 && !gravity) { // the horizon: where the ground plane's directions vanish
      const yh = cy - f * Math.tan(p);
      if (yh > 0 && yh < h) {
        ctx.setLineDash([8 * lw, 6 * lw]); ctx.strokeStyle = "rgba(255,255,255,0.5)"; ctx.lineWidth = lw;
        ctx.beginPath(); ctx.moveTo(0, yh); ctx.lineTo(w, yh); ctx.stroke(); ctx.setLineDash([]);
        label(ctx, "horizon", [6 * lw, yh - 5 * lw], "rgba(255,255,255,0.7)", lw);
      }
    }
    // gravity beside the object, pointing where down is in the picture, a third of the object long
    const centre = back((x0 + x1) / 2, (y0 + y1) / 2), from = project(centre);
    const direction = normalise(add(project(add(centre, scale(down, 0.1 * size))), scale(from, -1)));
    const start = [Math.min(x1 + 0.06 * (x1 - x0), w - 20 * lw), from[1] - 0.15 * (y1 - y0)];
    const tip = add(start, scale(direction, 0.33 * Math.max(x1 - x0, y1 - y0)));
    arrow(ctx, start, tip, "#ffffff", 2.5 * lw);
    label(ctx, "gravity", add(tip, [6 * lw, 0]), "#ffffff", lw);
    ctx.restore();
  }

  function label(ctx, text, at, colour, lw) {
    ctx.font = `${13 * lw}px system-ui, sans-serif`;
    ctx.lineWidth = 3 * lw; ctx.strokeStyle = "rgba(0,0,0,0.7)"; ctx.strokeText(text, ...at);
    ctx.fillStyle = colour; ctx.fillText(text, ...at);
  }

  function drawConditions(ctx, app, lw) {
    (app.scene.physics?.conditions || []).forEach((c, i) => {
      const colour = CONDITION_COLOURS[c.type] || "#fff";
      const g = regionGeometry(app, c);
      const selected = i === app.selCondition;
      ctx.save();
      ctx.lineWidth = (selected ? 2.5 : 1.5) * lw;
      ctx.strokeStyle = colour;
      ctx.fillStyle = colour + (c.type === "fixed" ? "55" : "22");
      if (g.kind === "box" || (g.kind === "all" && c.type === "fixed")) {
        const [a, b, cc, d] = g.rect;
        if (g.kind === "box") { ctx.setLineDash([6 * lw, 4 * lw]); }
        ctx.fillRect(a, b, cc - a, d - b); ctx.strokeRect(a, b, cc - a, d - b);
        if (c.type === "fixed") hatch(ctx, g.rect, colour, lw);
      } else if (g.kind === "sphere") {
        ctx.setLineDash([6 * lw, 4 * lw]);
        ctx.beginPath(); ctx.ellipse(...g.centre, g.rx, g.ry, 0, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      }
      ctx.setLineDash([]);
      const key = VECTOR_KEY[c.type];
      if (c.type === "torque") {
        const arc = torqueArc(app, c, g.centre);
        ctx.lineWidth = 3 * lw;
        ctx.beginPath(); ctx.arc(...g.centre, arc.radius, arc.start, arc.start + arc.sweep, arc.sweep < 0); ctx.stroke();
        const a1 = arc.start + arc.sweep, dir = Math.sign(arc.sweep) || 1;
        const tangent = [-Math.sin(a1) * dir, Math.cos(a1) * dir];
        arrow(ctx, [arc.end[0] - tangent[0] * 12 * lw, arc.end[1] - tangent[1] * 12 * lw], arc.end, colour, 3 * lw);
        const t = c.torque || [0, 0, 0], s = pixelsPerUnit(app, c);
        if (Math.hypot(t[0], t[1]) > 0) { // the axis' part in the picture's plane
          ctx.setLineDash([4 * lw, 4 * lw]);
          arrow(ctx, g.centre, [g.centre[0] + t[0] * s, g.centre[1] + t[1] * s], colour, 1.5 * lw);
        }
      } else if (key) {
        const d = toImage(app, c, c[key] || [0, 0, 0]), s = pixelsPerUnit(app, c);
        arrow(ctx, g.centre, [g.centre[0] + d[0] * s, g.centre[1] + d[1] * s], colour, 3 * lw);
      }
      const v = key ? c[key] || [0, 0, 0] : null;
      const unit = { impulse: "m/s", velocity: "m/s", force: "N", torque: "N m" }[c.type] || "";
      const when = c.start_s !== undefined || c.end_s !== undefined ?
        ` ${c.start_s ?? 0}–${c.end_s ?? "end"} s` : "";
      label(ctx, `${i}: ${c.type}${v ? ` ${Math.hypot(...v).toPrecision(3)} ${unit}` : ""}${when}`,
            [g.centre[0] + 8 * lw, g.centre[1] - 8 * lw], colour, lw);
      if (selected) for (const hdl of handles(app, i)) {
        ctx.fillStyle = "#fff"; ctx.strokeStyle = "#000"; ctx.lineWidth = lw;
        ctx.beginPath(); ctx.arc(...hdl.at, 5 * lw, 0, 2 * Math.PI); ctx.fill(); ctx.stroke();
      }
      ctx.restore();
    });
  }

  function hatch(ctx, [a, b, c, d], colour, lw) {
    ctx.save(); ctx.beginPath(); ctx.rect(a, b, c - a, d - b); ctx.clip();
    ctx.strokeStyle = colour + "99"; ctx.lineWidth = lw;
    for (let x = a - (d - b); x < c; x += 10 * lw) { ctx.beginPath(); ctx.moveTo(x, d); ctx.lineTo(x + (d - b), b); ctx.stroke(); }
    ctx.restore();
  }

  function render(app) {
    const canvas = app.canvas, ctx = canvas.getContext("2d");
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    if (!app.photo) return;
    ctx.setTransform(app.scale, 0, 0, app.scale, 0, 0);
    const lw = 1 / app.scale;
    ctx.drawImage(app.photo.img, 0, 0);
    app.scene.objects.forEach((o, k) => {
      const m = app.masks[k];
      if (m && m.canvas) { ctx.globalAlpha = k === app.selObject ? 0.55 : 0.3; ctx.drawImage(m.canvas, 0, 0); }
      ctx.globalAlpha = 0.85;
      if (app.hints[k]) ctx.drawImage(app.hints[k], 0, 0);
      ctx.globalAlpha = 1;
      const colour = OBJECT_COLOURS[k % OBJECT_COLOURS.length];
      if (o.box) {
        ctx.setLineDash([6 * lw, 4 * lw]); ctx.strokeStyle = colour; ctx.lineWidth = (k === app.selObject ? 2 : 1) * lw;
        ctx.strokeRect(o.box[0], o.box[1], o.box[2] - o.box[0], o.box[3] - o.box[1]); ctx.setLineDash([]);
      }
      const [x0, y0] = objectRect(app, k);
      label(ctx, `object ${k}: ${(o.material || {}).preset || "jelly"}`, [x0 + 3 * lw, y0 - 5 * lw], colour, lw);
    });
    drawCamera(ctx, app, lw);
    drawConditions(ctx, app, lw);
    if (app.drag && app.drag.kind === "newbox") {
      const [a, b] = [app.drag.from, app.drag.to];
      ctx.setLineDash([6 * lw, 4 * lw]); ctx.strokeStyle = "#fff"; ctx.lineWidth = 2 * lw;
      ctx.strokeRect(a[0], a[1], b[0] - a[0], b[1] - a[1]); ctx.setLineDash([]);
    }
  }

  const add = (a, b) => a.map((v, i) => v + b[i]);
  const scale = (a, s) => a.map((v) => v * s);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const normalise = (a) => { const n = Math.hypot(...a) || 1; return a.map((v) => v / n); };

  return { render, handles, regionGeometry, objectRect, toImage, fromImage, pixelsPerUnit, torqueFromAngle,
           VECTOR_KEY, OBJECT_COLOURS, CONDITION_COLOURS };
})();
