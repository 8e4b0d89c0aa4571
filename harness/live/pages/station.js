// The participant station: consent, then each trial. While driving: the driver's view (a
// first-person WebGL view, driver_view.js; [live] view = "driver", the default) with a dashboard
// (speed, AUTOPILOT / MANUAL, the next turn of the route, the notices) and the top-down map as a
// mini-map, or the top-down map alone (view = "map", map_view.js); the takeover / hand-back control
// (button or space), manual driving while in control (accelerate / brake while the arrow key or
// button is held, pull out into the oncoming lane to pass an obstacle) and trust reports 1-7
// (buttons or keys). It speaks the websocket protocol of docs/live_studies.md; the HttpOnly
// participant cookie authenticates the socket. Texts are for the participant: no road ids.
import { DriverView, webglAvailable } from "./driver_view.js";
import { Calibration, Inputs, calibrationWanted } from "./inputs.js";
import { drawMap } from "./map_view.js";
import { drawArrow, nextTurn } from "./next_turn.js";

const $ = (id) => document.getElementById(id);
// Text set only where it changes: frames arrive 25 times a second, and each assignment of a text,
// the same one included, makes the browser lay out and paint the page again.
function setText(element, text) {
  if (element.textContent !== text) element.textContent = text;
}
const steps = ["consent-step", "declined-step", "ready-step", "drive-step", "questionnaire-step", "done-step"];
const MAP_SCALE = 3;        // pixels per metre of the large map
const MINI_SPAN = 370;      // metres across the mini-map (square, drawn at its displayed size)
const NOTICES = { obstacle: "Obstacle ahead in your lane", truck: "Truck ahead",
                  pedestrian: "Pedestrian ahead" };
let socket = null;
let state = { phase: "consent" };
let mode = "auto";
let viewKind = null;        // "driver" or "map", from the welcome message
let driverView = null;
let net = null;
let latest = null;          // the newest frame
let edges = {};             // road id -> the shape of its rightmost lane (the next turn)
let continuous = false;     // [live] driving = "continuous": wheel and pedals (inputs.js)
let inputs = null;
let askedForInput = false;   // the notice asks for an input the study allows
const CONTROL_INTERVAL = 1 / 30;   // s: controls are sent at most this often (the server's bucket)
let sentControl = null;
let sentAt = 0;
let lastRead = performance.now() / 1000;
const WARNINGS = { back_to_lane: "Back into your lane first: then hand back.", collision: "Collision!",
                   off_road: "You left the road.", oncoming: "", own_lane: "", on_road: "",
                   hold: "The junction is near: the car stops here. Hand back now.",
                   guide_back: "The junction is near: steer back into your lane, then hand back.",
                   held_off_lane: "Stopped before the junction: hand back now.",
                   stopped_off_road: "Off the road: the car has stopped. Hand back now." };

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

let driveOver = false;   // the drive shown has ended (done, aborted or failed), the next phase not yet told
// A drive runs: it is neither paused nor over. Nothing is sent for a drive that does not.
const driveRuns = () => state.phase === "driving" && !driveOver;

let pendingPrompt = null;   // the prompt a report answers ({episode_id, road}), else a free report

// "You reported N." comes with the server's `reported`: a report refused (paused, the trial over)
// is not one. Outside a drive nothing is sent, as with the keys.
function report(value) {
  if (!driveRuns()) return;
  send(pendingPrompt ? { type: "trust", value, prompt: pendingPrompt } : { type: "trust", value });
  pendingPrompt = null;
  $("prompt").classList.add("hidden");
}

// The hand-back is due: warned, or by wheel the car held for it (a hold's warning, or each frame's
// `held`: a takeover after the commit point is held with no warning to hand back, and a page
// opened mid-hold saw none). The ego waits for the hand-back, so it is said until it comes, over
// every other notice (a device asked for, an incident, the road's end) but what must be done first:
// a one-off notice, written over by the next, left a person held with nothing telling them why.
let handBackDue = false;
const HAND_BACK_DUE = "Hand back before the junction (space): the vehicle waits for you.";
let dueText = HAND_BACK_DUE;   // the words it is said in: a hold's own where its warning came

// what the person must do first, shown even while the hand-back is due (which it would not answer)
const FIRST = new Set(["back_to_lane", "guide_back"]);
// the warnings of a car held for the hand-back (harness/simulation/wheel_driving.py `Wheel.held`)
const HELD = new Set(["hold", "held_off_lane", "stopped_off_road"]);

function notice(text, first = false) {
  setText($("incident"), handBackDue && !first ? dueText : text);
}

function handBackNow(text = HAND_BACK_DUE) {
  handBackDue = true;
  dueText = text;
  notice("");
}

function overlay(text, resumable = false) {
  $("overlay").classList.toggle("hidden", !text);
  setText($("overlay-text"), text);
  $("resume").classList.toggle("hidden", !resumable);
}

let toggling = false;   // a takeover or hand-back sent, its mode change not yet seen

// The car is brought to a stand for the hand-back whatever the pedals say: by wheel, while the
// newest frame says so (`held`: the episode's one rule, harness/simulation/wheel_driving.py
// `Wheel.held`); in assisted driving from the warning on (the vehicle then stops for the hand-back).
function held() {
  return continuous ? latest !== null && latest.held === true : handBackDue;
}

function setMode(next) {
  mode = next;
  pedal = "release";
  toggling = false;
  if (next === "auto") { handBackDue = false; dueText = HAND_BACK_DUE; notice(""); }   // answered
  const indicator = $("mode");
  indicator.textContent = next === "manual" ? "MANUAL" : "AUTOPILOT";
  indicator.className = next;
  $("toggle").textContent = next === "manual" ? "Hand back (space)" : "Take over (space)";
  updateControls();
  if (next !== "manual") $("hint").textContent = "";
}

// Which driving control works now, whatever it comes from (a button, a key, a wheel or gamepad):
// none unless a drive runs (not while it is paused, nor before its vehicle is ready: no frame of it
// yet, nothing to take over; nor once it has ended, before the next phase is told), the pedals and
// the steering in control only, no accelerating while held for the hand-back (`held`), and no
// steering once the car stands held (it waits for the hand-back, and nothing else moves it).
function allowed(control) {
  if (!driveRuns() || !latest) return false;
  if (control === "toggle") return true;
  if (mode !== "manual") return false;
  if (control === "accelerate") return !held();
  return !(control === "steer" && held() && latest.speed === 0);
}

const DRIVING_CONTROLS = ["toggle", "accelerate", "brake", "pull-out", "pull-in"];   // their buttons' ids
function updateControls() {
  for (const control of DRIVING_CONTROLS) $(control).disabled = !allowed(control);
  for (const button of $("trust").querySelectorAll("button")) button.disabled = !driveRuns();   // as `report`
  if (pedal === "accelerate" && !allowed("accelerate")) press("release");
}

// Manual driving: a pedal is sent when pressed and `release` when let go (no key repeat: the
// server's flood limit counts every message). A pedal let go while the drive is paused is sent
// when it resumes (the server takes no control while paused, and the episode keeps the last).
let pedal = "release";
function press(next) {
  if (next === pedal || continuous || mode !== "manual" || (next !== "release" && !allowed(next))) return;
  pedal = next;
  if (driveRuns()) send({ type: "drive", pedal: next });
}

function steer(lane) {
  if (allowed(lane === "oncoming" ? "pull-out" : "pull-in") && !continuous) send({ type: "steer", lane });
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

// -- the next turn of the route (next_turn.js) ----------------------------------------------------
let drawnTurn;   // the arrow on the canvas (null: none); it is drawn again only when it changes
function drawTurn(turn) {
  if (turn === drawnTurn) return;
  drawnTurn = turn;
  $("turn").classList.toggle("hidden", !turn);
  drawArrow($("turn"), turn);
}

function showNextTurn(frame) {
  const { turn, text } = nextTurn(frame, edges);
  drawTurn(turn);
  setText($("turn-text"), text);
}

// -- frames ---------------------------------------------------------------------------------------
// Each frame drawn is confirmed (`shown`: its simulated time), at most one confirmation per
// SHOWN_INTERVAL and the newest always: the episode waits for a station that falls behind
// (docs/live_studies.md), so a slow browser does not leave the person deciding on what is past.
const SHOWN_INTERVAL = 0.04;   // s (the server's bucket allows 30 a second)
let shownAt = 0;
let shownTimer = null;
function confirmShown() {
  if (shownTimer !== null) return;   // the newest is confirmed when the timer fires
  const wait = shownAt + SHOWN_INTERVAL - performance.now() / 1000;
  if (wait > 0) {
    shownTimer = setTimeout(() => { shownTimer = null; confirmShown(); }, wait * 1000);
    return;
  }
  shownAt = performance.now() / 1000;
  if (latest) send({ type: "shown", t: latest.t });
}

// The mini-map's canvas takes its displayed size in device pixels: drawn at the map's own 640 x 480
// and shown in a 200 px square, it was squashed sideways and cost eight times the pixels. The size
// comes from a ResizeObserver: reading clientWidth at every frame would force a layout each time.
let miniSize = null;   // [width, height] in CSS pixels
new ResizeObserver(([entry]) => { miniSize = [entry.contentRect.width, entry.contentRect.height]; }).observe($("view"));
function miniScale(canvas) {
  const ratio = window.devicePixelRatio || 1;
  const [width, height] = (miniSize || [canvas.clientWidth, canvas.clientHeight]).map((size) => Math.round(size * ratio));
  if (width && height && (canvas.width !== width || canvas.height !== height)) [canvas.width, canvas.height] = [width, height];
  return Math.min(canvas.width, canvas.height) / MINI_SPAN;
}

function onFrame(frame) {
  const first = !latest;
  latest = frame;
  if (first) updateControls();   // the vehicle is ready: it can be taken over
  if (frame.held && frame.mode === "manual" && mode === "manual" && !handBackDue) handBackNow();
  if (state.phase !== "paused") overlay("");
  setText($("speed"), `${(frame.speed * 3.6).toFixed(0)} km/h`);
  const oncoming = onOncomingLane(frame);
  setText($("road"), oncoming ? "In the oncoming lane" : "");
  // which road (for tests and the experimenter), never shown
  if ($("road").dataset.road !== frame.road) $("road").dataset.road = frame.road;
  // the hint is for a person driving by hand: on autopilot (the frames after a hand-back) it goes
  setText($("hint"), frame.mode !== "manual" || continuous ? ""
    : oncoming ? "Passing in the oncoming lane: back into your lane once past the obstacle."
      : obstacleAhead(frame)
        ? "Obstacle ahead: pull out with \u2190 to pass it through the oncoming lane when the way is clear."
        : "");
  showNextTurn(frame);
  if (driverView) driverView.push(frame);
  if (state.phase === "paused") drawStill();
  else if (net) drawMap($("view"), net, frame, mapScale());
  confirmShown();
}

const mapScale = () => (viewKind === "map" ? MAP_SCALE : miniScale($("view")));

// A paused drive streams no frames and runs no animation loop: the view and the map show the
// newest frame where it stands (not moved on), drawn once both it and the net are here. A station
// opened during the pause gets the server's last frame, so the person sees where the car is
// before they resume.
function drawStill() {
  if (state.phase !== "paused" || !latest) return;
  if (net) drawMap($("view"), net, latest, mapScale());
  if (driverView) requestAnimationFrame(() => { if (state.phase === "paused") driverView.render(true); });
}

// Continuous driving: the wheel and pedals (or the keyboard) read at every animation frame, every
// device connected from one look at them; the controls are sent when they change, at most every
// CONTROL_INTERVAL.
function readInputs() {
  const now = performance.now() / 1000;
  const devices = inputs.devices();
  const controls = inputs.read(now - lastRead, latest ? latest.speed : 0, devices);
  lastRead = now;
  // a device to connect or to calibrate first: said, with the hand-back rule when due
  const ask = inputs.ask(devices);
  offerCalibration(ask);
  if (ask) {
    setText($("incident"), [ask, handBackDue ? dueText : ""].join(" ").trim());
    askedForInput = true;
  } else if (askedForInput) { askedForInput = false; notice(""); }   // connected, or calibrated, now
  if (!controls) {   // nothing the study allows can be read
    // the episode keeps the last control it was sent: a wheel or pad unplugged with the
    // accelerator down is let go (hands and feet off it), in the input it was read from
    if (sentControl && allowed("steer")) sendControl(now, sentControl.source, 0, 0, 0);
    return;
  }
  if (controls.toggle) toggle();
  if (!allowed("steer")) { sentControl = null; return; }
  // held, the episode brakes the car whatever the pedals say: they are sent let go
  const pedals = allowed("accelerate");
  const [throttle, brake] = pedals ? [controls.throttle, controls.brake] : [0, 0];
  sendControl(now, controls.source, controls.steer, throttle, brake);
}

// The controls, sent when they differ from those last sent, at most every CONTROL_INTERVAL.
function sendControl(now, source, steer, throttle, brake) {
  const changed = !sentControl || Math.abs(steer - sentControl.steer) > 0.005
    || Math.abs(throttle - sentControl.throttle) > 0.01 || Math.abs(brake - sentControl.brake) > 0.01;
  if (changed && now - sentAt >= CONTROL_INTERVAL) {
    sentControl = { source, steer, throttle, brake };
    sentAt = now;
    send({ type: "control", source, steer: round(steer), throttle: round(throttle), brake: round(brake) });
  }
}
const round = (value) => Math.round(value * 1000) / 1000;

// The animation loop runs while a trial drives, the one phase that draws the view or reads the
// wheel: an animation frame requested in any other phase makes the browser run its frame pipeline
// 60 times a second for nothing (about a tenth of a core with software rendering).
let animating = false;
function animate() {
  if (state.phase !== "driving") { animating = false; return; }
  if (inputs) readInputs();
  if (driverView) driverView.render();
  requestAnimationFrame(animate);
}

function startAnimating() {
  if (animating) return;
  animating = true;
  lastRead = performance.now() / 1000;   // the keys turn the wheel by the time since the last read
  if (inputs) inputs.read(0);             // a button held since before is not a press
  requestAnimationFrame(animate);
}

function setDriving(kind, allowed = ["wheel", "gamepad", "keyboard"]) {
  continuous = kind === "continuous";
  if (continuous && !inputs) inputs = new Inputs(allowed);
  $("manual-controls").classList.toggle("hidden", continuous);
  $("wheel-help").classList.toggle("hidden", !continuous);
  if (continuous && !allowed.includes("keyboard")) {   // the keys are no help where they are not read
    $("wheel-help").textContent = "In control: steer with the wheel, accelerate and brake with the pedals.";
  }
  offerCalibration(inputs ? inputs.ask() : "");
}

// *Calibrate the wheel* (inputs.js, `Calibration`): on the ready step of a continuous study, and in
// a drive while a device connected waits for its calibration or a control is on no device read
// (`calibrationWanted`), or while one is under way; the ready step says beside it what is wanted.
// Called at every animation frame of a drive: the box's class is set, and the box moved, only when
// that changes.
let boxShown = null;
function offerCalibration(ask) {
  const calibrating = !$("calibrate-next").classList.contains("hidden");
  const wanted = calibrationWanted(ask);
  const shown = continuous && (state.phase === "ready" || (inDrive(state.phase) && (wanted || calibrating)));
  const box = $("calibrate-box");
  if (shown !== boxShown) { box.classList.toggle("hidden", !shown); boxShown = shown; }
  // in a drive below the view, so the view the person watches does not move
  const before = inDrive(state.phase) ? document.querySelector("#drive-step .trust-now") : $("trial-text");
  if (box.nextElementSibling !== before) before.before(box);
  // out of a walk-through the box says the last calibration made and, on the ready step, what is
  // still wanted (a pedal box calibrated alone: the steering), so neither hides the other
  const said = state.phase === "ready" && wanted ? ask : "";
  if (!calibrating) setText($("calibration-text"), [calibratedText, said].filter(Boolean).join(" "));
}
// the ready step runs no animation loop to read the device: it is looked at twice a second
setInterval(() => { if (inputs && state.phase === "ready") offerCalibration(inputs.ask()); }, 500);

let calibration = null;
let calibratedText = "";   // what the last calibration made said it calibrated
$("calibrate").addEventListener("click", () => {
  calibratedText = "";
  calibration = new Calibration((text) => { $("calibration-text").textContent = text; });
  $("calibrate-next").classList.remove("hidden");
});
$("calibrate-next").addEventListener("click", () => {
  const done = calibration && calibration.next();
  if (done) {
    calibratedText = $("calibration-text").textContent;
    inputs.calibrated(done);
    $("calibrate-next").classList.add("hidden");
  }
});

function setView(kind) {
  if (kind === "driver" && !webglAvailable()) {
    kind = "map";   // the fallback: this browser has no WebGL, so the top-down map is shown
    $("error").textContent = "This browser cannot show the driver's view (no WebGL): showing the map instead.";
  }
  if (viewKind === kind) return;
  viewKind = kind;
  $("scene").className = kind;
  const map = $("view");
  [map.width, map.height] = kind === "map" ? [640, 480] : [200, 200];
  $("legend").classList.toggle("hidden", kind === "driver");
  if (kind === "driver") {
    driverView = new DriverView($("driver"));
    window.driverView = driverView;   // its stats (renders, frames, pose, camera) for measurements
    if (net) driverView.setNet(net);
  }
}

async function loadNet() {
  const response = await fetch("/api/net");
  if (!response.ok) return;
  net = await response.json();
  edges = {};
  for (const lane of net.lanes) {
    const edge = lane.id.slice(0, lane.id.lastIndexOf("_"));
    if (!(edge in edges) || (lane.index ?? 0) === 0) edges[edge] = lane.shape;
  }
  if (driverView) driverView.setNet(net);
  drawStill();
}

// -- the session ----------------------------------------------------------------------------------
let shownEpisode = null;   // the episode the drive step shows
// What the server said of the drive this window saw end (its end's `station`: "Trial 1 of 4 is
// complete.", "The warm-up drive was stopped by the experimenter; ..."), until the next starts;
// `stopped`: it ended otherwise than complete, and is run again.
let ended = { text: "", stopped: false };

// The consent text, a paragraph for each block of it (blocks are separated by a blank line).
function showConsent(text) {
  $("consent-text").replaceChildren(...text.split(/\n\s*\n/).filter((block) => block.trim()).map((block) => {
    const paragraph = document.createElement("p");
    paragraph.textContent = block.trim();
    return paragraph;
  }));
}

// Between drives (the next one's start, a questionnaire) how the drive just ended is said.
function showCompleted(phase) {
  const text = phase === "ready" || phase === "questionnaire" ? ended.text : "";
  setText($("completed"), text);
  $("completed").classList.toggle("hidden", !text);
  $("completed").classList.toggle("stopped", ended.stopped);
}

const inDrive = (phase) => phase === "driving" || phase === "paused";

function onState(message) {
  const resumed = state.phase === "paused" && message.phase === "driving";
  if (message.phase !== state.phase) calibratedText = "";   // said on the step it was made on
  state = message;
  if (inputs) offerCalibration(inputs.ask());
  if (resumed && mode === "manual" && !continuous) send({ type: "drive", pedal });
  updateControls();
  // a new trial starts driving: the last trial's frame, speed and mode go at once (its SUMO takes
  // seconds to start; meanwhile the person sees the vehicle getting ready, not the last trial)
  // (a page opened while the drive is paused shows its episode too: the server's last frame of it
  // follows, and the resume goes on from it)
  if (inDrive(message.phase) && message.episode_id !== shownEpisode) startEpisode(message.episode_id);
  // the mode is the session's: a page opened mid-drive (reloaded, another window) saw none of the
  // `mode` events before it, and showing AUTOPILOT to a person in control, its button would ask for
  // a takeover the server refuses and never hand back (a request in flight is answered by `mode`)
  if (inDrive(message.phase) && !toggling && message.mode !== mode) {
    setMode(message.mode);
  }
  if (message.phase === "driving") startAnimating();
  // the trial's words are the server's (harness/live/session.py, `Session.station_texts`)
  $("status").textContent = message.phase === "paused"
    ? `Paused (${message.paused_by === "disconnect" ? "connection lost" : "by the experimenter"})`
    : message.station.status;
  if (message.phase === "paused") {
    overlay(message.paused_by === "disconnect"
      ? "Paused: the connection was lost. Press Resume to go on."
      : "Paused by the experimenter. Please wait.", message.paused_by === "disconnect");
  } else if (message.phase === "driving" && !latest) overlay("The vehicle is getting ready\u2026");
  else if (message.phase === "driving") overlay("");
  showCompleted(message.phase);
  if (message.phase === "consent") show("consent-step");
  else if (message.phase === "declined") closed("", "declined-step");
  else if (message.phase === "ready") {
    $("trial-text").textContent = message.station.next;
    show("ready-step");
  } else if (inDrive(message.phase)) show("drive-step");
  else if (message.phase === "questionnaire") {   // questionnaire.js
    $("status").textContent = "Questionnaire";
    renderQuestionnaire(message.questionnaire, send);
    show("questionnaire-step");
  } else if (message.phase === "done") show("done-step");
}

// The drive's end, in the server's words (harness/live/session.py `station_end`): said over the
// view standing still when the drive did not complete, and above the next step until the next drive.
function endDrive(message) {
  driveOver = true;
  ended = { text: message.station, stopped: message.type !== "episode_end" };
  if (ended.stopped) overlay(message.station);
  updateControls();
}

function startEpisode(episodeId) {
  // the last drive's report is not this one's; one given while this drive got ready (its
  // `episode_start` comes once its SUMO runs) is
  if (episodeId !== shownEpisode) $("reported").textContent = "";
  shownEpisode = episodeId;
  ended = { text: "", stopped: false };
  driveOver = false;
  latest = null;
  if (driverView) driverView.clear();
  setMode("auto");
  notice("");
  $("speed").textContent = "";
  $("road").textContent = "";
  delete $("road").dataset.road;
  drawTurn(null);
  $("turn-text").textContent = "";
  overlay("The vehicle is getting ready\u2026");
}

function onMessage(message) {
  switch (message.type) {
    case "welcome":
      showConsent(message.consent);
      setView(message.view === "map" ? "map" : "driver");
      setDriving(message.driving, message.inputs);
      break;
    case "state": onState(message); break;
    case "frame": onFrame(message); break;
    case "reported": $("reported").textContent = `You reported ${message.value}.`; break;
    case "mode": setMode(message.mode); break;
    case "incident": notice(NOTICES[message.kind] || ""); break;
    case "warning":
      if (message.kind === "hand_back") handBackNow();
      else if (HELD.has(message.kind)) handBackNow(WARNINGS[message.kind]);
      else if (message.kind in WARNINGS) notice(WARNINGS[message.kind], FIRST.has(message.kind));
      updateControls();
      break;
    case "road":
      notice("");
      if (message.prompt) { pendingPrompt = message.prompt; $("prompt").classList.remove("hidden"); }
      break;
    case "episode_start": startEpisode(message.episode_id); pendingPrompt = null; break;
    case "episode_end": case "episode_aborted": case "episode_failed": endDrive(message); break;
    case "notice": $("error").textContent = message.detail; break;
    case "error": {
      toggling = false;   // a refused takeover or hand-back may be tried again
      if (state.phase === "paused") break;   // the overlay says why nothing moves
      const text = message.code === "out_of_order" ? "Not possible right now." : message.detail;
      $("error").textContent = text;
      setTimeout(() => { if ($("error").textContent === text) $("error").textContent = ""; }, 5000);
      break;
    }
    default: break;
  }
}

// Close codes after which reconnecting would be wrong: another window holds the session (4001),
// or the link was revoked (1008), by a withdrawal too (its close reason "withdrawn").
const FINAL_CLOSE = { 4001: "This session is open in another window or tab; continue there.",
                      1008: "This session's link was revoked or is not valid; ask the experimenter." };
const WITHDRAWN = "You have withdrawn from the study; your data has been deleted. You can close this window.";

// The session is over in this window: its text, the step to show instead of the current one
// (null: none), and nothing left to press.
function closed(text, step) {
  state = { phase: "closed" };
  $("error").textContent = text;
  setText($("status"), "");
  showCompleted("closed");
  if (step !== undefined) show(step);
  for (const control of document.querySelectorAll("button, input")) control.disabled = true;
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/ws`);
  socket.addEventListener("message", (event) => onMessage(JSON.parse(event.data)));
  socket.addEventListener("close", (event) => {
    // withdrawn: every drive and answer is deleted, no step of the study is shown
    if (event.code === 1008 && event.reason === "withdrawn") { closed(WITHDRAWN, null); return; }
    if (event.code === 1008 && event.reason === "declined") { closed("", "declined-step"); return; }
    if (FINAL_CLOSE[event.code]) { closed(FINAL_CLOSE[event.code]); return; }
    $("error").textContent = "Connection lost; reconnecting...";
    setTimeout(connect, 1000);
  });
  socket.addEventListener("open", () => { $("error").textContent = ""; });
}
setInterval(() => send({ type: "ping" }), 20000);   // the server closes a socket silent for a minute

function toggle() {
  if (!allowed("toggle") || toggling) return;   // one request until the mode changes
  toggling = true;
  send({ type: mode === "manual" ? "hand_back" : "takeover" });
}

$("agree").addEventListener("click", () => send({ type: "consent", agree: true }));
$("decline").addEventListener("click", () => send({ type: "consent", agree: false }));
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
  if (!continuous && PEDALS[event.code] && pedal === PEDALS[event.code]) press("release");
});
$("resume").addEventListener("click", () => send({ type: "resume" }));
document.addEventListener("keydown", (event) => {
  if (state.phase !== "driving") return;
  if (event.code === "Space") { event.preventDefault(); toggle(); }
  else if (continuous && event.code.startsWith("Arrow")) event.preventDefault();   // inputs.js reads them
  else if (PEDALS[event.code]) { event.preventDefault(); if (!event.repeat) press(PEDALS[event.code]); }
  else if (event.code === "ArrowLeft") { event.preventDefault(); steer("oncoming"); }
  else if (event.code === "ArrowRight") { event.preventDefault(); steer("own"); }
  else if (/^[1-7]$/.test(event.key)) report(Number(event.key));
});
loadNet();
connect();
