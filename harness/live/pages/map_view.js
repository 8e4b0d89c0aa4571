// The top-down view: north up, the ego at the centre; the net's lanes, junctions and crossings
// (from /api/net), the ego's route, the next junction ringed, and the vehicles and persons of the
// frame as they are in SUMO. The station draws it large ([live] view = "map") or as the driver's
// view's mini-map.

export const COLOURS = { traffic: "#1e5aa8", obstacle: "#e67e00", oncoming: "#7b1fa2", truck: "#7b1fa2", parked: "#7b1fa2",
                         pedestrian: "#d81b60" };

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

function strokeLane(context, toCanvas, lane) {
  context.beginPath();
  lane.shape.forEach(([x, y], i) => {
    const [u, v] = toCanvas(x, y);
    if (i) context.lineTo(u, v); else context.moveTo(u, v);
  });
  context.stroke();
}

// A lane's box in net metres, widened by its width (computed once per lane).
const laneBoxes = new WeakMap();
function laneBox(lane) {
  if (!laneBoxes.has(lane)) {
    const xs = lane.shape.map(([x]) => x);
    const ys = lane.shape.map(([, y]) => y);
    const pad = lane.width || 0;
    laneBoxes.set(lane, [Math.min(...xs) - pad, Math.min(...ys) - pad, Math.max(...xs) + pad, Math.max(...ys) + pad]);
  }
  return laneBoxes.get(lane);
}

// The lanes within `halfWidth` x `halfHeight` metres of (x, y), by their boxes.
function lanesAround(net, x, y, halfWidth, halfHeight) {
  return net.lanes.filter((lane) => {
    const [x0, y0, x1, y1] = laneBox(lane);
    return x1 >= x - halfWidth && x0 <= x + halfWidth && y1 >= y - halfHeight && y0 <= y + halfHeight;
  });
}

// The net's lanes drawn once into a canvas LAYER_SPAN times the map's size around where the ego
// was, and copied at every frame until the ego's view leaves it: stroking every lane at every frame
// took about as long as the rest of the station's page drawing with software rendering.
const LAYER_SPAN = 3;
const layers = new WeakMap();   // map canvas -> its lane layer

function laneLayer(canvas, net, frame, scale) {
  const [width, height] = [canvas.width, canvas.height];
  let layer = layers.get(canvas);
  const covers = layer && layer.net === net && layer.scale === scale && layer.width === width
    && layer.height === height && Math.abs(frame.x - layer.x) * scale <= width * (LAYER_SPAN - 1) / 2
    && Math.abs(frame.y - layer.y) * scale <= height * (LAYER_SPAN - 1) / 2;
  if (covers) return layer;
  const image = document.createElement("canvas");
  [image.width, image.height] = [LAYER_SPAN * width, LAYER_SPAN * height];
  const context = image.getContext("2d");
  const toLayer = (x, y) => [image.width / 2 + (x - frame.x) * scale, image.height / 2 - (y - frame.y) * scale];
  context.fillStyle = "#dfe8d8";
  context.fillRect(0, 0, image.width, image.height);
  context.lineCap = "round";
  const lanes = lanesAround(net, frame.x, frame.y, image.width / 2 / scale, image.height / 2 / scale);
  // two passes: a light band per lane, then the asphalt a little narrower, so that the lanes of a
  // road stay apart by a thin marking
  for (const [colour, inset] of [["#f4f4f4", 0], [null, Math.min(1.5, scale / 2)]]) {
    for (const lane of lanes) {
      context.strokeStyle = colour || (lane.internal ? "#8c8c8c" : "#6f6f6f");
      context.lineWidth = Math.max(lane.width * scale - inset, 1);
      strokeLane(context, toLayer, lane);
    }
  }
  layer = { net, scale, width, height, x: frame.x, y: frame.y, image };
  layers.set(canvas, layer);
  return layer;
}

// `scale`: pixels per metre. `route`: the roads of the ego's route from the one it is on. The map
// shows a few hundred metres of a town that may have thousands of lanes, and it is drawn at every
// frame: the lanes come from the lane layer, whole pixels from where the ego is (the overlays are
// drawn at the frame's own position, at most half a pixel from the lanes under them).
export function drawMap(canvas, net, frame, scale) {
  const context = canvas.getContext("2d");
  const toCanvas = (x, y) => [canvas.width / 2 + (x - frame.x) * scale, canvas.height / 2 - (y - frame.y) * scale];
  const layer = laneLayer(canvas, net, frame, scale);
  const left = Math.round((layer.image.width - canvas.width) / 2 + (frame.x - layer.x) * scale);
  const top = Math.round((layer.image.height - canvas.height) / 2 - (frame.y - layer.y) * scale);
  context.drawImage(layer.image, left, top, canvas.width, canvas.height, 0, 0, canvas.width, canvas.height);
  context.lineCap = "round";
  const lanes = lanesAround(net, frame.x, frame.y, canvas.width / 2 / scale, canvas.height / 2 / scale);
  const route = new Set(frame.route || []);
  context.strokeStyle = "rgba(30, 136, 229, 0.85)";
  for (const lane of lanes) {
    if (!route.has(lane.id.slice(0, lane.id.lastIndexOf("_")))) continue;
    context.lineWidth = Math.max(lane.width * scale * 0.45, 2);
    strokeLane(context, toCanvas, lane);
  }
  const next = net.junctions[frame.junction];
  if (next) {   // the junction the ego drives to: the policy chooses the road after it
    const [u, v] = toCanvas(next[0], next[1]);
    context.strokeStyle = "#f9a825";
    context.lineWidth = 3;
    context.beginPath();
    context.arc(u, v, 9 * scale, 0, 2 * Math.PI);
    context.stroke();
  }
  for (const [x, y, angle, kind, , , length, width] of frame.vehicles || []) {
    const truck = kind === "oncoming" || kind === "parked" || kind === "truck";
    box(context, toCanvas, x, y, angle, length || (truck ? 10 : 4.5), width || (truck ? 2.5 : 1.8),
        COLOURS[kind] || COLOURS.traffic, scale);
  }
  for (const [x, y, kind] of frame.persons || []) {
    const [u, v] = toCanvas(x, y);
    context.fillStyle = COLOURS[kind] || COLOURS.pedestrian;
    context.beginPath();
    context.arc(u, v, Math.max(0.6 * scale, 2.5), 0, 2 * Math.PI);
    context.fill();
  }
  drawEgo(context, toCanvas, frame, scale);
}

// The ego is drawn at least EGO_PIXELS long (CSS pixels) and half as wide: at the mini-map's scale
// (a few hundred metres in 200 pixels) a car at its size is a speck of two or three pixels.
const EGO_PIXELS = 16;
function drawEgo(context, toCanvas, frame, scale) {
  const length = frame.length || 4.5;
  const shown = Math.max(scale, (EGO_PIXELS * (window.devicePixelRatio || 1)) / length);
  const width = shown > scale ? Math.max(frame.width || 1.8, length / 2) : frame.width || 1.8;
  box(context, toCanvas, frame.x, frame.y, frame.angle, length, width,
      frame.mode === "manual" ? "#c62828" : "#2e7d32", shown, "#ffffff");
}
