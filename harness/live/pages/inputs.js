// Continuous driving inputs ([live] driving = "continuous"): a steering wheel with pedals or a
// gamepad through the browser's Gamepad API, each device calibrated once and remembered by this
// browser for its id (localStorage), or the keyboard as the fallback. `read(seconds)` gives the
// controls now: {steer: -1 (full left) .. 1 (full right), throttle: 0..1, brake: 0..1, toggle:
// true once when the take-over / hand-back button is pressed, source: "wheel" | "gamepad" |
// "keyboard"}, or null when nothing the study allows ([live] inputs) is there to read.
//
// A device in the browser's "standard" mapping is a gamepad; any other (a wheel's) is a wheel.
//
// A device is read by the calibration saved for its id, else, in the browser's "standard" mapping,
// as a gamepad (left stick: steer, right trigger: throttle, left trigger: brake, A: take over /
// hand back). A device in neither (a wheel, G29, G920: its pedals are axes whose resting value
// differs per model, which the standard layout leaves unread) is not read until it is calibrated:
// `ask()` says so, and the station offers the calibration.

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

// The calibrations this browser keeps, by device id (an entry that is not one is left out).
export function loadCalibrations(storage = window.localStorage) {
  let saved = null;
  try { saved = JSON.parse(storage.getItem(STORAGE_KEY) || "null"); } catch { /* none kept */ }
  if (!saved || typeof saved !== "object") return {};
  return Object.fromEntries(Object.entries(saved).filter(([, c]) => c && typeof c === "object" && c.steer));
}

function saveCalibration(calibration, storage = window.localStorage) {
  storage.setItem(STORAGE_KEY, JSON.stringify({ ...loadCalibrations(storage), [calibration.id]: calibration }));
}

const clamp = (value, low, high) => Math.min(Math.max(value, low), high);

// 0 at `rest`, 1 at `full`, whichever way the axis runs.
function pedal(value, rest, full) {
  return full === rest ? 0 : clamp((value - rest) / (full - rest), 0, 1);
}

// A reading (-1..1) with the dead zone taken out: 0 within DEAD_ZONE, then rising to 1 at 1.
const outsideDeadZone = (value) => Math.sign(value) * Math.max(0, Math.abs(value) - DEAD_ZONE) / (1 - DEAD_ZONE);

export function firstGamepad() {
  for (const pad of navigator.getGamepads ? navigator.getGamepads() : []) if (pad && pad.connected) return pad;
  return null;
}

export const INPUTS = ["wheel", "gamepad", "keyboard"];

export function padKind(pad) {
  return pad.mapping === "standard" ? "gamepad" : "wheel";
}

export const UNCALIBRATED = "This wheel has no standard layout and is not calibrated, so it is not read: "
  + "click Calibrate the wheel and follow the steps.";

// A device is read by its calibration, or in the standard mapping; else not at all.
const readable = ({ pad, calibration }) => calibration !== null || pad.mapping === "standard";

export class Inputs {
  constructor(allowed = INPUTS) {
    this.allowed = allowed;
    this.calibrations = loadCalibrations();
    this.keys = new Set();
    this.keySteer = 0;
    this.buttonDown = false;
    document.addEventListener("keydown", (event) => this.keys.add(event.code));
    document.addEventListener("keyup", (event) => this.keys.delete(event.code));
    window.addEventListener("blur", () => this.keys.clear());
  }

  // The first device, if the study allows its kind, with the calibration saved for its id (null: none).
  device() {
    const pad = firstGamepad();
    if (!pad || !this.allowed.includes(padKind(pad))) return null;
    return { pad, calibration: this.calibrations[pad.id] ?? null };
  }

  // A calibration made now (`Calibration.next`): it reads its device from here on; its button,
  // held for the last step, is not a press.
  calibrated(calibration) {
    this.calibrations[calibration.id] = calibration;
    this.buttonDown = true;
  }

  // `speed` (m/s): the vehicle's, which the keys' steering follows.
  read(seconds, speed = 0) {
    const device = this.device();
    if (device && readable(device)) return this.fromGamepad(device.pad, device.calibration);
    return this.allowed.includes("keyboard") ? this.fromKeyboard(seconds, speed) : null;
  }

  // What the person is asked to do ("" when nothing): calibrate the device connected when it
  // cannot be read, or connect one when nothing the study allows is there.
  ask() {
    const device = this.device();
    if (device) return readable(device) ? "" : UNCALIBRATED;
    if (this.allowed.includes("keyboard")) return "";
    const names = this.allowed.map((kind) => (kind === "wheel" ? "a steering wheel with pedals" : "a gamepad"));
    return `Connect ${names.join(" or ")} to drive: this study does not use the keyboard.`;
  }

  fromGamepad(pad, c) {
    const axis = (index) => pad.axes[index] ?? 0;
    const button = (index) => pad.buttons[index] ?? { pressed: false, value: 0 };
    let steer, throttle, brake, pressed;
    if (c) {
      const { centre, left, right } = c.steer;
      const away = axis(c.steer.axis) - centre;   // the axis may run either way
      steer = Math.sign(away) === Math.sign(left - centre)
        ? -clamp(Math.abs(away) / (Math.abs(left - centre) || 1), 0, 1)
        : clamp(Math.abs(away) / (Math.abs(right - centre) || 1), 0, 1);
      throttle = pedal(axis(c.throttle.axis), c.throttle.rest, c.throttle.full);
      brake = pedal(axis(c.brake.axis), c.brake.rest, c.brake.full);
      pressed = button(c.button).pressed;
    } else {
      steer = clamp(axis(0), -1, 1);
      throttle = button(7).value;
      brake = button(6).value;
      pressed = button(0).pressed;
    }
    const toggle = pressed && !this.buttonDown;
    this.buttonDown = pressed;
    return { steer: outsideDeadZone(steer), throttle: outsideDeadZone(throttle), brake: outsideDeadZone(brake),
             toggle, source: padKind(pad) };
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

// The calibration: one step at a time, each read from the first gamepad when the person presses
// Next. `onText(text)` shows the instruction; `done(calibration)` when saved.
const STEPS = [
  ["rest", "Let go of the wheel and the pedals, then press Next."],
  ["left", "Turn the wheel fully to the left and hold it, then press Next."],
  ["right", "Turn the wheel fully to the right and hold it, then press Next."],
  ["throttle", "Press the accelerator pedal fully and hold it, then press Next."],
  ["brake", "Press the brake pedal fully and hold it, then press Next."],
  ["button", "Hold the button you will use to take over and hand back, then press Next."],
];

export class Calibration {
  constructor(onText) {
    this.onText = onText;
    this.step = 0;
    this.readings = {};
    onText(firstGamepad() ? STEPS[0][1] : "Connect the wheel or gamepad and press any of its buttons, then press Next.");
  }

  // The axis that moved most from the resting reading (not `except`).
  moved(pad, except = -1) {
    let best = -1;
    let largest = 0.2;   // an axis must move at least this far to count
    pad.axes.forEach((value, index) => {
      const change = Math.abs(value - this.readings.rest[index]);
      if (index !== except && change > largest) { largest = change; best = index; }
    });
    return best;
  }

  next() {
    const pad = firstGamepad();
    if (!pad) { this.onText("No wheel or gamepad found: connect it and press one of its buttons."); return false; }
    const [name] = STEPS[this.step];
    if (name === "rest") [this.readings.id, this.readings.rest] = [pad.id, [...pad.axes]];
    else if (name === "button") {
      const index = pad.buttons.findIndex((b) => b.pressed);
      if (index < 0) { this.onText("No button is held: hold it, then press Next."); return false; }
      this.readings.button = index;
    } else {
      const except = name === "left" || name === "right" ? -1 : this.readings.left?.axis;
      const axis = name === "right" ? this.readings.left.axis : this.moved(pad, except);
      if (axis < 0) { this.onText("Nothing moved: try again, then press Next."); return false; }
      this.readings[name] = { axis, value: pad.axes[axis] };
    }
    this.step += 1;
    if (this.step < STEPS.length) { this.onText(STEPS[this.step][1]); return false; }
    const r = this.readings;
    const calibration = {
      id: r.id,
      steer: { axis: r.left.axis, left: r.left.value, right: r.right.value, centre: r.rest[r.left.axis] },
      throttle: { axis: r.throttle.axis, rest: r.rest[r.throttle.axis], full: r.throttle.value },
      brake: { axis: r.brake.axis, rest: r.rest[r.brake.axis], full: r.brake.value },
      button: r.button,
    };
    saveCalibration(calibration);
    this.onText("Calibrated: this browser remembers it for this device.");
    return calibration;
  }
}
