// Continuous driving inputs ([live] driving = "continuous"): steering wheels, pedal boxes and
// gamepads through the browser's Gamepad API, every device connected read at once, each calibrated
// once and remembered by this browser for its id (localStorage), or the keyboard as the fallback.
// `read(seconds)` gives the controls now: {steer: -1 (full left) .. 1 (full right), throttle: 0..1,
// brake: 0..1, toggle: true once when the take-over / hand-back button is pressed, source: "wheel" |
// "gamepad" | "keyboard"}, or null when nothing the study allows ([live] inputs) is there to read.
//
// A device in the browser's "standard" mapping is a gamepad; any other (a wheel's, a pedal box's)
// is a wheel.
//
// A device is read by the calibration saved for its id, which gives the controls found on it (a
// pedal box: the accelerator and the brake; a wheel whose pedals are a device of their own: the
// steering and the button), else, in the browser's "standard" mapping, as a gamepad giving them
// all (left stick: steer, right trigger: throttle, left trigger: brake, A: take over / hand back).
// A device in neither (a wheel, G29, G920: its pedals are axes whose resting value differs per
// model, which the standard layout leaves unread) is not read until it is calibrated: `ask()` says
// so, and the station offers the calibration. Each control is taken from the devices that give it
// (`combine`): of two, the one deflected furthest from rest.

const STORAGE_KEY = "trustroute.wheel";   // {device id: its calibration}
// Steering and pedals read from a device count only beyond DEAD_ZONE of their travel from rest
// (after the calibration), rescaled so that full travel is still full: a stick that drifts a few
// hundredths, a wheel resting slightly off the centre it was calibrated at or a pedal not quite
// back at rest would otherwise steer or press all the time. 0.05 is past the drift of a worn
// stick's rest (a few hundredths) and, on a 900-degree wheel, about 22 degrees either side of the
// centre; the vehicle model's steering at 50 km/h starts from nothing beyond it, not with a jump.
export const DEAD_ZONE = 0.05;
// A held arrow key turns the wheel KEY_STEER_RATE per second up to full lock at up to
// KEY_FULL_LOCK_SPEED; faster, both its reach and its rate fall with the square of the speed. The
// vehicle model's lateral acceleration grows with speed squared times the steering
// (harness/simulation/vehicle_model.py), so the keys then ask for at most what full lock asks at
// KEY_FULL_LOCK_SPEED (about 4.3 m/s^2), reached in the same 0.67 s at any speed: a tap at 50 km/h
// is a lane change, not a swerve.
const KEY_STEER_RATE = 1.5;       // per second
const KEY_FULL_LOCK_SPEED = 4.5;  // m/s
const KEY_CENTRE_RATE = 3.0;      // per second: how fast the wheel comes back when the keys are let go

const CONTROLS = ["steer", "throttle", "brake"];   // the axes a calibration may give
const NAMES = { steer: "the steering", throttle: "the accelerator", brake: "the brake" };

// The calibrations this browser keeps, by device id (an entry that is not one, giving no control,
// is left out). A calibration: {id, steer: {axis, left, right, centre} | null, throttle and brake:
// {axis, rest, full} | null, button: index | null}; null: that control is not on the device.
export function loadCalibrations(storage = window.localStorage) {
  let saved = null;
  try { saved = JSON.parse(storage.getItem(STORAGE_KEY) || "null"); } catch { /* none kept */ }
  if (!saved || typeof saved !== "object") return {};
  const gives = (c) => CONTROLS.some((name) => c[name] && typeof c[name] === "object") || Number.isInteger(c.button);
  return Object.fromEntries(Object.entries(saved).filter(([, c]) => c && typeof c === "object" && gives(c)));
}

function saveCalibrations(calibrations, storage = window.localStorage) {
  const saved = loadCalibrations(storage);
  for (const calibration of calibrations) saved[calibration.id] = calibration;
  storage.setItem(STORAGE_KEY, JSON.stringify(saved));
}

const clamp = (value, low, high) => Math.min(Math.max(value, low), high);

// 0 at `rest`, 1 at `full`, whichever way the axis runs.
function pedal(value, rest, full) {
  return full === rest ? 0 : clamp((value - rest) / (full - rest), 0, 1);
}

// -1 at the calibration's `left`, 0 at its `centre`, 1 at its `right` (the axis may run either way).
function steering(value, { centre, left, right }) {
  const away = value - centre;
  return Math.sign(away) === Math.sign(left - centre)
    ? -clamp(Math.abs(away) / (Math.abs(left - centre) || 1), 0, 1)
    : clamp(Math.abs(away) / (Math.abs(right - centre) || 1), 0, 1);
}

// A reading (-1..1) with the dead zone taken out: 0 within DEAD_ZONE, then rising to 1 at 1.
const outsideDeadZone = (value) => Math.sign(value) * Math.max(0, Math.abs(value) - DEAD_ZONE) / (1 - DEAD_ZONE);

// Every device connected, in the browser's order: one call of the Gamepad API.
export function connectedPads() {
  return [...(navigator.getGamepads ? navigator.getGamepads() : [])].filter((pad) => pad && pad.connected);
}

export const INPUTS = ["wheel", "gamepad", "keyboard"];

export function padKind(pad) {
  return pad.mapping === "standard" ? "gamepad" : "wheel";
}

const UNCALIBRATED = "This wheel has no standard layout and is not calibrated, so it is not read: "
  + "click Calibrate the wheel and follow the steps.";
// the start of the ask for a control no device connected gives (`ask`)
const NOT_GIVEN = "No device connected gives ";

// The asks a calibration may answer: a device not read, a control no device gives.
export const calibrationWanted = (ask) => ask === UNCALIBRATED || ask.startsWith(NOT_GIVEN);

// The axes a calibration found on its device.
const calibrationGives = (calibration) => CONTROLS.filter((name) => calibration[name]);

// A device is read by its calibration, or in the standard mapping; else not at all.
const readable = ({ pad, calibration }) => calibration !== null || pad.mapping === "standard";

// The controls of several devices' readings (`Inputs.reading`; a control a device does not give is
// null there): each from the device deflected furthest from rest (the steering by its size either
// way), the first in the browser's order of those equally far (all at rest: the first that gives
// it); a control no device gives is let go (0). The source is the kind of the device steered with
// (no device steering: of the first read).
function combine(readings) {
  const controls = {};
  for (const name of CONTROLS) {
    const givers = readings.filter((reading) => reading[name] !== null);
    const furthest = givers.reduce((best, reading) => (Math.abs(reading[name]) > Math.abs(best[name]) ? reading : best),
      givers[0] ?? null);
    controls[name] = furthest ? furthest[name] : 0;
    if (name === "steer") controls.source = (furthest ?? readings[0]).kind;
  }
  controls.toggle = readings.some((reading) => reading.toggle);
  return controls;
}

// A device's own key (two of one model share an id).
const padKey = (pad) => `${pad.index}:${pad.id}`;

export class Inputs {
  constructor(allowed = INPUTS) {
    this.allowed = allowed;
    this.calibrations = loadCalibrations();
    this.keys = new Set();
    this.keySteer = 0;
    this.buttonsDown = new Map();   // padKey -> its take-over button was down at the last read
    document.addEventListener("keydown", (event) => this.keys.add(event.code));
    document.addEventListener("keyup", (event) => this.keys.delete(event.code));
    window.addEventListener("blur", () => this.keys.clear());
  }

  // The devices connected whose kind the study allows, each with the calibration saved for its id
  // (null: none). One Gamepad API call: `read` and `ask` of the same moment take what it gives.
  devices() {
    return connectedPads().filter((pad) => this.allowed.includes(padKind(pad)))
      .map((pad) => ({ pad, calibration: this.calibrations[pad.id] ?? null }));
  }

  // Calibrations made now (`Calibration.next`): they read their devices from here on; a button
  // held for the last step, on any device, is not a press.
  calibrated(calibrations) {
    for (const calibration of calibrations) this.calibrations[calibration.id] = calibration;
    for (const { pad } of this.devices()) this.buttonsDown.set(padKey(pad), true);
  }

  // `speed` (m/s): the vehicle's, which the keys' steering follows.
  read(seconds, speed = 0, devices = this.devices()) {
    const readables = devices.filter(readable);
    if (readables.length) return combine(readables.map((device) => this.reading(device)));
    return this.allowed.includes("keyboard") ? this.fromKeyboard(seconds, speed) : null;
  }

  // What the person is asked to do ("" when nothing): calibrate a device connected that cannot be
  // read; connect (or calibrate) what gives a control no device read gives; or connect a device
  // when nothing the study allows is there.
  ask(devices = this.devices()) {
    if (devices.some((device) => !readable(device))) return UNCALIBRATED;
    if (devices.length) {
      const given = devices.map((device) => this.gives(device));
      const missing = CONTROLS.filter((name) => !given.some((controls) => controls.includes(name)));
      return missing.length ? `${NOT_GIVEN}${missing.map((name) => NAMES[name]).join(" or ")}: `
        + "connect the device that does, then click Calibrate the wheel if it is not read." : "";
    }
    if (this.allowed.includes("keyboard")) return "";
    const names = this.allowed.map((kind) => (kind === "wheel" ? "a steering wheel with pedals" : "a gamepad"));
    return `Connect ${names.join(" or ")} to drive: this study does not use the keyboard.`;
  }

  // The controls a readable device gives: its calibration's, or all in the standard mapping.
  gives({ calibration }) {
    return calibration ? calibrationGives(calibration) : CONTROLS;
  }

  // One device now, the dead zone taken out: {steer, throttle, brake (null: not on this device),
  // toggle, kind}, by its calibration or the standard mapping.
  reading({ pad, calibration: c }) {
    const axis = (index) => pad.axes[index] ?? 0;
    const button = (index) => pad.buttons[index] ?? { pressed: false, value: 0 };
    const given = (value) => (value === null ? null : outsideDeadZone(value));
    const [steer, throttle, brake, pressed] = c
      ? [c.steer ? steering(axis(c.steer.axis), c.steer) : null,
         c.throttle ? pedal(axis(c.throttle.axis), c.throttle.rest, c.throttle.full) : null,
         c.brake ? pedal(axis(c.brake.axis), c.brake.rest, c.brake.full) : null,
         Number.isInteger(c.button) && button(c.button).pressed]
      : [clamp(axis(0), -1, 1), button(7).value, button(6).value, button(0).pressed];
    const key = padKey(pad);
    const toggle = pressed && !this.buttonsDown.get(key);
    this.buttonsDown.set(key, pressed);
    return { steer: given(steer), throttle: given(throttle), brake: given(brake), toggle, kind: padKind(pad) };
  }

  fromKeyboard(seconds, speed) {
    const left = this.keys.has("ArrowLeft");
    const right = this.keys.has("ArrowRight");
    const reach = Math.min(1, (KEY_FULL_LOCK_SPEED / Math.max(speed, 1e-6)) ** 2);
    if (left !== right) this.keySteer += (right ? 1 : -1) * KEY_STEER_RATE * reach * seconds;
    else this.keySteer -= Math.sign(this.keySteer) * Math.min(Math.abs(this.keySteer), KEY_CENTRE_RATE * seconds);
    this.keySteer = clamp(this.keySteer, -reach, reach);   // (the reach falls as the car speeds up)
    return { steer: this.keySteer, throttle: this.keys.has("ArrowUp") ? 1 : 0,
             brake: this.keys.has("ArrowDown") ? 1 : 0, toggle: false, source: "keyboard" };
  }
}

// The calibration of every device connected at once: one step at a time, each read from all of
// them when the person presses Next; a control is found on the device whose axis (or button) moved
// for its step, and a step that moves nothing is a control none of them has (a pedal box alone has
// no steering), not an error. Each device a control was found on gets a calibration of its own, of
// what was found on it; one where nothing was found keeps what it had. `onText(text)` shows the
// instruction; `next()` gives the calibrations once saved.
const NONE = "none of them: just press Next";
const STEPS = [
  ["rest", "Let go of the wheel and the pedals, then press Next."],
  ["left", `Turn the wheel fully to the left and hold it, then press Next (no wheel, a pedal box alone: ${NONE}).`],
  ["right", "Turn the wheel fully to the right and hold it, then press Next."],
  ["throttle", `Press the accelerator pedal fully and hold it, then press Next (no pedals: ${NONE}).`],
  ["brake", `Press the brake pedal fully and hold it, then press Next (no brake pedal: ${NONE}).`],
  ["button", `Hold the button you will use to take over and hand back, then press Next (${NONE}; space does it).`],
];
const MOVED = 0.2;   // an axis must move at least this far from rest to count

const quoted = (pads) => pads.map((pad) => `"${pad.id}"`).join(", ");

export class Calibration {
  constructor(onText) {
    this.onText = onText;
    this.step = 0;
    this.rest = new Map();   // device id -> its axes at rest
    this.found = {};         // control -> {id, axis, value} or, the button, {id, button}
    const pads = connectedPads();
    const which = pads.length === 1 ? `The device ${quoted(pads)}` : `${pads.length} devices (${quoted(pads)})`;
    onText(pads.length ? `${which}: ${STEPS[0][1]}`
      : "Connect the wheel and pedals (or gamepad) and press any of their buttons, then press Next.");
  }

  // The axis of the devices read at rest that moved most from there, not one of `except`
  // ({id, axis}), at least MOVED: {id, axis, value}, or null.
  moved(pads, except = []) {
    let best = null;
    let largest = MOVED;
    for (const pad of pads) {
      const rest = this.rest.get(pad.id);
      pad.axes.forEach((value, axis) => {
        const change = Math.abs(value - (rest?.[axis] ?? value));
        const excluded = except.some((other) => other.id === pad.id && other.axis === axis);
        if (!excluded && change > largest) { largest = change; best = { id: pad.id, axis, value }; }
      });
    }
    return best;
  }

  // The step's reading (a control found, or null: none of the devices has it), or a text saying
  // why the step must be done again.
  take(name, pads) {
    if (name === "rest") {
      for (const pad of pads) if (!this.rest.has(pad.id)) this.rest.set(pad.id, [...pad.axes]);
      return null;
    }
    if (name === "button") {
      for (const pad of pads) {
        const button = pad.buttons.findIndex((b) => b.pressed);
        if (this.rest.has(pad.id) && button >= 0) return { id: pad.id, button };
      }
      return null;
    }
    if (name === "right") {
      const { id, axis } = this.found.left;
      const pad = pads.find((p) => p.id === id);
      return pad ? { id, axis, value: pad.axes[axis] } : `The wheel "${id}" is gone: connect it, then press Next.`;
    }
    // the pedals: any axis but the steering's (the two pedals may share one, each its own way)
    return this.moved(pads, name === "left" || !this.found.left ? [] : [this.found.left]);
  }

  next() {
    const pads = connectedPads();
    if (!pads.length) { this.onText("No wheel, pedals or gamepad found: connect them and press one of their buttons."); return false; }
    const [name] = STEPS[this.step];
    const taken = this.take(name, pads);
    if (typeof taken === "string") { this.onText(taken); return false; }
    if (taken) this.found[name] = taken;
    this.step += name === "left" && !taken ? 2 : 1;   // no wheel: no right to turn it to
    if (this.step < STEPS.length) { this.onText(STEPS[this.step][1]); return false; }
    const calibrations = this.calibrations();
    if (!calibrations.length) {
      this.step = 0;
      this.rest.clear();
      this.onText(`Nothing moved at any step, so nothing was calibrated. ${STEPS[0][1]}`);
      return false;
    }
    saveCalibrations(calibrations);
    const said = calibrations.map((c) => `"${c.id}": ${[...calibrationGives(c).map((n) => NAMES[n]),
      ...(c.button === null ? [] : ["the button"])].join(", ")}`);
    this.onText(`Calibrated: this browser remembers it for each device (${said.join("; ")}).`);
    return calibrations;
  }

  // A calibration for each device a control was found on, of the controls found on it.
  calibrations() {
    const { left, right, throttle, brake, button } = this.found;
    const ids = [...new Set(Object.values(this.found).map((found) => found.id))];
    return ids.map((id) => {
      const on = (found) => (found && found.id === id ? found : null);
      const rest = this.rest.get(id);
      const axisPedal = (found) => (on(found) ? { axis: found.axis, rest: rest[found.axis], full: found.value } : null);
      return {
        id,
        steer: on(left) ? { axis: left.axis, left: left.value, right: right.value, centre: rest[left.axis] } : null,
        throttle: axisPedal(throttle),
        brake: axisPedal(brake),
        button: on(button) ? button.button : null,
      };
    });
  }
}
