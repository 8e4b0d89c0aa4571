// The participant station: consent, then each trial; the mode indicator, a top-down view (the
// net's lanes, the ego, traffic and the incidents' objects around it), the takeover / hand-back
// control (button or space), manual driving while in control (accelerate / brake while the arrow
// key or button is held, pull out into the oncoming lane to pass an obstacle) and trust reports
// 1-7 (buttons or keys). It speaks the websocket protocol of docs/live_studies.md; the HttpOnly participant
// cookie authenticates the socket.
"use strict";

const $ = (id) => document.getElementById(id);
const steps = ["consent-step", "ready-step", "drive-step", "questionnaire-step", "done-step"];
let socket = null;
let state = { phase: "consent" };
let mode = "auto";

function show(step) {
  for (const id of steps) $(id).classList.toggle("hidden", id !== step);
}

function send(message) {
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
}

function trustButtons(container, onPick) {
  for (let value = 1; value <= 7; value++) {
    const button = document.createElement("button");
    button.textContent = String(value);
    button.addEventListener("click", () => onPick(value));
    container.appendChild(button);
  }
}

let pendingPrompt = null;   // the prompt a report answers ({episode_id, road}), else a free report

function report(value) {
  send(pendingPrompt ? { type: "trust", value, prompt: pendingPrompt } : { type: "trust", value });
  pendingPrompt = null;
  $("reported").textContent = `You reported ${value}.`;
  $("prompt").classList.add("hidden");
}

let handBackDue = false;   // warned: the ego waits for the hand-back; the warning stays up until it

function notice(text) {
  $("incident").textContent = handBackDue
    ? "Hand back before the junction (space): the vehicle waits for you."
    : text;
}

let toggling = false;   // a takeover or hand-back sent, its mode change not yet seen

function setMode(next) {
  mode = next;
  pedal = "release";
  toggling = false;
  if (next === "auto") { handBackDue = false; notice(""); }   // the hand-back warning is answered
  const indicator = $("mode");
  indicator.textContent = next === "manual" ? "MANUAL" : "AUTOPILOT";
  indicator.className = next;
  $("toggle").textContent = next === "manual" ? "Hand back (space)" : "Take over (space)";
  for (const id of ["accelerate", "brake", "pull-out", "pull-in"]) $(id).disabled = next !== "manual";
  if (next !== "manual") $("hint").textContent = "";
}

// Manual driving: a pedal is sent when pressed and `release` when let go (no key repeat: the
// server's flood limit counts every message).
let pedal = "release";
function press(next) {
  if (mode !== "manual" || next === pedal) return;
  pedal = next;
  send({ type: "drive", pedal: next });
}

function steer(lane) {
  if (mode === "manual") send({ type: "steer", lane });
}

function obstacleAhead(frame) {
  const heading = (frame.angle * Math.PI) / 180;   // clockwise from north
  return (frame.vehicles || []).some(([x, y, , kind]) => {
    const ahead = (x - frame.x) * Math.sin(heading) + (y - frame.y) * Math.cos(heading);
    const aside = (x - frame.x) * Math.cos(heading) - (y - frame.y) * Math.sin(heading);
    return kind === "obstacle" && ahead > 0 && ahead < 80 && Math.abs(aside) < 4;   // in the ego's lane
  });
}

function onOncomingLane(frame) {
  const [u, v] = String(frame.road).split("-");
  return v !== undefined && String(frame.lane).startsWith(`${v}-${u}_`);
}

const COLOURS = { traffic: "#1e5aa8", obstacle: "#e67e00", oncoming: "#7b1fa2", parked: "#7b1fa2",
                  pedestrian: "#d81b60" };
let lanes = [];
let junctions = {};

async function loadNet() {
  const response = await fetch("/api/net");
  if (response.ok) ({ lanes, junctions } = await response.json());
}

function box(context, toCanvas, x, y, angle, length, width, colour, scale, outline) {
  const [u, v] = toCanvas(x, y);
  context.save();
  context.translate(u, v);
  context.rotate((angle * Math.PI) / 180);   // SUMO's angle: degrees clockwise from north
  context.fillStyle = colour;
  context.fillRect((-width / 2) * scale, 0, width * scale, length * scale);   // the front at (x, y)
  if (outline) {   // the ego: outlined, with its heading marked, so it stands out from traffic
    context.strokeStyle = outline;
    context.lineWidth = 2;
    context.strokeRect((-width / 2) * scale, 0, width * scale, length * scale);
    context.fillStyle = outline;
    context.beginPath();
    context.moveTo(0, -3 * scale);
    context.lineTo((-width / 2) * scale, -0.5 * scale);
    context.lineTo((width / 2) * scale, -0.5 * scale);
    context.fill();
  }
  context.restore();
}

function draw(frame) {
  const canvas = $("view");
  const context = canvas.getContext("2d");
  const scale = 3;   // pixels per metre, north up, the ego at the centre
  const toCanvas = (x, y) => [canvas.width / 2 + (x - frame.x) * scale, canvas.height / 2 - (y - frame.y) * scale];
  context.fillStyle = "#dfe8d8";
  context.fillRect(0, 0, canvas.width, canvas.height);
  context.lineCap = "round";
  // two passes: a light band per lane, then the asphalt a little narrower, so that the lanes of a
  // road stay apart by a thin marking
  for (const [colour, inset] of [["#f4f4f4", 0], [null, 1.5]]) {
    for (const lane of lanes) {
      context.strokeStyle = colour || (lane.internal ? "#8c8c8c" : "#6f6f6f");
      context.lineWidth = Math.max(lane.width * scale - inset, 1);
      context.beginPath();
      lane.shape.forEach(([x, y], i) => { const [u, v] = toCanvas(x, y); if (i) context.lineTo(u, v); else context.moveTo(u, v); });
      context.stroke();
    }
  }
  const next = junctions[frame.junction];
  if (next) {   // the junction the ego drives to: the policy chooses the road after it
    const [u, v] = toCanvas(next[0], next[1]);
    context.strokeStyle = "#f9a825";
    context.lineWidth = 3;
    context.beginPath();
    context.arc(u, v, 9 * scale, 0, 2 * Math.PI);
    context.stroke();
  }
  for (const [x, y, angle, kind] of frame.vehicles || []) {
    const truck = kind === "oncoming" || kind === "parked";
    box(context, toCanvas, x, y, angle, truck ? 10 : 4.5, truck ? 2.5 : 1.8, COLOURS[kind] || COLOURS.traffic, scale);
  }
  for (const [x, y, kind] of frame.persons || []) {
    const [u, v] = toCanvas(x, y);
    context.fillStyle = COLOURS[kind] || COLOURS.pedestrian;
    context.beginPath();
    context.arc(u, v, 0.6 * scale, 0, 2 * Math.PI);
    context.fill();
  }
  box(context, toCanvas, frame.x, frame.y, frame.angle, 4.5, 1.8, frame.mode === "manual" ? "#c62828" : "#2e7d32", scale,
      "#ffffff");
  $("speed").textContent = `${(frame.speed * 3.6).toFixed(0)} km/h`;
  $("road").textContent = `road ${frame.road}` + (onOncomingLane(frame) ? " (oncoming lane)" : "");
  if (frame.mode === "manual") {
    $("hint").textContent = onOncomingLane(frame)
      ? "Passing in the oncoming lane: back into your lane once past the obstacle."
      : obstacleAhead(frame)
        ? "Obstacle ahead: pull out with \u2190 to pass it through the oncoming lane when the way is clear."
        : "";
  }
}

function onState(message) {
  state = message;
  $("status").textContent = message.phase === "paused"
    ? `Paused (${message.paused_by === "disconnect" ? "connection lost" : "by the experimenter"})`
    : message.warm_up === "pending" ? "Warm-up drive" : `Trial ${message.trial} of ${message.trials}`;
  $("resume").classList.toggle("hidden", !(message.phase === "paused" && message.paused_by === "disconnect"));
  if (message.phase === "consent") show("consent-step");
  else if (message.phase === "ready") {
    $("trial-text").textContent = message.warm_up === "pending"
      ? "Next: a warm-up drive, to get to know the vehicle."
      : `Next: trial ${message.done.length + 1} of ${message.trials}.`;
    show("ready-step");
  } else if (message.phase === "driving" || message.phase === "paused") show("drive-step");
  else if (message.phase === "questionnaire") {   // questionnaire.js
    $("status").textContent = "Questionnaire";
    renderQuestionnaire(message.questionnaire, send);
    show("questionnaire-step");
  } else if (message.phase === "done") show("done-step");
}

function onMessage(message) {
  switch (message.type) {
    case "welcome": $("consent-text").textContent = message.consent; break;
    case "state": onState(message); break;
    case "frame": draw(message); break;
    case "mode": setMode(message.mode); break;
    case "incident": notice(`Ahead: ${message.kind}`); break;
    case "warning": handBackDue = true; notice(""); break;
    case "road":
      notice("");
      if (message.prompt) { pendingPrompt = message.prompt; $("prompt").classList.remove("hidden"); }
      break;
    case "episode_start": setMode("auto"); pendingPrompt = null; break;
    case "episode_end": $("status").textContent = "Trial complete."; break;
    case "episode_aborted": $("status").textContent = "The trial was stopped; it will be run again."; break;
    case "episode_failed": $("error").textContent = "The trial failed; it will be run again."; break;
    case "notice": $("error").textContent = message.detail; break;
    case "error":
      toggling = false;   // a refused takeover or hand-back may be tried again
      $("error").textContent = message.detail;
      setTimeout(() => { if ($("error").textContent === message.detail) $("error").textContent = ""; }, 5000);
      break;
    default: break;
  }
}

// Close codes after which reconnecting would be wrong: another window holds the session (4001),
// or the link was revoked (1008).
const FINAL_CLOSE = { 4001: "This session is open in another window or tab; continue there.",
                      1008: "This session's link was revoked or is not valid; ask the experimenter." };

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws`);
  socket.addEventListener("message", (event) => onMessage(JSON.parse(event.data)));
  socket.addEventListener("close", (event) => {
    if (FINAL_CLOSE[event.code]) { $("error").textContent = FINAL_CLOSE[event.code]; return; }
    $("error").textContent = "Connection lost; reconnecting...";
    setTimeout(connect, 1000);
  });
  socket.addEventListener("open", () => { $("error").textContent = ""; });
}
setInterval(() => send({ type: "ping" }), 20000);   // the server closes a socket silent for a minute

function toggle() {
  if (state.phase !== "driving" || toggling) return;   // one request until the mode changes
  toggling = true;
  send({ type: mode === "manual" ? "hand_back" : "takeover" });
}

$("agree").addEventListener("click", () => send({ type: "consent", agree: true }));
trustButtons($("start-trust"), (value) => send({ type: "start", trust: value }));
trustButtons($("trust"), report);
$("toggle").addEventListener("click", toggle);
for (const [id, which] of [["accelerate", "accelerate"], ["brake", "brake"]]) {
  $(id).addEventListener("pointerdown", () => press(which));
  for (const end of ["pointerup", "pointerleave"]) $(id).addEventListener(end, () => press("release"));
}
$("pull-out").addEventListener("click", () => steer("oncoming"));
$("pull-in").addEventListener("click", () => steer("own"));
const PEDALS = { ArrowUp: "accelerate", ArrowDown: "brake" };
document.addEventListener("keyup", (event) => {
  if (PEDALS[event.code] && pedal === PEDALS[event.code]) press("release");
});
$("resume").addEventListener("click", () => send({ type: "resume" }));
document.addEventListener("keydown", (event) => {
  if (state.phase !== "driving") return;
  if (event.code === "Space") { event.preventDefault(); toggle(); }
  else if (PEDALS[event.code]) { event.preventDefault(); if (!event.repeat) press(PEDALS[event.code]); }
  else if (event.code === "ArrowLeft") { event.preventDefault(); steer("oncoming"); }
  else if (event.code === "ArrowRight") { event.preventDefault(); steer("own"); }
  else if (/^[1-7]$/.test(event.key)) report(Number(event.key));
});
loadNet();
connect();
