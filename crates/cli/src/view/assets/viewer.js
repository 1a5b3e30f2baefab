// The viewer page: polls /state and /frame.png, posts commands to /control. No dependencies.
"use strict";
const $ = (id) => document.getElementById(id);
const cam = { az: -40.8, el: 22.4, dist: 1.57, tx: 0.35, ty: 0.0, tz: 0.85 };
let state = null;
let frameNo = 0;
let sending = false;
let pendingJoints = null;
let switching = false; // a slider moved outside manual mode; the switch is under way

function frameUrl() {
  const q = Object.entries(cam).map(([k, v]) => `${k}=${v.toFixed(4)}`).join("&");
  return `/frame.png?${q}&n=${frameNo++}`;
}

// One frame in flight at a time: the next is asked for when this one has arrived.
function nextFrame() { $("frame").src = frameUrl(); }
$("frame").addEventListener("load", () => setTimeout(nextFrame, 30));
$("frame").addEventListener("error", () => setTimeout(nextFrame, 500));

async function send(command) {
  const r = await fetch("/control", { method: "POST", body: JSON.stringify(command) });
  $("error").textContent = r.ok ? "" : await r.text();
  await refresh();
  return r.ok;
}

// Slider moves are coalesced: while one joints command runs, only the latest waits.
async function sendJoints(degrees) {
  pendingJoints = degrees;
  if (sending) return;
  sending = true;
  while (pendingJoints) {
    const d = pendingJoints;
    pendingJoints = null;
    await send({ cmd: "joints", degrees: d });
  }
  sending = false;
}

function buildJoints(joints) {
  const box = $("joints");
  box.textContent = "";
  joints.forEach((j, i) => {
    const row = document.createElement("div");
    row.className = "joint";
    const name = document.createElement("span");
    name.textContent = `J${i + 1}`;
    name.title = j.name;
    const input = document.createElement("input");
    Object.assign(input, { type: "range", id: `joint-${i}`, step: "0.5" });
    input.min = Math.ceil(j.min_degrees);
    input.max = Math.floor(j.max_degrees);
    input.value = j.degrees;
    const value = document.createElement("span");
    value.id = `joint-${i}-value`;
    input.addEventListener("input", async () => {
      // Read the sliders now: a state poll answered before the mode change lands would move
      // them back to the arm's angles.
      const all = state.joints.map((_, k) => Number($(`joint-${k}`).value));
      if (state.mode !== "manual") {
        switching = true;
        await send({ cmd: "mode", mode: "manual" });
        switching = false;
      }
      sendJoints(all);
    });
    row.append(name, input, value);
    box.append(row);
  });
}

function show(s) {
  const first = state === null;
  state = s;
  if (first) {
    $("env").textContent = s.env;
    buildJoints(s.joints);
    for (const m of s.modes) $("mode").append(new Option(m, m));
  }
  $("mode").value = s.mode;
  $("status").textContent =
    `${s.playing ? "playing" : "paused"} · episode ${s.episode} · step ${s.step}` +
    ` · return ${s.episode_return.toFixed(3)}${s.done ? " · ended" : ""}`;
  s.joints.forEach((j, i) => {
    const input = $(`joint-${i}`);
    // In manual mode the sliders hold the targets the user set; otherwise they follow the arm.
    if (s.mode !== "manual" && !switching) input.value = j.degrees;
    $(`joint-${i}-value`).textContent = j.degrees.toFixed(1);
  });
  $("gripper").textContent = s.gripper_open ? "Close gripper" : "Open gripper";
  const rows = [["success", s.success ? "yes" : "no"], ["reward", s.reward.toFixed(4)]];
  for (const [k, v] of Object.entries(s.reward_terms || {})) rows.push([`reward · ${k}`, v.toFixed(4)]);
  for (const [k, v] of Object.entries(s.extras || {})) rows.push([k, Number(v).toFixed(4)]);
  const table = $("info");
  table.textContent = "";
  for (const [k, v] of rows) {
    const tr = table.insertRow();
    tr.insertCell().textContent = k;
    const td = tr.insertCell();
    td.className = "v" + (k === "success" && v === "yes" ? " ok" : "");
    td.textContent = v;
  }
}

// State answers can arrive out of order (the poll and a command's refresh race); one asked
// before an answer already shown is stale and would move the sliders back.
let stateAsked = 0;
let stateShown = 0;
async function refresh() {
  const ticket = ++stateAsked;
  try {
    const r = await fetch("/state");
    if (!r.ok) return;
    const s = await r.json();
    if (ticket < stateShown) return;
    stateShown = ticket;
    show(s);
  } catch (e) {
    $("error").textContent = `lost the server: ${e}`;
  }
}

for (const c of ["play", "pause", "step", "reset"]) $(c).addEventListener("click", () => send({ cmd: c }));
$("mode").addEventListener("change", () => send({ cmd: "mode", mode: $("mode").value }));
// The gripper button jogs too: it switches to manual mode first, like the sliders.
$("gripper").addEventListener("click", async () => {
  const open = !state.gripper_open;
  if (state.mode !== "manual" && !(await send({ cmd: "mode", mode: "manual" }))) return;
  send({ cmd: "gripper", open });
});

// Orbit: drag turns the camera around the target; the wheel moves it nearer or farther.
let drag = null;
$("frame").addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY }; e.preventDefault(); });
window.addEventListener("mouseup", () => { drag = null; });
window.addEventListener("mousemove", (e) => {
  if (!drag) return;
  cam.az -= (e.clientX - drag.x) * 0.4;
  cam.el = Math.max(-89, Math.min(89, cam.el + (e.clientY - drag.y) * 0.4));
  drag = { x: e.clientX, y: e.clientY };
});
$("frame").addEventListener("wheel", (e) => {
  cam.dist = Math.max(0.3, Math.min(6, cam.dist * Math.exp(e.deltaY * 0.001)));
  e.preventDefault();
}, { passive: false });

refresh().then(() => {
  if (state) { $("frame").width = state.frame.width; $("frame").height = state.frame.height; }
  nextFrame();
});
setInterval(refresh, 250);
