// The driver's view: a first-person, perspective view from the driver's eye, rendered with
// three.js (WebGL). The scene is built once from the net the ego drives (/api/net, SUMO's
// coordinates): lane surfaces from their shapes and widths, lane markings, junction areas,
// crossings, sidewalks and walking areas, ground and sky. Every frame's vehicles and persons are
// simple shapes at their SUMO sizes, positions and headings, with brake lights and indicators.
//
// SUMO's (x, y) in metres, y north, is three's (x, -z), y up; SUMO's angle (degrees clockwise
// from north) is a rotation of -angle about y. A vehicle's SUMO position is its front centre.
//
// Motion: the server's frames (25 a second, stepped or dead-reckoned) are buffered by arrival
// time and the view renders the state INTERPOLATION seconds back, interpolated between the two
// frames around it (positions, headings); past the newest frame it moves on along each heading at
// its speed for at most EXTRAPOLATE_LIMIT seconds.
//
// Drawing: an animation frame draws only when the picture would change: once per frame arriving
// while the frames stream, at every animation frame while the view moves on to the newest frame
// after they stop, and on a resize or an indicator's blink; an unchanged picture is never drawn
// again. Software WebGL (no GPU) spends a core drawing every animation frame, and a laptop's GPU
// its battery.
import * as THREE from "./vendor/three.module.js";

// The camera model (the screenshot tests project with the same numbers): the eye EYE_BACK metres
// behind the front centre, EYE_LEFT to its left (a left-hand drive car on right-hand traffic),
// EYE_HEIGHT above the road, looking along the heading; vertical field of view FOV degrees.
export const CAMERA = { eyeBack: 1.9, eyeLeft: 0.35, eyeHeight: 1.2, fov: 40, near: 0.3, far: 600 };
const INTERPOLATION = 0.06;       // s: rendered this far behind the newest frame (1.5 frame intervals)
const EXTRAPOLATE_LIMIT = 0.25;   // s: at most this far past the newest frame
const SNAP_DISTANCE = 15;         // m: a jump larger than this between frames is not interpolated
const STREAMING = 0.1;            // s: frames arriving at most this far apart are a stream
const SKY = 0xa9cfee;
const TRAFFIC = [0x2f5d8c, 0x9c2f2f, 0xd6d6d6, 0x3a3a3a, 0x2f7a4a, 0xb8b8b8, 0x6d4c41];
const KIND_COLOUR = { obstacle: 0xe67e00, oncoming: 0x7b1fa2, truck: 0x7b1fa2, parked: 0x7b1fa2, pedestrian: 0xd81b60 };
const LEVEL = { ground: -0.05, walk: 0.004, area: 0.01, internal: 0.014, road: 0.018, crossing: 0.026,
                marking: 0.03 };
const FLAT_ORDER = -100;   // the render order of the lowest level (objects above them: 0)

const toScene = (x, y, height = 0) => new THREE.Vector3(x, height, -y);

// -- the net --------------------------------------------------------------------------------------
function normals(shape) {
  // at each point, the normal to the left of the direction of travel, mitred at corners (the
  // mean of the two segments' unit normals, lengthened so both offset segments stay parallel)
  const segment = (i) => {
    const [ax, ay] = shape[i];
    const [bx, by] = shape[i + 1];
    const length = Math.hypot(bx - ax, by - ay) || 1;
    return [-(by - ay) / length, (bx - ax) / length];
  };
  const out = [];
  for (let i = 0; i < shape.length; i++) {
    const before = segment(Math.max(i - 1, 0));
    const after = segment(Math.min(i, shape.length - 2));
    const [mx, my] = [before[0] + after[0], before[1] + after[1]];
    const length = Math.hypot(mx, my);
    if (length < 1e-6) { out.push(after); continue; }   // a U-turn in place: no mitre
    const cosine = Math.max((mx * after[0] + my * after[1]) / length, 0.25);
    out.push([mx / length / cosine, my / length / cosine]);
  }
  return out;
}

function offset(shape, lateral) {
  const n = normals(shape);
  return shape.map(([x, y], i) => [x + n[i][0] * lateral, y + n[i][1] * lateral]);
}

// A band along `shape` from `left` to `right` metres to its left: two triangles per segment.
function ribbon(positions, shape, left, right, height) {
  const a = offset(shape, left);
  const b = offset(shape, right);
  for (let i = 0; i + 1 < shape.length; i++) {
    const quad = [a[i], b[i], b[i + 1], a[i], b[i + 1], a[i + 1]];
    for (const [x, y] of quad) positions.push(x, height, -y);
  }
}

// Pieces of a polyline: [from, to] metres along it, every `period` metres, their ends found in
// steps of 0.5 m. A piece keeps only its ends and the polyline's corners: the points between lie
// on a straight segment, and as vertices they only multiply the triangles software WebGL draws at
// every frame (on Town01 they were nine in ten of the net's triangles).
function dashes(shape, on, period) {
  const pieces = [];
  let along = 0;
  let current = null;
  for (let i = 0; i + 1 < shape.length; i++) {
    const [ax, ay] = shape[i];
    const [bx, by] = shape[i + 1];
    const length = Math.hypot(bx - ax, by - ay);
    let kept = 0;   // the current piece's points in this segment
    for (let s = 0; s < length; s += 0.5) {
      const phase = (along + s) % period;
      const point = [ax + ((bx - ax) * s) / length, ay + ((by - ay) * s) / length];
      if (phase >= on) { current = null; kept = 0; continue; }
      if (!current) { current = []; pieces.push(current); }
      if (kept < 2) current.push(point);
      else current[current.length - 1] = point;   // the piece's straight run in this segment goes on
      kept += 1;
    }
    along += length;
  }
  return pieces.filter((piece) => piece.length > 1);
}

function polygon(positions, points, height) {
  const contour = points.map(([x, y]) => new THREE.Vector2(x, y));
  for (const [i, j, k] of THREE.ShapeUtils.triangulateShape(contour, [])) {
    for (const index of [i, k, j]) positions.push(points[index][0], height, -points[index][1]);
  }
}

// The ground and the net's layers lie in one plane, centimetres apart (LEVEL): they are drawn first,
// in the order of their levels, each over the one below, and neither test nor write the depth
// buffer, so no renderer's depth precision decides which shows. SwiftShader's would: it gives the
// ground's two triangles (thousands of metres across, cut by the near plane) depths nearer than
// the road's at some canvas sizes (about 216-228, 268-278, 376-392 and 486-500 pixels wide at
// 16:9, a 400 px phone's among them), and grass would cover the road. Everything else stands on
// these layers and is drawn after them, with the depth buffer.
function flat(object, level) {
  object.renderOrder = FLAT_ORDER - 1 + Object.values(LEVEL).filter((other) => other <= level).length;
  object.material.depthTest = false;
  object.material.depthWrite = false;
  return object;
}

function mesh(positions, colour, level) {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute("position", new THREE.Float32BufferAttribute(positions, 3));
  return flat(new THREE.Mesh(geometry, new THREE.MeshBasicMaterial({ color: colour, side: THREE.DoubleSide })), level);
}

export function netScene(net) {
  const group = new THREE.Group();
  const parts = { road: [], internal: [], area: [], walk: [], crossing: [], marking: [], edge: [] };
  const roadLanes = {};   // edge -> [rightmost, leftmost] index of its vehicle lanes (sidewalks aside)
  for (const lane of net.lanes) {
    if ((lane.kind || "road") !== "road") continue;
    const edge = lane.id.slice(0, lane.id.lastIndexOf("_"));
    const [low, high] = roadLanes[edge] || [Infinity, -Infinity];
    roadLanes[edge] = [Math.min(low, lane.index ?? 0), Math.max(high, lane.index ?? 0)];
  }
  for (const lane of net.lanes) {
    const kind = lane.kind || (lane.internal ? "internal" : "road");
    const half = lane.width / 2;
    if (lane.shape.length < 2) continue;
    if (kind === "walkingarea") { if (lane.shape.length >= 3) polygon(parts.walk, lane.shape, LEVEL.walk); continue; }
    if (kind === "sidewalk") { ribbon(parts.walk, lane.shape, half, -half, LEVEL.walk); continue; }
    if (kind === "crossing") {   // zebra bars along the walking direction, across the crossing's width
      for (let left = half - 0.25; left > -half; left -= 1.0) ribbon(parts.crossing, lane.shape, left, left - 0.5, LEVEL.crossing);
      continue;
    }
    ribbon(kind === "internal" ? parts.internal : parts.road, lane.shape, half, -half,
           kind === "internal" ? LEVEL.internal : LEVEL.road);
    if (kind !== "road") continue;
    const [rightmost, leftmostIndex] = roadLanes[lane.id.slice(0, lane.id.lastIndexOf("_"))];
    if ((lane.index ?? 0) === rightmost) ribbon(parts.edge, lane.shape, -half + 0.3, -half + 0.15, LEVEL.marking);   // the road's edge
    const leftmost = (lane.index ?? 0) === leftmostIndex;
    // the centre line (the leftmost lane's left side) and lane dividers: dashed
    for (const piece of dashes(offset(lane.shape, half), leftmost ? 3 : 4, leftmost ? 6 : 12)) {
      ribbon(parts.marking, piece, 0.07, -0.07, LEVEL.marking);
    }
  }
  for (const area of net.areas || []) polygon(parts.area, area, LEVEL.area);
  const colours = { road: 0x4a4d50, internal: 0x505356, area: 0x505356, walk: 0xb9b4aa, crossing: 0xf2f2f2,
                    marking: 0xf2f2f2, edge: 0xf2f2f2 };
  const levels = { ...LEVEL, edge: LEVEL.marking };
  for (const [name, positions] of Object.entries(parts)) {
    if (positions.length) group.add(mesh(positions, colours[name], levels[name]));
  }
  const [x0, y0, x1, y1] = net.bounds;
  const size = Math.max(x1 - x0, y1 - y0) + 3000;
  const ground = new THREE.Mesh(new THREE.PlaneGeometry(size, size), new THREE.MeshBasicMaterial({ color: 0x87a96b }));
  flat(ground, LEVEL.ground);
  ground.rotation.x = -Math.PI / 2;
  ground.position.copy(toScene((x0 + x1) / 2, (y0 + y1) / 2, LEVEL.ground));
  group.add(ground);
  return group;
}

// -- vehicles and persons -------------------------------------------------------------------------
const boxGeometry = new THREE.BoxGeometry(1, 1, 1);
const materials = new Map();
function material(colour) {
  if (!materials.has(colour)) materials.set(colour, new THREE.MeshLambertMaterial({ color: colour }));
  return materials.get(colour);
}

function part(group, colour, [sx, sy, sz], [px, py, pz]) {
  // a box sx wide, sy high, sz long; (px, py, pz) its centre: px to the right, pz back from the front
  const box = new THREE.Mesh(boxGeometry, colour instanceof THREE.Material ? colour : material(colour));
  box.scale.set(sx, sy, sz);
  box.position.set(px, py, pz);
  group.add(box);
  return box;
}

function lamp(group, colour, x, y, z) {
  const light = new THREE.Mesh(boxGeometry, new THREE.MeshBasicMaterial({ color: colour }));
  light.scale.set(0.25, 0.14, 0.05);
  light.position.set(x, y, z);
  group.add(light);
  return light;
}

// A vehicle's shape in its own frame: the front centre at the origin, the body along +z (back).
function vehicleShape(kind, handle, length, width, height, shape) {
  const group = new THREE.Group();
  const colour = KIND_COLOUR[kind] ?? TRAFFIC[handle % TRAFFIC.length];
  const clearance = 0.3;
  if (shape === "bicycle" || shape === "motorcycle" || shape === "moped") {
    part(group, colour, [Math.min(width, 0.3), 0.7, length], [0, 0.55, length / 2]);
    part(group, 0x333333, [0.35, 0.6, 0.3], [0, 1.2, length * 0.6]);   // the rider
    return { group, lights: null };
  }
  const heavy = /truck|trailer|bus|delivery|semitrailer/.test(shape || "") || length > 7;
  if (heavy) {
    const cab = Math.min(2.2, length * 0.25);
    part(group, 0xeeeeee, [width, height * 0.8 - clearance, cab], [0, clearance + (height * 0.8 - clearance) / 2, cab / 2]);
    part(group, colour, [width, height - clearance, length - cab - 0.3], [0, clearance + (height - clearance) / 2, cab + 0.3 + (length - cab - 0.3) / 2]);
    part(group, 0x1d2a33, [width * 0.9, height * 0.3, 0.05], [0, height * 0.55, -0.01]);   // the windscreen
  } else {
    const body = height * 0.55;
    part(group, colour, [width, body - clearance, length], [0, clearance + (body - clearance) / 2, length / 2]);
    part(group, colour, [width * 0.86, height - body, length * 0.5], [0, body + (height - body) / 2, length * 0.55]);
    part(group, 0x1d2a33, [width * 0.8, (height - body) * 0.8, 0.05], [0, body + (height - body) / 2, length * 0.3 - 0.01]);
  }
  for (const side of [-1, 1]) {
    for (const z of [0.8, length - 0.8]) part(group, 0x151515, [0.25, 0.6, 0.6], [side * (width / 2 - 0.1), 0.3, z]);
  }
  const rearY = heavy ? 0.9 : height * 0.45;
  const lights = {
    brake: [-1, 1].map((side) => lamp(group, 0x5a0a0a, side * (width / 2 - 0.2), rearY, length + 0.01)),
    left: [lamp(group, 0x5a3a00, -width / 2 + 0.1, rearY + 0.18, length + 0.01), lamp(group, 0x5a3a00, -width / 2 + 0.1, 0.7, -0.01)],
    right: [lamp(group, 0x5a3a00, width / 2 - 0.1, rearY + 0.18, length + 0.01), lamp(group, 0x5a3a00, width / 2 - 0.1, 0.7, -0.01)],
  };
  return { group, lights };
}

function personShape(kind) {
  const group = new THREE.Group();
  const colour = KIND_COLOUR[kind] ?? 0x455a64;
  part(group, 0x263238, [0.35, 0.85, 0.25], [0, 0.42, 0]);    // legs
  part(group, colour, [0.5, 0.65, 0.3], [0, 1.17, 0]);         // body
  part(group, 0xe0ac69, [0.22, 0.25, 0.22], [0, 1.62, 0]);     // head
  return { group, lights: null };
}

function setLights(lights, signals, blinkOn) {
  if (!lights) return;
  const brake = (signals & 8) !== 0;
  for (const light of lights.brake) light.material.color.setHex(brake ? 0xff1a1a : 0x5a0a0a);
  const hazard = (signals & 4) !== 0;
  for (const [side, bit] of [["right", 1], ["left", 2]]) {
    const on = blinkOn && (hazard || (signals & bit) !== 0);
    for (const light of lights[side]) light.material.color.setHex(on ? 0xffa000 : 0x5a3a00);
  }
}

// -- interpolation --------------------------------------------------------------------------------
const lerp = (a, b, w) => a + (b - a) * w;
function lerpAngle(a, b, w) {
  const d = ((((b - a) % 360) + 540) % 360) - 180;
  return a + d * w;
}
function movedOn(x, y, angle, speed, seconds) {
  const heading = (angle * Math.PI) / 180;
  return [x + speed * seconds * Math.sin(heading), y + speed * seconds * Math.cos(heading)];
}

// The pose [x, y, angle] of one object between frames a (weight 1 - w) and b (weight w).
function between(a, b, w) {
  if (!a || Math.hypot(b[0] - a[0], b[1] - a[1]) > SNAP_DISTANCE) return [b[0], b[1], b[2]];
  return [lerp(a[0], b[0], w), lerp(a[1], b[1], w), lerpAngle(a[2], b[2], w)];
}

export class DriverView {
  constructor(canvas) {
    this.canvas = canvas;
    // no multisampling: with software WebGL (no GPU) it costs about as much as the scene itself
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(1);
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(SKY);
    this.scene.fog = new THREE.Fog(SKY, 180, CAMERA.far * 0.9);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x667755, 2.2));
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(-0.5, 1, 0.3);
    this.scene.add(sun);
    this.camera = new THREE.PerspectiveCamera(CAMERA.fov, canvas.width / canvas.height, CAMERA.near, CAMERA.far);
    this.camera.rotation.order = "YXZ";
    this.camera.position.set(0, 60, 0);   // before the first frame: above the net, looking down the road
    this.objects = new Map();              // "v<handle>" / "p<handle>" -> {group, lights}
    this.frames = [];                      // [{arrival (s), frame}], oldest first
    // renders: pictures drawn; skipped: animation frames that drew none; settled: the frames
    // received when the picture drawn was last found to be the newest frame's, at rest
    this.stats = { renders: 0, skipped: 0, settled: 0, frames: 0, pose: null, camera: CAMERA,
                   started: performance.now() };
    this.net = null;
    this.drawn = null;    // what the last picture drew (`picture`), null: draw at the next call
    this.fresh = true;    // a frame has arrived since the last picture
    // the canvas's displayed size, from a ResizeObserver: reading clientWidth at every picture
    // would force a layout each time the page's text changed
    this.shown = null;
    new ResizeObserver(() => { this.shown = [canvas.clientWidth, canvas.clientHeight]; }).observe(canvas);
  }

  setNet(net) {
    if (this.net) this.scene.remove(this.net);
    this.net = netScene(net);
    this.scene.add(this.net);
    this.drawn = null;
  }

  push(frame) {
    const now = performance.now() / 1000;
    this.frames.push({ arrival: now, frame });
    this.stats.frames += 1;
    this.fresh = true;
    while (this.frames.length > 2 && this.frames[1].arrival < now - 1) this.frames.shift();
  }

  clear() { this.frames = []; this.drawn = null; }

  // Everything a picture of `state` shows that moves: the camera's pose, each object's pose and lamps.
  static picture(state, blinkOn) {
    if (!state) return "";
    const objects = [];
    for (const [key, { pose, v }] of state.vehicles) objects.push(key, ...pose, v[10] || 0, (v[10] & 7) !== 0 && blinkOn);
    for (const [key, { pose }] of state.persons) objects.push(key, ...pose);
    return JSON.stringify([state.ego, objects]);
  }

  // The state to render at `now`: {ego: [x, y, angle], vehicles: Map, persons: Map, frame}.
  state(now) {
    const frames = this.frames;
    if (!frames.length) return null;
    const target = now - INTERPOLATION;
    let i = frames.length - 1;
    while (i > 0 && frames[i - 1].arrival > target) i--;
    const b = frames[i];
    const a = i > 0 ? frames[i - 1] : null;
    if (a && target <= b.arrival && target >= a.arrival) {
      return this.blend(a.frame, b.frame, (target - a.arrival) / Math.max(b.arrival - a.arrival, 1e-6), 0);
    }
    const ahead = Math.min(Math.max(target - b.arrival, 0), EXTRAPOLATE_LIMIT);
    return this.blend(null, b.frame, 1, ahead);
  }

  blend(a, b, w, ahead) {
    const ego = between(a && [a.x, a.y, a.angle], [...movedOn(b.x, b.y, b.angle, b.speed, ahead), b.angle], w);
    const before = new Map((a?.vehicles || []).map((v) => [v[5], v]));
    const vehicles = new Map();
    for (const v of b.vehicles || []) {
      const old = before.get(v[5]);
      const pose = between(old && [old[0], old[1], old[2]], [...movedOn(v[0], v[1], v[2], v[4], ahead), v[2]], w);
      vehicles.set(`v${v[5]}`, { pose, v });
    }
    const walked = new Map((a?.persons || []).map((p) => [p[3], p]));
    const persons = new Map();
    for (const p of b.persons || []) {
      const old = walked.get(p[3]);
      persons.set(`p${p[3]}`, { pose: between(old && [old[0], old[1], old[4] ?? 0], [p[0], p[1], p[4] ?? 0], w), p });
    }
    return { ego, vehicles, persons, frame: b };
  }

  place(key, pose, make) {
    let object = this.objects.get(key);
    if (!object) {
      object = make();
      this.objects.set(key, object);
      this.scene.add(object.group);
    }
    object.group.position.copy(toScene(pose[0], pose[1]));
    object.group.rotation.y = (-pose[2] * Math.PI) / 180;   // local +z (the body) points back from the front
    object.seen = true;
    return object;
  }

  // Draws the view at this moment if its picture changed (see Drawing above); the state drawn, or
  // null when nothing was drawn. `still`: the newest frame as it is, neither interpolated nor
  // moved on (a paused drive: the car stands where its last frame put it).
  render(still = false) {
    const now = performance.now() / 1000;
    const newestFrame = this.frames.length ? this.frames[this.frames.length - 1].frame : null;
    const state = still ? newestFrame && this.blend(null, newestFrame, 1, 0) : this.state(now);
    const blinkOn = Math.floor(now * 3) % 2 === 0;   // indicators at 1.5 Hz
    const resized = this.resize();
    const picture = DriverView.picture(state, blinkOn);
    const newest = this.frames.length ? this.frames[this.frames.length - 1].arrival : -Infinity;
    const streaming = now - newest < STREAMING;
    const unchanged = !resized && this.drawn !== null && picture === this.drawn;
    if (unchanged && !streaming) this.stats.settled = this.stats.frames;
    if (unchanged || (!resized && this.drawn !== null && streaming && !this.fresh)) {
      this.stats.skipped += 1;
      return null;
    }
    this.drawn = picture;
    this.fresh = false;
    if (state) {
      for (const object of this.objects.values()) object.seen = false;
      for (const [key, { pose, v }] of state.vehicles) {
        const [, , , kind, , handle, length, width, height, shape, signals] = v;
        const object = this.place(key, pose, () => vehicleShape(kind, handle, length || 4.5, width || 1.8, height || 1.5, shape));
        setLights(object.lights, signals || 0, blinkOn);
      }
      for (const [key, { pose, p }] of state.persons) this.place(key, pose, () => personShape(p[2]));
      for (const [key, object] of this.objects) {
        if (!object.seen) { this.scene.remove(object.group); this.objects.delete(key); }
      }
      const [x, y, angle] = state.ego;
      const heading = (angle * Math.PI) / 180;
      const [ex, ey] = [x - CAMERA.eyeBack * Math.sin(heading) - CAMERA.eyeLeft * Math.cos(heading),
                        y - CAMERA.eyeBack * Math.cos(heading) + CAMERA.eyeLeft * Math.sin(heading)];
      this.camera.position.copy(toScene(ex, ey, CAMERA.eyeHeight));
      this.camera.rotation.set(0, -heading, 0);
      this.stats.pose = [x, y, angle];
    }
    this.renderer.render(this.scene, this.camera);
    this.stats.renders += 1;
    return state;
  }

  resize() {   // whether the canvas took its displayed size
    const [width, height] = this.shown || [this.canvas.clientWidth, this.canvas.clientHeight];
    if (width && height && (this.canvas.width !== width || this.canvas.height !== height)) {
      this.renderer.setSize(width, height, false);
      this.camera.aspect = width / height;
      this.camera.updateProjectionMatrix();
      return true;
    }
    return false;
  }
}

export function webglAvailable() {
  try {
    const probe = document.createElement("canvas");
    return Boolean(probe.getContext("webgl2") || probe.getContext("webgl"));
  } catch {
    return false;
  }
}
