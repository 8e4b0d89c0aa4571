// The next turn of the route, for the station's dashboard: which way the route goes at the end of
// the road the ego is on, how far along the road that is, and the arrow that shows it.

function direction([ax, ay], [bx, by]) { return Math.atan2(by - ay, bx - ax); }

// "left", "right", "straight" or "back" from the end of road `from` into road `to` (their shapes).
export function turnBetween(from, to) {
  if (!from || !to || from.length < 2 || to.length < 2) return null;
  const before = direction(from[from.length - 2], from[from.length - 1]);
  const after = direction(to[0], to[1]);
  const delta = ((((after - before) * 180) / Math.PI + 540) % 360) - 180;   // counter-clockwise: left
  if (Math.abs(delta) > 150) return "back";
  if (delta > 30) return "left";
  if (delta < -30) return "right";
  return "straight";
}

// Metres along `shape` (a polyline) from the point of it nearest (x, y) to its end. The nearest
// point is the projection on the nearest segment, not the nearest vertex: measured from a vertex,
// the distance grew as the car moved away from it and jumped when another vertex became nearer.
export function remaining(shape, x, y) {
  let best = Infinity;
  let at = null;   // [segment index, the projected point]
  for (let i = 0; i + 1 < shape.length; i++) {
    const [ax, ay] = shape[i];
    const [bx, by] = shape[i + 1];
    const squared = (bx - ax) ** 2 + (by - ay) ** 2;
    const along = squared > 0 ? Math.min(1, Math.max(0, ((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / squared)) : 0;
    const point = [ax + along * (bx - ax), ay + along * (by - ay)];
    const distance = Math.hypot(point[0] - x, point[1] - y);
    if (distance < best) { best = distance; at = [i, point]; }
  }
  if (at === null) return 0;
  const [index, [px, py]] = at;
  let total = Math.hypot(shape[index + 1][0] - px, shape[index + 1][1] - py);
  for (let i = index + 1; i + 1 < shape.length; i++) total += Math.hypot(shape[i + 1][0] - shape[i][0], shape[i + 1][1] - shape[i][1]);
  return total;
}

const TURN_WORDS = { left: "Turn left", right: "Turn right", straight: "Straight on", back: "Turn around" };

// {turn, text} for `frame`: `edges` maps a road id to the shape of its rightmost lane. In a
// junction (a road id starting with ":") the turn is under way: nothing is said.
export function nextTurn(frame, edges) {
  const route = frame.route || [];
  const current = edges[route[0]];
  if (String(frame.road).startsWith(":")) return { turn: null, text: "" };
  const turn = route.length > 1 ? turnBetween(current, edges[route[1]]) : null;
  if (!current) return { turn, text: "" };
  const distance = Math.round(remaining(current, frame.x, frame.y) / 10) * 10;
  return { turn, text: turn ? `${TURN_WORDS[turn]} in ${distance} m` : `Junction in ${distance} m` };
}

// The arrow of `turn` on `canvas` (cleared first; nothing for no turn).
export function drawArrow(canvas, turn) {
  const context = canvas.getContext("2d");
  context.clearRect(0, 0, canvas.width, canvas.height);
  if (!turn) return;
  context.save();
  context.translate(canvas.width / 2, canvas.height / 2 + 6);
  context.strokeStyle = "#ffffff";
  context.fillStyle = "#ffffff";
  context.lineWidth = 6;
  context.lineJoin = "round";
  context.beginPath();
  context.moveTo(0, 20);
  const tip = { straight: [0, -22], left: [-20, -12], right: [20, -12], back: [-14, 14] }[turn];
  if (turn === "straight") context.lineTo(0, -12);
  else if (turn === "back") { context.lineTo(0, -14); context.arc(-7, -14, 7, 0, Math.PI, true); context.lineTo(-14, 4); }
  else { context.lineTo(0, -12); context.lineTo(tip[0] * 0.55, -12); }
  context.stroke();
  context.beginPath();   // the arrow head
  const [hx, hy] = tip;
  if (turn === "straight") { context.moveTo(hx, hy); context.lineTo(hx - 10, hy + 12); context.lineTo(hx + 10, hy + 12); }
  else if (turn === "back") { context.moveTo(hx, hy); context.lineTo(hx - 9, hy - 11); context.lineTo(hx + 9, hy - 11); }
  else { const s = Math.sign(hx); context.moveTo(hx, -12); context.lineTo(hx - s * 12, -22); context.lineTo(hx - s * 12, -2); }
  context.fill();
  context.restore();
}

