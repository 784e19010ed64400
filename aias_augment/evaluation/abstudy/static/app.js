// aias-abstudy rating page: plain JS, no dependencies. Keyboard: left/right arrow choose, down arrow (or C) cannot
// tell, space replays a clip. body[data-state] is "loading" | "name" | "ready" | "voting" | "done" (tests wait on it).
"use strict";

const $ = (id) => document.getElementById(id);
const state = { pair: null, ready: false, busy: false, shownAt: 0, total: 0, players: [] };

function setState(s) { document.body.dataset.state = s; }

function status(msg, isError) {
  const el = $("status");
  el.textContent = msg || "";
  el.classList.toggle("error", !!isError);
}

async function api(method, url, body) {
  const opts = { method, headers: {}, credentials: "same-origin" };
  if (body !== undefined) {
    opts.headers["Content-Type"] = "application/json";
    opts.body = JSON.stringify(body);
  }
  const resp = await fetch(url, opts);
  let data = null;
  try { data = await resp.json(); } catch (e) { data = null; }
  return { status: resp.status, ok: resp.ok, data };
}

function detail(r) {
  if (r.data && typeof r.data.detail === "string") return r.data.detail;
  if (r.data && Array.isArray(r.data.detail)) return r.data.detail.map((d) => d.msg).join("; ");
  return "HTTP " + r.status;
}

function show(section) {
  for (const id of ["intro", "trial", "done"]) $(id).hidden = id !== section;
}

function setProgress(done, total) {
  state.total = total;
  const shown = Math.min(done + 1, total);
  $("progress-text").textContent = `Pair ${shown} of ${total} (${done} rated)`;
  $("progress-bar").style.width = (total ? (100 * done) / total : 0) + "%";
}

// ----------------------------------------------------------------------------------------------- media
function loadImage(url) {
  return new Promise((resolve, reject) => {
    const img = new Image();
    img.onload = () => resolve(img);
    img.onerror = () => reject(new Error("cannot load " + url));
    img.src = url;
  });
}

// A clip is played as its frames on a canvas, both sides from one clock (no codec needed, frames stay in step).
class Flipbook {
  constructor(container, frames, fps) {
    this.frames = frames;
    this.fps = fps || 10;
    this.canvas = document.createElement("canvas");
    this.canvas.width = frames[0].naturalWidth;
    this.canvas.height = frames[0].naturalHeight;
    this.ctx = this.canvas.getContext("2d");
    container.appendChild(this.canvas);
    this.draw(0);
  }
  draw(i) { this.ctx.drawImage(this.frames[Math.max(0, Math.min(i, this.frames.length - 1))], 0, 0); }
}

function playAll() {
  const players = state.players;
  if (!players.length) return;
  const token = {};
  state.playToken = token;
  document.body.dataset.plays = String(Number(document.body.dataset.plays || 0) + 1);
  const t0 = performance.now();
  const n = Math.max(...players.map((p) => p.frames.length));
  const fps = players[0].fps;
  const step = (now) => {
    if (state.playToken !== token) return;
    // a frame's timestamp can precede t0 (it is the start of the frame in which playAll ran)
    const i = Math.max(0, Math.floor(((now - t0) / 1000) * fps));
    players.forEach((p) => p.draw(i));
    if (i < n - 1) requestAnimationFrame(step);
  };
  requestAnimationFrame(step);
}

async function render(pair) {
  state.ready = false;
  state.players = [];
  state.playToken = null;
  const sides = [["left", pair.left], ["right", pair.right]];
  for (const [side] of sides) $(side).querySelector(".media").replaceChildren();
  document.body.classList.toggle("clip", pair.kind === "clip");
  $("trial").dataset.pairId = pair.id;
  const loaded = await Promise.all(sides.map(([, urls]) => Promise.all(urls.map(loadImage))));
  if (state.pair !== pair) return;   // a newer pair was requested meanwhile
  sides.forEach(([side], k) => {
    const box = $(side).querySelector(".media");
    if (pair.kind === "clip") {
      state.players.push(new Flipbook(box, loaded[k], pair.fps));
    } else {
      const img = loaded[k][0];
      img.alt = side + " version";
      box.appendChild(img);
    }
  });
  if (pair.kind === "clip") playAll();
  state.ready = true;
  state.shownAt = performance.now();
  setState("ready");
}

// ------------------------------------------------------------------------------------------------ flow
async function next() {
  setState("loading");
  const r = await api("GET", "/api/next");
  if (!r.ok) {
    if (r.status === 400) return askName();
    status("Could not load the next pair: " + detail(r), true);
    return;
  }
  setProgress(r.data.done, r.data.total);
  if (!r.data.pair) {
    $("done-count").textContent = r.data.total;
    show("done");
    setState("done");
    $("results-link").focus();
    return;
  }
  show("trial");
  state.pair = r.data.pair;
  try {
    await render(state.pair);
  } catch (e) {
    status(e.message, true);
  }
}

async function vote(choice) {
  if (!state.ready || state.busy || !state.pair) return;
  state.busy = true;
  state.ready = false;
  setState("voting");
  const btn = $(choice === "left" ? "btn-left" : choice === "right" ? "btn-right" : "btn-tie");
  btn.classList.add("pressed");
  const ms = Math.round(performance.now() - state.shownAt);
  const r = await api("POST", "/api/vote", { pair_id: state.pair.id, choice, ms });
  btn.classList.remove("pressed");
  state.busy = false;
  if (r.status === 201) {
    status("");
  } else if (r.status === 409) {
    status("You had already rated that pair; your first vote counts.");
  } else {
    status("Your vote was not stored: " + detail(r), true);
    state.ready = true;
    setState("ready");
    return;
  }
  await next();
}

function askName() {
  show("intro");
  $("who").hidden = true;
  setState("name");
  $("name").focus();
}

async function start() {
  const [study, me] = await Promise.all([api("GET", "/api/study"), api("GET", "/api/me")]);
  if (study.ok) {
    $("title").textContent = study.data.title;
    document.title = study.data.title;
    $("total-pairs").textContent = study.data.pairs;
    document.body.classList.toggle("clip", study.data.kind === "clip");
    const word = study.data.kind === "clip" ? "video" : "photo";
    for (const el of document.querySelectorAll(".kind-word")) el.textContent = word;
  }
  if (me.ok && me.data.rater) {
    $("who-name").textContent = me.data.rater;
    $("who").hidden = false;
    await next();
  } else {
    askName();
  }
}

$("name-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const r = await api("POST", "/api/rater", { name: $("name").value });
  if (!r.ok) { status(detail(r), true); return; }
  status("");
  $("who-name").textContent = r.data.rater;
  $("who").hidden = false;
  $("name").blur();
  await next();
});

$("change-rater").addEventListener("click", (ev) => { ev.preventDefault(); $("name").value = ""; askName(); });

for (const b of document.querySelectorAll(".buttons button")) {
  b.addEventListener("click", () => vote(b.dataset.choice));
}

document.addEventListener("keydown", (ev) => {
  if (ev.target instanceof HTMLInputElement || ev.altKey || ev.ctrlKey || ev.metaKey) return;
  if ($("trial").hidden) return;
  const keys = { ArrowLeft: "left", ArrowRight: "right", ArrowDown: "tie", c: "tie", C: "tie" };
  if (ev.key in keys) {
    ev.preventDefault();
    if (!ev.repeat) vote(keys[ev.key]);
  } else if (ev.key === " " || ev.code === "Space") {
    ev.preventDefault();
    playAll();
  }
});

start();
