// The participant station: consent, then each trial; the mode indicator, a view of the ego's
// path, the takeover / hand-back control (button or space) and trust reports 1-7 (buttons or
// keys). It speaks the websocket protocol of docs/live_studies.md; the HttpOnly participant
// cookie authenticates the socket.
"use strict";

const $ = (id) => document.getElementById(id);
const steps = ["consent-step", "ready-step", "drive-step", "done-step"];
let socket = null;
let state = { phase: "consent" };
let mode = "auto";
const trail = [];

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

function report(value) {
  send({ type: "trust", value });
  $("reported").textContent = `You reported ${value}.`;
  $("prompt").classList.add("hidden");
}

function setMode(next) {
  mode = next;
  const indicator = $("mode");
  indicator.textContent = next === "manual" ? "MANUAL" : "AUTOPILOT";
  indicator.className = next;
  $("toggle").textContent = next === "manual" ? "Hand back (space)" : "Take over (space)";
}

function draw(frame) {
  trail.push([frame.x, frame.y]);
  if (trail.length > 2000) trail.shift();
  const canvas = $("view");
  const context = canvas.getContext("2d");
  const scale = 1.5;   // pixels per metre, the ego at the centre
  const toCanvas = ([x, y]) => [canvas.width / 2 + (x - frame.x) * scale, canvas.height / 2 - (y - frame.y) * scale];
  context.clearRect(0, 0, canvas.width, canvas.height);
  context.strokeStyle = "#999";
  context.lineWidth = 6;
  context.beginPath();
  trail.forEach((point, i) => { const [u, v] = toCanvas(point); if (i) context.lineTo(u, v); else context.moveTo(u, v); });
  context.stroke();
  context.save();
  context.translate(canvas.width / 2, canvas.height / 2);
  context.rotate((frame.angle * Math.PI) / 180);   // SUMO's angle: degrees clockwise from north
  context.fillStyle = frame.mode === "manual" ? "#c62828" : "#2e7d32";
  context.fillRect(-4, -8, 8, 16);
  context.restore();
  $("speed").textContent = `${(frame.speed * 3.6).toFixed(0)} km/h`;
  $("road").textContent = `road ${frame.road}`;
}

function onState(message) {
  state = message;
  $("status").textContent = message.phase === "paused"
    ? `Paused (${message.paused_by === "disconnect" ? "connection lost" : "by the experimenter"})`
    : `Trial ${message.trial} of ${message.trials}`;
  $("resume").classList.toggle("hidden", !(message.phase === "paused" && message.paused_by === "disconnect"));
  if (message.phase === "consent") show("consent-step");
  else if (message.phase === "ready") {
    $("trial-text").textContent = `Next: trial ${message.done.length + 1} of ${message.trials}.`;
    show("ready-step");
  } else if (message.phase === "driving" || message.phase === "paused") show("drive-step");
  else if (message.phase === "done") show("done-step");
}

function onMessage(message) {
  switch (message.type) {
    case "welcome": $("consent-text").textContent = message.consent; break;
    case "state": onState(message); break;
    case "frame": draw(message); break;
    case "mode": setMode(message.mode); break;
    case "incident": $("incident").textContent = `Ahead: ${message.kind}`; break;
    case "road":
      $("incident").textContent = "";
      $("prompt").classList.remove("hidden");
      break;
    case "episode_start": trail.length = 0; setMode("auto"); break;
    case "episode_end": $("status").textContent = "Trial complete."; break;
    case "episode_aborted": $("status").textContent = "The trial was stopped; it will be run again."; break;
    case "episode_failed": $("error").textContent = "The trial failed; it will be run again."; break;
    case "error": $("error").textContent = message.detail; break;
    default: break;
  }
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws`);
  socket.addEventListener("message", (event) => onMessage(JSON.parse(event.data)));
  socket.addEventListener("close", () => {
    $("error").textContent = "Connection lost; reconnecting...";
    setTimeout(connect, 1000);
  });
  socket.addEventListener("open", () => { $("error").textContent = ""; });
}

function toggle() {
  if (state.phase === "driving") send({ type: mode === "manual" ? "hand_back" : "takeover" });
}

$("agree").addEventListener("click", () => send({ type: "consent", agree: true }));
trustButtons($("start-trust"), (value) => send({ type: "start", trust: value }));
trustButtons($("trust"), report);
$("toggle").addEventListener("click", toggle);
$("resume").addEventListener("click", () => send({ type: "resume" }));
document.addEventListener("keydown", (event) => {
  if (state.phase !== "driving") return;
  if (event.code === "Space") { event.preventDefault(); toggle(); }
  else if (/^[1-7]$/.test(event.key)) report(Number(event.key));
});
connect();
