// The page's state and its events: the scene mapping from /api/scene, edited in place and sent back on Save.
"use strict";
const app = {
  scene: null, schema: null, photo: null, masks: [], hints: [], selObject: 0, selCondition: null,
  tool: "box", drag: null, scale: 1, canvas: document.getElementById("canvas"), defaults: {},
  conditionDefs: {}, presetDefs: {}, pendingMasks: 0, preview: null,
};
const $ = (id) => document.getElementById(id);
const { el } = Forms;

async function api(method, url, body) {
  const response = await fetch(url, { method, headers: body ? { "Content-Type": "application/json" } : {},
                                      body: body === undefined ? undefined : JSON.stringify(body) });
  const data = await response.json().catch(() => ({ error: { message: `${response.status} ${response.statusText}` } }));
  return { ok: response.ok, data };
}

function status(text) { $("status").textContent = text; }

// ---------------------------------------------------------------------------------------------------------
// Loading

async function load() {
  const { data } = await api("GET", "/api/scene");
  await adopt(data);
}

async function adopt(data) {
  app.schema = data.schema;
  Forms.setSchema(data.schema);
  const defs = data.schema.$defs;
  app.conditionDefs = mapping(Forms.resolve(defs.PhysicsConfig).properties.conditions.items);
  app.presetDefs = mapping(Forms.resolve(defs.ObjectConfig).properties.material);
  app.defaults = { fov: defs.CameraConfig.properties.fov_deg.default, pitch: defs.CameraConfig.properties.pitch_deg.default,
                   size: defs.ObjectConfig.properties.size_m.default };
  app.scene = withSections(data.scene);
  $("folder").textContent = data.folder;
  app.masks = []; app.hints = [];
  app.selObject = Math.min(app.selObject, app.scene.objects.length - 1);
  if (data.photo) {
    app.photo = { ...data.photo, img: await image(data.photo.url + "?t=" + Date.now()) };
    $("empty").hidden = true;
    fit();
    for (let k = 0; k < app.scene.objects.length; k++) {
      app.hints[k] = blankCanvas();
      if (data.hints[k]) hintsFromFile(app.hints[k], await image(data.hints[k] + "?t=" + Date.now()));
    }
    await Promise.all(app.scene.objects.map((_, k) => updateMask(k)));
  } else {
    app.photo = null;
    $("empty").hidden = false;
    app.canvas.width = Math.min($("stage").clientWidth - 30, 900);
    app.canvas.height = Math.round(app.canvas.width * 9 / 16);
  }
  renderPanel();
  redraw();
  if (data.error) Forms.showError(data.error.field, data.error.message);
  status(data.saved ? "saved scene.yaml loaded" : "new scene: not saved yet");
}

// The scene mapping with the sections the page edits in place (a saved file leaves out those at their defaults).
function withSections(scene) {
  scene = scene && Object.keys(scene).length ? scene : { objects: [{}] };
  scene.objects = scene.objects || [{}];
  scene.physics = scene.physics || {};
  scene.physics.conditions = scene.physics.conditions || [];
  scene.camera = scene.camera || {};
  return scene;
}

// {tag: def name} of a discriminated union, from pydantic's schema (discriminator.mapping).
function mapping(s) {
  const out = {};
  for (const [tag, ref] of Object.entries(s.discriminator.mapping)) out[tag] = ref.split("/").pop();
  return out;
}

app.materialDefault = (material, key) => {
  const def = Forms.defs()[app.presetDefs[(material || {}).preset || "jelly"]];
  return def.properties[key] ? def.properties[key].default : undefined;
};

function image(url) {
  return new Promise((resolve, reject) => { const i = new Image(); i.onload = () => resolve(i); i.onerror = reject; i.src = url; });
}

function blankCanvas() {
  const c = document.createElement("canvas");
  c.width = app.photo.width; c.height = app.photo.height;
  return c;
}

// The hint file (white object strokes, black background strokes) as the page paints them (green, red).
function hintsFromFile(canvas, img) {
  const ctx = canvas.getContext("2d");
  ctx.drawImage(img, 0, 0);
  const d = ctx.getImageData(0, 0, canvas.width, canvas.height);
  for (let i = 0; i < d.data.length; i += 4) {
    if (d.data[i + 3] <= 127) { d.data[i + 3] = 0; continue; }
    const object = d.data[i] + d.data[i + 1] + d.data[i + 2] > 3 * 127;
    d.data.set(object ? [40, 230, 90, 255] : [255, 50, 50, 255], i);
  }
  ctx.putImageData(d, 0, 0);
}

function hasStrokes(k) {
  const c = app.hints[k];
  if (!c) return false;
  const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
  for (let i = 3; i < d.length; i += 4) if (d[i] > 127) return true;
  return false;
}

function fit() {
  const wrap = $("stage");
  const maxW = wrap.clientWidth - 30, maxH = window.innerHeight * 0.64;
  app.scale = Math.min(maxW / app.photo.width, maxH / app.photo.height, 3);
  app.canvas.width = Math.round(app.photo.width * app.scale);
  app.canvas.height = Math.round(app.photo.height * app.scale);
}

// ---------------------------------------------------------------------------------------------------------
// Masks: what pm-reconstruct would make of this object (server side, the same segmentation code)

async function updateMask(k) {
  const o = app.scene.objects[k];
  app.pendingMasks++;
  $("mask-info").textContent = `object ${k}: segmenting…`;
  const { ok, data } = await api("POST", "/api/mask", {
    object: k, box: o.box || null, mask: o.mask || null, hints: hasStrokes(k) ? app.hints[k].toDataURL("image/png") : null });
  app.pendingMasks--;
  if (!ok) {
    app.masks[k] = { error: data.error.message };
    $("mask-info").textContent = data.error.message;
    Forms.showError(data.error.field, data.error.message);
  } else {
    const img = await image(data.mask);
    app.masks[k] = { canvas: tint(img, Draw.OBJECT_COLOURS[k % Draw.OBJECT_COLOURS.length]), bbox: data.bbox, pixels: data.pixels };
    $("mask-info").textContent = `object ${k}: ${data.pixels} pixels (${data.method}${hasStrokes(k) ? ", with your strokes" : ""})`;
  }
  redraw();
}

function tint(img, colour) {
  const c = blankCanvas(), ctx = c.getContext("2d");
  ctx.drawImage(img, 0, 0);
  const d = ctx.getImageData(0, 0, c.width, c.height);
  const rgb = [1, 3, 5].map((i) => parseInt(colour.slice(i, i + 2), 16));
  for (let i = 0; i < d.data.length; i += 4) {
    const on = d.data[i] > 127;
    d.data.set(on ? [...rgb, 255] : [0, 0, 0, 0], i);
  }
  ctx.putImageData(d, 0, 0);
  return c;
}

// ---------------------------------------------------------------------------------------------------------
// The side panel: generated from the schema

function edited(path) {
  scheduleCheck();
  if (path && (path.startsWith("objects") || path.startsWith("camera") || path.startsWith("physics"))) redraw();
}

function renderPanel() {
  const objectSelect = $("object-select");
  objectSelect.replaceChildren(...app.scene.objects.map((o, k) => el("option", { value: k }, `object ${k}`)));
  objectSelect.value = app.selObject;
  renderObject();
  renderConditions();
  const defs = app.schema.$defs;
  $("camera-form").replaceChildren();
  Forms.form($("camera-form"), defs.CameraConfig, app.scene.camera, "camera", edited, { sliders: ["fov_deg", "pitch_deg"] });
  $("physics-form").replaceChildren();
  Forms.form($("physics-form"), defs.PhysicsConfig, app.scene.physics, "physics", edited, { skip: ["conditions"] });
  $("more-form").replaceChildren();
  Forms.form($("more-form"), app.schema, app.scene, "", edited, { skip: ["image", "camera", "objects", "physics"] });
}

function renderObject() {
  const k = app.selObject, o = app.scene.objects[k], box = $("object-form");
  box.replaceChildren();
  const defs = app.schema.$defs, objectDef = defs.ObjectConfig;
  const seg = el("div", { class: "field", "data-field": `objects[${k}].box` }, el("label", {}, "segmentation"),
    el("div", {}, o.mask ? `mask file ${o.mask}` : o.box ? `box [${o.box.map((v) => Math.round(v)).join(", ")}] px` :
                   "no box: draw one with ▭ Box"));
  box.append(seg);
  box.append(el("div", { class: "field", "data-field": `objects[${k}].hints` }, el("label", {}, "hints"),
    el("div", { class: "muted" }, o.hints ? `${o.hints} (saved strokes)` : "paint ✚ Object / ━ Background strokes to correct the mask")));
  Forms.field(box, "size_m", objectDef.properties.size_m, o, `objects[${k}].size_m`, edited);
  o.material = o.material || { preset: "jelly" };
  const presets = Object.keys(app.presetDefs);
  const wrap = el("div", { class: "field", "data-field": `objects[${k}].material.preset` }, el("label", {}, "material"));
  const select = el("select", { id: "preset", name: `objects[${k}].material.preset` },
                    ...presets.map((p) => el("option", { value: p }, p)));
  select.value = o.material.preset || "jelly";
  select.addEventListener("change", () => { o.material = { preset: select.value }; renderObject(); edited(`objects[${k}]`); });
  const presetDef = defs[app.presetDefs[select.value]];
  wrap.append(select, el("div", { class: "hint" }, presetDef.description || ""));
  box.append(wrap);
  const keys = el("fieldset", { "data-field": `objects[${k}].material` }, el("legend", {}, `${select.value} keys`));
  Forms.form(keys, presetDef, o.material, `objects[${k}].material`, edited, { skip: ["preset"] });
  box.append(keys);
}

function defaultRegion(kind) {
  return kind === "box" ? { box: [0.25, 0.25, 0, 0.75, 0.75, 1] } : kind === "sphere" ? { sphere: [0.5, 0.5, 0.5, 0.3] } : "all";
}

function renderConditions() {
  const typeSelect = $("condition-type");
  if (!typeSelect.options.length) {
    typeSelect.replaceChildren(...Object.keys(app.conditionDefs).map((t) => el("option", { value: t }, t)));
    typeSelect.value = "impulse" in app.conditionDefs ? "impulse" : typeSelect.options[0].value;
  }
  const list = $("conditions");
  list.replaceChildren();
  app.scene.physics.conditions.forEach((c, i) => list.append(conditionCard(c, i)));
}

function conditionCard(c, i) {
  const path = `physics.conditions[${i}]`, def = Forms.defs()[app.conditionDefs[c.type]];
  const card = el("div", { class: "condition" + (i === app.selCondition ? " selected" : ""), "data-field": path,
                           onclick: () => { if (app.selCondition !== i) { app.selCondition = i; renderConditions(); redraw(); } } });
  const remove = el("button", { title: "remove this condition", onclick: (e) => {
    e.stopPropagation(); app.scene.physics.conditions.splice(i, 1); app.selCondition = null; renderConditions(); edited(path); } }, "✕");
  card.append(el("div", { class: "title" }, el("span", { class: "swatch", style: `background:${Draw.CONDITION_COLOURS[c.type]}` }),
                 `${i}: ${c.type}`, el("span", { class: "spacer" }), remove));
  card.append(el("div", { class: "hint muted" }, def.description || ""));
  if (app.scene.objects.length > 1) Forms.field(card, "object", def.properties.object, c, `${path}.object`, () => { renderConditions(); edited(path); });
  // region: all, a box or a sphere in the object's normalised box, drawn on the photograph
  const kind = c.region && c.region.box ? "box" : c.region && c.region.sphere ? "sphere" : "all";
  const regionRow = el("div", { class: "field", "data-field": `${path}.region` }, el("label", {}, "region"));
  const regionSelect = el("select", { name: `${path}.region` }, ...["all", "box", "sphere"].map((r) => el("option", { value: r }, r)));
  regionSelect.value = kind;
  regionSelect.addEventListener("change", () => { c.region = defaultRegion(regionSelect.value); renderConditions(); edited(path); });
  regionRow.append(regionSelect, el("div", { class: "hint" }, kind === "all" ? "the whole object" :
    "drag it on the photograph (✥ Move); depth (z, away from the camera) below"));
  card.append(regionRow);
  if (kind === "box") depthInputs(card, c.region.box, [2, 5], `${path}.region`, ["z0", "z1"]);
  if (kind === "sphere") depthInputs(card, c.region.sphere, [2], `${path}.region`, ["cz"]);
  const key = Draw.VECTOR_KEY[c.type];
  if (key) Forms.field(card, key, def.properties[key], c, `${path}.${key}`, (p) => { edited(p); });
  windowSliders(card, c, def, path);
  Forms.form(card, def, c, path, edited, { skip: ["type", "object", "region", key, "start_s", "end_s"] });
  return card;
}

function depthInputs(card, values, indices, path, names) {
  const row = el("div", { class: "field" }, el("label", {}, names.join(", ")));
  const inputs = el("div", { class: "vec" });
  indices.forEach((idx) => {
    const input = el("input", { type: "number", step: "0.05", min: 0, max: 1, name: `${path}.${names[indices.indexOf(idx)]}` });
    input.value = values[idx];
    input.addEventListener("change", () => { values[idx] = Number(input.value); edited(path); });
    inputs.append(input);
  });
  row.append(inputs);
  card.append(row);
}

// start_s and end_s as sliders over the video's duration; end_s at the far right is 'until the end' (null).
function windowSliders(card, c, def, path) {
  const duration = app.scene.physics.duration_s ?? Forms.defs().PhysicsConfig.properties.duration_s.default;
  for (const key of ["start_s", "end_s"]) {
    if (!def.properties[key]) continue;
    const s = Forms.plain(def.properties[key]);
    const wrap = el("div", { class: "field", "data-field": `${path}.${key}` }, el("label", {}, key.replace("_s", " (s)")));
    const value = c[key] ?? (key === "end_s" ? duration : s.default ?? 0);
    const range = el("input", { type: "range", min: 0, max: duration, step: duration / 100, name: `${path}.${key}` });
    range.value = value;
    const shown = el("span", { class: "muted" });
    const show = () => { shown.textContent = key === "end_s" && Number(range.value) >= duration ? "until the end" : `${Number(range.value).toFixed(2)} s`; };
    range.addEventListener("input", () => {
      const v = Number(range.value);
      if (key === "end_s" && v >= duration) delete c.end_s; else c[key] = v;
      show(); edited(`${path}.${key}`);
    });
    show();
    wrap.append(el("div", { class: "vec" }, range, shown), el("div", { class: "hint" }, s.description || ""));
    card.append(wrap);
  }
}

// ---------------------------------------------------------------------------------------------------------
// The canvas: drawing boxes and strokes, dragging arrows and regions

function redraw() { if (app.scene) Draw.render(app); }

function photoPoint(event) {
  const r = app.canvas.getBoundingClientRect();
  return [(event.clientX - r.left) * app.canvas.width / r.width / app.scale,
          (event.clientY - r.top) * app.canvas.height / r.height / app.scale];
}

function setTool(tool) {
  app.tool = tool;
  document.querySelectorAll("[data-tool]").forEach((b) => b.classList.toggle("active", b.dataset.tool === tool));
  app.canvas.style.cursor = tool === "move" ? "grab" : "crosshair";
}

function paint(p, last) {
  const ctx = app.hints[app.selObject].getContext("2d");
  ctx.strokeStyle = ctx.fillStyle = app.tool === "fg" ? "rgb(40,230,90)" : "rgb(255,50,50)";
  ctx.lineWidth = 2 * Number($("brush").value) / app.scale;
  ctx.lineCap = "round";
  ctx.beginPath(); ctx.moveTo(...(last || p)); ctx.lineTo(...p); ctx.stroke();
}

function hit(p) {
  const conditions = app.scene.physics.conditions;
  const order = app.selCondition !== null ? [app.selCondition, ...conditions.keys()] : [...conditions.keys()];
  for (const i of order) {
    for (const h of Draw.handles(app, i)) {
      if (Math.hypot(h.at[0] - p[0], h.at[1] - p[1]) < 9 / app.scale) return { index: i, ...h };
    }
  }
  for (const i of order) { // inside a region: select it
    const g = Draw.regionGeometry(app, conditions[i]);
    const r = g.rect || [g.centre[0] - g.rx, g.centre[1] - g.ry, g.centre[0] + g.rx, g.centre[1] + g.ry];
    if (p[0] >= r[0] && p[0] <= r[2] && p[1] >= r[1] && p[1] <= r[3]) return { index: i, kind: "select" };
  }
  return null;
}

function onDown(event) {
  if (!app.photo) return;
  const p = photoPoint(event);
  if (app.tool === "box") app.drag = { kind: "newbox", from: p, to: p };
  else if (app.tool === "fg" || app.tool === "bg") { app.drag = { kind: "paint", last: p }; paint(p); }
  else {
    const h = hit(p);
    if (h) {
      app.drag = { ...h, from: p };
      if (app.selCondition !== h.index) { app.selCondition = h.index; renderConditions(); }
    }
  }
  redraw();
}

function clamp01(v) { return Math.max(0, Math.min(1, v)); }

function onMove(event) {
  if (!app.drag) return;
  const p = photoPoint(event), d = app.drag;
  if (d.kind === "newbox") d.to = p;
  else if (d.kind === "paint") { paint(p, d.last); d.last = p; }
  else {
    const c = app.scene.physics.conditions[d.index];
    const g = Draw.regionGeometry(app, c), [x0, y0, x1, y1] = Draw.objectRect(app, c.object || 0);
    const u = (q) => [clamp01((q[0] - x0) / (x1 - x0)), clamp01((q[1] - y0) / (y1 - y0))];
    if (d.kind === "vector") {
      const key = Draw.VECTOR_KEY[c.type], s = Draw.pixelsPerUnit(app, c);
      const v = Draw.fromImage(app, c, (p[0] - g.centre[0]) / s, (p[1] - g.centre[1]) / s, c[key] || [0, 0, 0]);
      c[key] = v.map((x) => Number(x.toPrecision(3)));
    } else if (d.kind === "torque") {
      const t = c.torque || [0, 0, 0];
      c.torque = [t[0], t[1], Number(Draw.torqueFromAngle(app, c, g.centre, p).toPrecision(3))];
    } else if (d.kind === "corner0" || d.kind === "corner1") {
      const b = c.region.box, [a, bb] = u(p), o = d.kind === "corner0" ? 0 : 3;
      b[o] = round(a); b[o + 1] = round(bb);
      if (b[0] > b[3]) [b[0], b[3]] = [b[3], b[0]];
      if (b[1] > b[4]) [b[1], b[4]] = [b[4], b[1]];
    } else if (d.kind === "centre") {
      const [du, dv] = [(p[0] - d.from[0]) / (x1 - x0), (p[1] - d.from[1]) / (y1 - y0)];
      d.from = p;
      if (c.region.box) {
        const b = c.region.box;
        const su = Math.max(-b[0], Math.min(1 - b[3], du)), sv = Math.max(-b[1], Math.min(1 - b[4], dv));
        [b[0], b[3], b[1], b[4]] = [b[0] + su, b[3] + su, b[1] + sv, b[4] + sv].map(round);
      } else {
        const s = c.region.sphere;
        [s[0], s[1]] = [round(clamp01(s[0] + du)), round(clamp01(s[1] + dv))];
      }
    } else if (d.kind === "radius") {
      const s = c.region.sphere;
      s[3] = round(Math.max(0.02, Math.abs(p[0] - g.centre[0]) / (x1 - x0)));
    }
  }
  redraw();
}

const round = (v) => Math.round(v * 1000) / 1000;

function onUp() {
  const d = app.drag;
  app.drag = null;
  if (!d) return;
  const k = app.selObject, o = app.scene.objects[k];
  if (d.kind === "newbox") {
    const [a, b] = [d.from, d.to];
    const box = [Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.max(a[0], b[0]), Math.max(a[1], b[1])]
      .map((v, i) => Math.round(Math.max(0, Math.min(i % 2 ? app.photo.height : app.photo.width, v))));
    if (box[2] - box[0] < 4 || box[3] - box[1] < 4) { redraw(); return; }
    o.box = box;
    delete o.mask; // a box replaces a mask file (scene.yaml takes one or the other)
    renderObject();
    updateMask(k);
  } else if (d.kind === "paint") {
    delete o.mask;
    updateMask(k);
  } else if (d.kind !== "select") {
    renderConditions();
  }
  scheduleCheck();
  redraw();
}

// ---------------------------------------------------------------------------------------------------------
// Checking, saving, previewing

let checkTimer = null;
function scheduleCheck() {
  clearTimeout(checkTimer);
  checkTimer = setTimeout(async () => {
    const { data } = await api("POST", "/api/check", { scene: app.scene });
    Forms.clearErrors();
    if (data.error) Forms.showError(data.error.field, data.error.message);
    status(data.error ? "the loader refuses this scene (see the red note)" : "not saved");
  }, 400);
}

async function save() {
  clearTimeout(checkTimer); // the save reports the loader's verdict itself
  const hints = {};
  app.scene.objects.forEach((_, k) => { hints[k] = hasStrokes(k) ? app.hints[k].toDataURL("image/png") : null; });
  status("saving…");
  const { ok, data } = await api("PUT", "/api/scene", { scene: app.scene, hints });
  if (!ok) {
    Forms.showError(data.error.field, data.error.message);
    status("not saved: the loader refuses this scene");
    return false;
  }
  Forms.clearErrors();
  app.scene = withSections(data.scene);
  renderPanel();
  redraw();
  status(`saved ${data.folder}/scene.yaml`);
  return true;
}

async function startPreview() {
  if (!(await save())) return;
  const { ok, data } = await api("POST", "/api/preview");
  if (!ok) { Forms.showError(data.error.field, data.error.message); return; }
  $("preview-pane").hidden = false;
  $("preview-pane").scrollIntoView({ block: "end" });
  pollPreview();
}

async function pollPreview() {
  const { data } = await api("GET", "/api/preview");
  const share = (data.done_stages + (data.state === "running" ? data.stage_fraction : 0)) / data.stages.length;
  $("progress-bar").style.width = `${Math.round(100 * (data.state === "done" ? 1 : share))}%`;
  $("preview-msg").textContent = data.state === "running" ? `pm-${data.stage} (${data.done_stages + 1}/${data.stages.length}), ${data.seconds} s: ${data.message}` : data.message;
  $("preview-msg").className = data.state === "failed" ? "error" : "muted";
  $("cancel").disabled = data.state !== "running";
  $("preview-pane").dataset.state = data.state;
  if (data.setup && $("preview-setup").dataset.src !== data.setup) {
    $("preview-setup").src = data.setup + "?t=" + Date.now(); $("preview-setup").dataset.src = data.setup;
  }
  if (data.state === "running") { setTimeout(pollPreview, 500); return; }
  if (data.state === "done") { playFrames(data.frames, data.fps); $("preview-pane").scrollIntoView({ block: "end" }); }
}

function playFrames(frames, fps) {
  const stamp = Date.now();
  const images = frames.map((f) => { const i = new Image(); i.src = `${f}?t=${stamp}`; return i; });
  const scrub = $("preview-scrub");
  scrub.max = frames.length - 1;
  clearInterval(app.preview);
  let t = 0;
  const show = (i) => { $("preview-frame").src = images[i].src; scrub.value = i; $("preview-frame").dataset.frame = i; };
  app.preview = setInterval(() => { show(t); t = (t + 1) % frames.length; }, 1000 / fps);
  scrub.oninput = () => { clearInterval(app.preview); show(Number(scrub.value)); };
  $("preview-pane").dataset.frames = frames.length;
}

async function uploadPhoto(file) {
  status("uploading…");
  const response = await fetch(`/api/photo?name=${encodeURIComponent(file.name)}`, { method: "POST", body: file });
  const data = await response.json();
  if (!response.ok) { Forms.showError(null, data.error.message); status("upload refused"); return; }
  await adopt(data);
}

// ---------------------------------------------------------------------------------------------------------

document.querySelectorAll("[data-tool]").forEach((b) => b.addEventListener("click", () => setTool(b.dataset.tool)));
app.canvas.addEventListener("pointerdown", onDown);
window.addEventListener("pointermove", onMove);
window.addEventListener("pointerup", onUp);
window.addEventListener("resize", () => { if (app.photo) { fit(); redraw(); } });
window.addEventListener("keydown", (e) => {
  if (e.target.tagName === "INPUT" || e.target.tagName === "SELECT") return;
  const tool = { b: "box", f: "fg", g: "bg", m: "move" }[e.key];
  if (tool) setTool(tool);
});
$("object-select").addEventListener("change", () => { app.selObject = Number($("object-select").value); renderObject(); redraw(); });
$("add-object").addEventListener("click", () => {
  app.scene.objects.push({ size_m: app.defaults.size, material: { preset: "jelly" } });
  app.hints.push(blankCanvas()); app.masks.push(null);
  app.selObject = app.scene.objects.length - 1; renderPanel(); setTool("box"); redraw();
});
$("remove-object").addEventListener("click", () => {
  if (app.scene.objects.length <= 1) return;
  const k = app.selObject;
  app.scene.objects.splice(k, 1); app.hints.splice(k, 1); app.masks.splice(k, 1);
  app.scene.physics.conditions = app.scene.physics.conditions.filter((c) => (c.object || 0) !== k)
    .map((c) => ((c.object || 0) > k ? { ...c, object: c.object - 1 } : c));
  app.selObject = 0; renderPanel(); redraw(); scheduleCheck();
});
$("add-condition").addEventListener("click", () => {
  const type = $("condition-type").value, key = Draw.VECTOR_KEY[type];
  const c = { type, object: app.selObject, region: "all" };
  if (key) c[key] = type === "torque" ? [0, 0, 0] : [0, 0, 0];
  app.scene.physics.conditions.push(c);
  app.selCondition = app.scene.physics.conditions.length - 1;
  if (key) { // a visible starting arrow: up for velocities, along +x for forces, a quarter turn for torques
    const s = Draw.pixelsPerUnit(app, c), [x0, y0, x1, y1] = Draw.objectRect(app, c.object);
    const len = 0.25 * Math.max(x1 - x0, y1 - y0) / s;
    c[key] = type === "torque" ? [0, 0, Number((len).toPrecision(2))] : type === "force" ? [Number(len.toPrecision(2)), 0, 0] : [0, -Number(len.toPrecision(2)), 0];
  }
  renderConditions(); setTool("move"); redraw(); scheduleCheck();
});
$("clear-hints").addEventListener("click", () => {
  const k = app.selObject;
  app.hints[k] = blankCanvas(); updateMask(k);
});
$("brush").addEventListener("input", redraw);
$("save").addEventListener("click", save);
$("preview").addEventListener("click", startPreview);
$("cancel").addEventListener("click", async () => { await api("DELETE", "/api/preview"); });
for (const id of ["photo-file", "photo-file-start"]) {
  $(id).addEventListener("change", (e) => { if (e.target.files[0]) uploadPhoto(e.target.files[0]); });
}
setTool("box");
window.pm = app; // for the browser tests: the state behind the page
load();
