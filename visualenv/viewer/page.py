"""The viewer's page: plain HTML, CSS and a little inline JavaScript (no build step, nothing fetched from elsewhere).

It listens to ``/events`` (:mod:`visualenv.viewer.server`) and draws what each snapshot holds: the observation
pictures upscaled without smoothing, the high-resolution view, the values, the state, the located error of a spec
that does not build, and (on an interactive page) the keys, buttons and sliders that send ``/input``.

The elements tests and scripts read have ids: ``v-<value>`` (``v-step``, ``v-return``...), ``error``, ``status``,
and each picture's ``<img>`` has ``data-name`` (``observation``, a camera key, ``view``) and ``data-kind``.
"""

from __future__ import annotations

import html
import json

#: the values shown in the table, in order, with their labels (a value the snapshot lacks is left out)
FIELDS = (
    ("env", "env"),
    ("step", "step"),
    ("episode", "episode"),
    ("seed", "seed"),
    ("reward", "reward"),
    ("return", "return"),
    ("outcome", "outcome"),
    ("success", "success"),
    ("action", "action"),
    ("envs", "envs"),
)

_PAGE = """<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>__TITLE__ - visualenv</title>
<style>
  body { font: 14px/1.4 "Open Sans", system-ui, sans-serif; margin: 12px 16px; background: #15171c; color: #dfe3ea; }
  header { display: flex; gap: 16px; align-items: baseline; margin-bottom: 8px; }
  header b { font-size: 18px; }
  #spec { color: #8a93a3; }
  #status { margin-left: auto; color: #9fd29f; }
  #status.off { color: #e08080; }
  #error { background: #3a1616; color: #ffb4b4; border: 1px solid #a33; padding: 8px 10px; white-space: pre-wrap; margin: 0 0 10px; }
  main { display: flex; gap: 20px; align-items: flex-start; flex-wrap: wrap; }
  #pictures { display: flex; gap: 14px; flex-wrap: wrap; align-items: flex-start; }
  figure { margin: 0; }
  figcaption { color: #8a93a3; font-size: 12px; }
  img[data-kind=observation] { image-rendering: pixelated; image-rendering: crisp-edges; background: #000; }
  img[data-kind=view] { max-width: 640px; }
  aside { min-width: 260px; }
  table { border-collapse: collapse; margin-bottom: 10px; }
  td { padding: 1px 10px 1px 0; vertical-align: top; }
  td:first-child { color: #8a93a3; }
  h3 { font-size: 13px; margin: 8px 0 2px; color: #8a93a3; font-weight: normal; }
  #controls button, #controls select, #controls input { font: inherit; margin: 2px 4px 2px 0; }
  #controls input[type=number] { width: 6em; }
  kbd { border: 1px solid #556; border-radius: 3px; padding: 0 4px; background: #23262e; }
  .slider { display: block; }
</style>
</head>
<body>
<header><b id="title">__TITLE__</b><span id="spec"></span><span id="mode"></span><span id="status" class="off">connecting</span></header>
<pre id="error" hidden></pre>
<main>
  <section id="pictures"></section>
  <aside>
    <table><tbody id="values"></tbody></table>
    <h3>state</h3>
    <table><tbody id="state"></tbody></table>
    <div id="controls" hidden>
      <div>
        <button id="pause">pause</button><button id="step">step</button>
        <label>seed <input id="seed" type="number" min="0" step="1"></label><button id="reset">reset</button>
      </div>
      <div><label>speed <select id="speed"></select> steps/s</label></div>
      <h3>keys</h3>
      <table><tbody id="keys"></tbody></table>
      <div id="sliders"></div>
    </div>
  </aside>
</main>
<script>
"use strict";
const INTERACTIVE = __INTERACTIVE__;
const FIELDS = __FIELDS__;
const SPEEDS = [1, 2, 5, 10, 20, 30, 60, 120];
const ARROWS = {ArrowLeft: "left", ArrowRight: "right", ArrowUp: "up", ArrowDown: "down", " ": "space"};
const $ = (id) => document.getElementById(id);
let actionKeys = new Set(), held = new Set(), shownControls = "", latest = {};

let sending = Promise.resolve();
function send(message) {  // one after another: a key's release never overtakes its press
  if (!INTERACTIVE) return;
  const body = JSON.stringify(message);
  sending = sending.then(() => fetch("input", {method: "POST", headers: {"Content-Type": "application/json"}, body: body})).catch(() => {});
}
function text(value) {
  if (value === null || value === undefined) return "";
  if (typeof value === "number") return Number.isInteger(value) ? String(value) : value.toFixed(3);
  if (Array.isArray(value)) return "[" + value.map(text).join(", ") + "]";
  return String(value);
}
function rows(body, pairs) {
  body.replaceChildren(...pairs.map(([label, value]) => {
    const tr = document.createElement("tr");
    const a = document.createElement("td"), b = document.createElement("td");
    a.textContent = label; b.textContent = text(value); b.id = "v-" + label;
    tr.append(a, b);
    return tr;
  }));
}
function kbd(key) { return "<kbd>" + (ARROWS[key] || key) + "</kbd>"; }
function escape(s) { const d = document.createElement("div"); d.textContent = s; return d.innerHTML; }

function showPictures(names, pictures) {
  const box = $("pictures");
  for (const img of [...box.querySelectorAll("img")]) {
    if (!(img.dataset.name in names)) img.closest("figure").remove();
  }
  for (const [name, kind] of Object.entries(names)) {
    let img = box.querySelector('img[data-name="' + CSS.escape(name) + '"]');
    if (!img) {
      const figure = document.createElement("figure");
      img = document.createElement("img");
      img.dataset.name = name; img.dataset.kind = kind; img.alt = name;
      const caption = document.createElement("figcaption");
      figure.append(img, caption);
      if (kind === "view") box.append(figure); else box.prepend(figure);
    }
    const p = pictures[name];
    if (!p) continue;
    img.src = p.src;
    if (kind === "observation") {
      const scale = Math.max(1, Math.floor(320 / Math.max(p.width, p.height)));
      img.width = p.width * scale; img.height = p.height * scale;
    }
    img.nextSibling.textContent = (kind === "view" ? "view" : name) + " " + p.width + "\\u00d7" + p.height;
  }
}

function showControls(controls) {
  const key = JSON.stringify(controls || {});
  if (key === shownControls) return;
  shownControls = key;
  actionKeys = new Set();
  const body = $("keys");
  body.innerHTML = "";
  for (const entry of (controls && controls.keys) || []) {
    entry.keys.forEach((k) => actionKeys.add(k));
    const tr = document.createElement("tr");
    tr.innerHTML = "<td>" + entry.keys.map(kbd).join(" ") + "</td><td>" + escape(entry.text) + "</td>";
    body.append(tr);
  }
  const general = [[["space"], "pause / run"], [["."], "one step"], [["r"], "reset with the seed"], [["+", "-"], "faster / slower"]];
  for (const [keys, what] of general) {
    const tr = document.createElement("tr");
    tr.innerHTML = "<td>" + keys.map(kbd).join(" ") + "</td><td>" + what + "</td>";
    body.append(tr);
  }
  const sliders = $("sliders");
  sliders.innerHTML = "";
  for (const s of (controls && controls.sliders) || []) {
    const label = document.createElement("label");
    label.className = "slider";
    const input = document.createElement("input");
    Object.assign(input, {type: "range", min: s.low, max: s.high, step: (s.high - s.low) / 100, value: s.value});
    input.dataset.name = s.name;
    const out = document.createElement("span");
    out.textContent = " " + s.name + " " + text(s.value);
    input.addEventListener("input", () => {
      out.textContent = " " + s.name + " " + text(Number(input.value));
      send({type: "slider", name: s.name, value: Number(input.value)});
    });
    label.append(input, out);
    sliders.append(label);
  }
}

function show(event) {
  const v = event.values;
  latest = v;
  document.title = (v.title || "visualenv") + " - visualenv";
  $("title").textContent = v.title || "";
  $("spec").textContent = v.spec || "";
  $("mode").textContent = v.mode || "";
  const error = $("error");
  error.hidden = !v.error;
  error.textContent = v.error || "";
  $("status").textContent = v.status || "live";
  $("status").className = "";
  rows($("values"), FIELDS.filter(([key]) => key in v).map(([key, label]) => [label, v[key]]));
  rows($("state"), Object.entries(v.state || {}));
  showPictures(event.names, event.pictures);
  if (INTERACTIVE) {
    showControls(v.controls);
    $("pause").textContent = v.paused ? "run" : "pause";
    if (document.activeElement !== $("seed") && v.seed !== undefined) $("seed").value = v.seed;
    if (document.activeElement !== $("speed") && v.speed !== undefined) $("speed").value = String(v.speed);
  }
}

function speedBy(delta) {
  const now = SPEEDS.indexOf(Number(latest.speed));
  const next = SPEEDS[Math.min(SPEEDS.length - 1, Math.max(0, (now < 0 ? 3 : now) + delta))];
  send({type: "speed", value: next});
}
function reset() {
  const seed = $("seed").value === "" ? null : Number($("seed").value);
  send({type: "reset", seed: seed});
}

if (INTERACTIVE) {
  $("controls").hidden = false;
  for (const s of SPEEDS) $("speed").append(new Option(String(s), String(s)));
  $("speed").addEventListener("change", () => send({type: "speed", value: Number($("speed").value)}));
  $("pause").addEventListener("click", () => send({type: "pause"}));
  $("step").addEventListener("click", () => send({type: "step"}));
  $("reset").addEventListener("click", reset);
  document.addEventListener("keydown", (e) => {
    const typing = e.target instanceof HTMLInputElement && e.target.type !== "range" || e.target instanceof HTMLSelectElement;
    if (typing) { if (e.key === "Enter" && e.target === $("seed")) reset(); return; }
    if (actionKeys.has(e.key)) {
      e.preventDefault();
      if (!e.repeat && !held.has(e.key)) { held.add(e.key); send({type: "key", key: e.key, down: true}); }
    } else if (e.key === " ") { e.preventDefault(); if (!e.repeat) send({type: "pause"}); }
    else if (e.key === ".") send({type: "step"});
    else if (e.key === "r") reset();
    else if (e.key === "+" || e.key === "=") speedBy(1);
    else if (e.key === "-") speedBy(-1);
  });
  document.addEventListener("keyup", (e) => {
    if (held.delete(e.key)) send({type: "key", key: e.key, down: false});
  });
  window.addEventListener("blur", () => {
    for (const key of held) send({type: "key", key: key, down: false});
    held.clear();
  });
}

const events = new EventSource("events");
events.onmessage = (message) => show(JSON.parse(message.data));
events.onerror = () => { $("status").textContent = "disconnected: is the viewer still running?"; $("status").className = "off"; };
</script>
</body>
</html>
"""


def page_html(title: str, interactive: bool) -> str:
    """The page for an env titled `title`; `interactive` shows the controls and sends the keys."""
    return (
        _PAGE.replace("__TITLE__", html.escape(title))
        .replace("__INTERACTIVE__", "true" if interactive else "false")
        .replace("__FIELDS__", json.dumps(FIELDS))
    )
