// Forms generated from the scene's JSON Schema (pydantic's model_json_schema, served by /api/scene):
// labels, units (in the descriptions), defaults and ranges come from schemas/, so a key the models gain
// appears here by itself.
"use strict";
const Forms = (() => {
  let defs = {};

  function setSchema(schema) { defs = schema.$defs || {}; }

  function resolve(s) {
    while (s && s.$ref) s = defs[s.$ref.split("/").pop()];
    return s;
  }

  // Optional[X] (anyOf X, null) as X with nullable set; everything else resolved.
  function plain(s) {
    const r = resolve(s);
    if (r && r.anyOf) {
      const items = r.anyOf.filter((a) => a.type !== "null");
      if (items.length === 1 && items.length < r.anyOf.length) {
        return { ...resolve(items[0]), description: r.description, default: r.default, nullable: true };
      }
    }
    return r;
  }

  function rangeText(s) {
    const lo = s.exclusiveMinimum !== undefined ? `> ${s.exclusiveMinimum}` : s.minimum !== undefined ? `≥ ${s.minimum}` : "";
    const hi = s.exclusiveMaximum !== undefined ? `< ${s.exclusiveMaximum}` : s.maximum !== undefined ? `≤ ${s.maximum}` : "";
    return [lo, hi].filter(Boolean).join(", ");
  }

  function bounds(s) {
    return { min: s.minimum ?? s.exclusiveMinimum, max: s.maximum ?? s.exclusiveMaximum };
  }

  function el(tag, attrs = {}, ...children) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (k === "class") e.className = v; else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else if (v !== undefined && v !== null) e.setAttribute(k, v);
    }
    for (const c of children) if (c !== null && c !== undefined) e.append(c);
    return e;
  }

  function numberInput(s, value, onChange, name) {
    const b = bounds(s);
    const input = el("input", { type: "number", step: "any", name, min: b.min, max: b.max,
                                placeholder: s.nullable ? "none" : "" });
    input.value = value ?? "";
    input.addEventListener("change", () => {
      if (input.value === "") return onChange(s.nullable ? null : undefined);
      const v = Number(input.value);
      onChange(s.type === "integer" ? Math.round(v) : v);
    });
    return input;
  }

  // One field: key of obj (a plain JS object inside the scene mapping), at scene path `path`.
  function field(container, key, schema, obj, path, onChange, opts = {}) {
    const s = plain(schema);
    if (!s) return;
    const current = obj[key] !== undefined ? obj[key] : s.default;
    const set = (v) => {
      if (v === undefined) delete obj[key]; else obj[key] = v;
      onChange(path, v);
    };
    const wrap = el("div", { class: "field", "data-field": path });
    const title = key; // the key as scene.yaml spells it; the description below says what it means
    wrap.append(el("label", { for: path, title: key }, title));
    let control;
    if (s.type === "boolean") {
      control = el("input", { type: "checkbox", name: path });
      control.checked = !!current;
      control.addEventListener("change", () => set(control.checked));
    } else if (s.enum || s.const !== undefined) {
      const options = s.enum || [s.const];
      control = el("select", { name: path }, ...options.map((o) => el("option", { value: o }, String(o))));
      control.value = current ?? options[0];
      control.addEventListener("change", () => set(control.value));
    } else if (s.type === "number" || s.type === "integer") {
      const b = bounds(s);
      if (opts.slider && b.min !== undefined && b.max !== undefined) {
        const num = numberInput(s, current, (v) => { range.value = v; set(v); }, path);
        const range = el("input", { type: "range", min: b.min, max: b.max, step: (b.max - b.min) / 200 });
        range.value = current;
        range.addEventListener("input", () => { num.value = range.value; set(Number(range.value)); });
        control = el("div", { class: "vec" }, range, num);
      } else {
        control = numberInput(s, current, set, path);
      }
    } else if (s.type === "array" && s.prefixItems && s.prefixItems.every((p) => resolve(p).type === "number")) {
      const values = [...(current || s.prefixItems.map(() => 0))];
      control = el("div", { class: "vec" }, ...values.map((v, i) => {
        const input = el("input", { type: "number", step: "any", name: `${path}[${i}]` });
        input.value = v;
        input.addEventListener("change", () => { values[i] = Number(input.value); set([...values]); });
        return input;
      }));
    } else if (s.type === "string") {
      control = el("input", { type: "text", name: path });
      control.value = current ?? "";
      control.addEventListener("change", () => set(control.value === "" && s.nullable ? null : control.value));
    } else if (s.properties) {
      if (obj[key] === undefined || obj[key] === null) obj[key] = {};
      const box = el("fieldset", { "data-field": path }, el("legend", {}, title));
      form(box, s, obj[key], path, onChange, opts);
      container.append(box);
      return;
    } else {
      return; // unions (regions, materials, conditions) have their own controls
    }
    control.id = path;
    wrap.append(control);
    const hint = [s.description, rangeText(s), s.default !== undefined && s.default !== null ? `default ${s.default}` : ""]
      .filter(Boolean).join(" · ");
    if (hint) wrap.append(el("div", { class: "hint" }, hint));
    container.append(wrap);
    return control;
  }

  // Every property of a model, but those in opts.skip.
  function form(container, schema, obj, path, onChange, opts = {}) {
    const s = resolve(schema);
    for (const [key, prop] of Object.entries(s.properties || {})) {
      if ((opts.skip || []).includes(key)) continue;
      field(container, key, prop, obj, path ? `${path}.${key}` : key, onChange,
            { ...opts, skip: [], slider: (opts.sliders || []).includes(key) });
    }
  }

  // Show the loader's message beside the control of `fieldPath` (or its nearest enclosing one).
  function showError(fieldPath, message) {
    clearErrors();
    let path = fieldPath || "";
    while (path) {
      const target = document.querySelector(`[data-field="${CSS.escape(path)}"]`);
      if (target) {
        target.append(el("div", { class: "error-msg", role: "alert" }, message));
        target.querySelectorAll("input,select").forEach((i) => i.classList.add("invalid"));
        target.scrollIntoView({ block: "nearest" });
        return target;
      }
      path = path.replace(/(\.[^.\[]+|\[\d+\])$/, "");
    }
    const banner = document.getElementById("scene-error");
    banner.textContent = message;
    banner.hidden = false;
    return banner;
  }

  function clearErrors() {
    document.querySelectorAll(".error-msg").forEach((e) => e.remove());
    document.querySelectorAll(".invalid").forEach((e) => e.classList.remove("invalid"));
    document.getElementById("scene-error").hidden = true;
  }

  return { setSchema, resolve, plain, field, form, showError, clearErrors, el, defs: () => defs };
})();
