// The panel's map: where the robot is, where its orders will take it, the places of the
// orders and the robot's own map, drawn in SVG. World coordinates are metres; SVG's y axis
// points down, so every y is drawn negated.
"use strict";

const SVG = "http://www.w3.org/2000/svg";
const WORLD_FRAMES = ["map", "odom"];
const ROBOT_FRAME = "base_link";

// Where a sequence of orders takes the robot, from `start` ({x, y, yaw}): one step per
// order, {from, to} with `to` null for an order that does not move it (a photo, a wait) or
// whose frame is unknown. An absolute goal ('map', 'odom') is reached as it is; a relative
// one ('base_link') from the pose where the previous order ends.
function plan(start, orders) {
  let at = start;
  return orders.map((order) => {
    const target = order.target_pose;
    let to = null;
    if (target && at && WORLD_FRAMES.includes(target.frame)) {
      to = { x: target.x, y: target.y, yaw: target.yaw || 0 };
    } else if (target && at && target.frame === ROBOT_FRAME) {
      to = compose(at, target);
    }
    const step = { order, from: at, to };
    if (to) at = to;
    return step;
  });
}

function compose(base, relative) {
  const cos = Math.cos(base.yaw);
  const sin = Math.sin(base.yaw);
  return {
    x: base.x + cos * relative.x - sin * (relative.y || 0),
    y: base.y + sin * relative.x + cos * (relative.y || 0),
    yaw: normalize(base.yaw + (relative.yaw || 0)),
  };
}

function normalize(angle) {
  const turned = (angle + Math.PI) % (2 * Math.PI);
  return (turned < 0 ? turned + 2 * Math.PI : turned) - Math.PI;
}

function node(tag, attributes, text) {
  const made = document.createElementNS(SVG, tag);
  for (const [name, value] of Object.entries(attributes || {})) made.setAttribute(name, value);
  if (text !== undefined) made.textContent = text;
  return made;
}

function arrow(pose, size, cls) {
  // A triangle pointing where the robot heads.
  const tip = [pose.x + size * Math.cos(pose.yaw), pose.y + size * Math.sin(pose.yaw)];
  const side = (angle) => [pose.x + size * 0.6 * Math.cos(pose.yaw + angle),
    pose.y + size * 0.6 * Math.sin(pose.yaw + angle)];
  const points = [tip, side(2.5), side(-2.5)].map(([x, y]) => `${x},${-y}`).join(" ");
  return node("polygon", { points, class: cls });
}

// The part of an occupancy grid worth framing, in metres: where its cells are known (not
// map_server's 205 grey), found once per grid by reading its PNG back from a canvas. A Nav2
// map is often mostly unknown margin; framing all of it would shrink the rooms to nothing.
// Resolves to the whole grid when the image cannot be read.
function knownExtent(grid) {
  const whole = {
    minX: grid.origin.x, minY: grid.origin.y,
    maxX: grid.origin.x + grid.width * grid.resolution,
    maxY: grid.origin.y + grid.height * grid.resolution,
  };
  return new Promise((resolve) => {
    const image = new Image();
    image.onerror = () => resolve(whole);
    image.onload = () => {
      const canvas = document.createElement("canvas");
      [canvas.width, canvas.height] = [grid.width, grid.height];
      const context = canvas.getContext("2d");
      if (!context) { resolve(whole); return; }
      context.drawImage(image, 0, 0);
      const pixels = context.getImageData(0, 0, grid.width, grid.height).data;
      const cells = new Uint8Array(grid.width * grid.height); // the grey of each, for goalTrouble
      let [left, right, low, high] = [Infinity, -Infinity, Infinity, -Infinity];
      for (let row = 0; row < grid.height; row += 1) {
        for (let column = 0; column < grid.width; column += 1) {
          cells[row * grid.width + column] = pixels[(row * grid.width + column) * 4];
          if (pixels[(row * grid.width + column) * 4] === 205) continue; // unknown
          left = Math.min(left, column); right = Math.max(right, column);
          low = Math.min(low, row); high = Math.max(high, row);
        }
      }
      grid.cells = cells;
      if (left > right) { resolve(whole); return; }
      const metres = (cells) => cells * grid.resolution;
      resolve({ // row 0 is at the origin (the image is flipped when drawn)
        minX: grid.origin.x + metres(left), maxX: grid.origin.x + metres(right + 1),
        minY: grid.origin.y + metres(low), maxY: grid.origin.y + metres(high + 1),
      });
    };
    image.src = `data:image/png;base64,${grid.png}`;
  });
}

// What is wrong with a goal on the robot's own map, as the catalogue's word for it (words.js,
// trouble.*; "" when nothing is, or when the map's cells are not read yet): outside the map,
// on an occupied cell (map_server's grey below 89: more than 65 % sure), or on an unknown one.
function goalTrouble(grid, pose) {
  if (!grid || !pose) return "";
  const column = Math.floor((pose.x - grid.origin.x) / grid.resolution);
  const row = Math.floor((pose.y - grid.origin.y) / grid.resolution);
  if (column < 0 || row < 0 || column >= grid.width || row >= grid.height) {
    return "outside";
  }
  if (!grid.cells) return "";
  const grey = grid.cells[row * grid.width + column];
  if (grey === 205) return "unseen";
  if (grey < 89) return "obstacle";
  return "";
}

// Labels placed greedily: each takes the first of a few spots around its anchor where it
// overlaps nothing placed before, or the spot where it overlaps least. Boxes are in SVG
// coordinates (y down).
function overlap(a, b) {
  const w = Math.min(a.x + a.w, b.x + b.w) - Math.max(a.x, b.x);
  const h = Math.min(a.y + a.h, b.y + b.h) - Math.max(a.y, b.y);
  return w > 0 && h > 0 ? w * h : 0;
}

function away(point, box) {
  // How far `point` is from `box` (0 inside it).
  const dx = Math.max(box.x - point.x, 0, point.x - box.x - box.w);
  const dy = Math.max(box.y - point.y, 0, point.y - box.y - box.h);
  return Math.hypot(dx, dy);
}

// Where a label may go around its anchor, by name: the box's top-left corner for a box of
// w x h at `gap` from the anchor (x, y).
const SPOTS = {
  above: (x, y, w, h, gap) => [x - w / 2, y - gap - h],
  right: (x, y, w, h, gap) => [x + gap, y - h / 2],
  below: (x, y, w, h, gap) => [x - w / 2, y + gap],
  left: (x, y, w, h, gap) => [x - gap - w, y - h / 2],
  aboveRight: (x, y, w, h, gap) => [x + gap * 0.7, y - gap * 0.7 - h],
  belowRight: (x, y, w, h, gap) => [x + gap * 0.7, y + gap * 0.7],
  aboveLeft: (x, y, w, h, gap) => [x - gap * 0.7 - w, y - gap * 0.7 - h],
  belowLeft: (x, y, w, h, gap) => [x - gap * 0.7 - w, y + gap * 0.7],
};
const AROUND = Object.keys(SPOTS);

// `order`: the spots to try, first first; `others`: anchors a label must not sit nearer to
// than to its own (the other places), for a reader takes a label for the nearest mark's.
function placeLabel(taken, x, y, text, size, gap, order = AROUND, others = [], w = text.length * size * 0.66) {
  const view = taken.view; // a spot that leaves the view is worse than one that overlaps
  const h = size * 1.25;
  let best = null;
  for (const spot of order) {
    const [left, top] = SPOTS[spot](x, y, w, h, gap);
    const box = { x: left, y: top, w, h };
    const inside = view ? overlap(box, view) : box.w * box.h;
    const own = away({ x, y }, box);
    const misleading = others.some((other) => away(other, box) <= own) ? w * h : 0;
    const cost = taken.reduce((sum, other) => sum + overlap(box, other), 0) +
      10 * (box.w * box.h - inside) + misleading;
    if (!best || cost < best.cost) best = { box, cost };
    if (cost === 0) break;
  }
  taken.push(best.box);
  return { x: best.box.x, y: best.box.y + size * 0.95 }; // text baseline, anchored at its start
}

// The order a place's label tries the spots around it: beside its circle, on the side that
// faces away from the other places (where there is room), then the other side, then above
// or below (away first), then the corners. It depends on the places alone, so that a label
// is on the same side of its place at every redraw, whatever the robot and the orders do.
function placeOrder(place, places) {
  const others = places.filter((other) => other !== place);
  const cx = others.reduce((sum, other) => sum + other.pose.x, 0) / (others.length || 1);
  const cy = others.reduce((sum, other) => sum + other.pose.y, 0) / (others.length || 1);
  const east = !others.length || place.pose.x >= cx;
  const north = !others.length || place.pose.y >= cy; // world y up: north is above
  const [first, second] = east ? ["right", "left"] : ["left", "right"];
  const [up, down] = north ? ["above", "below"] : ["below", "above"];
  const corners = [`${north ? "above" : "below"}${east ? "Right" : "Left"}`,
    `${north ? "above" : "below"}${east ? "Left" : "Right"}`,
    `${north ? "below" : "above"}${east ? "Right" : "Left"}`,
    `${north ? "below" : "above"}${east ? "Left" : "Right"}`];
  return [first, second, up, down, ...corners];
}

// How wide `text` is drawn at font size `size` in `svg` (in its user units): measured once
// per text, or a generous guess while the map is not laid out (hidden).
const measured = new Map();
function textWidth(svg, text, size) {
  if (!measured.has(text)) {
    // In a place's group, so that it has the font a place's label has.
    const probe = node("g", { class: "place", visibility: "hidden" });
    const sample = node("text", { "font-size": 100, class: "label" }, text);
    probe.append(sample);
    svg.append(probe);
    const width = sample.getComputedTextLength();
    probe.remove();
    if (width > 0) measured.set(text, width / 100);
  }
  return measured.has(text) ? measured.get(text) * size : text.length * size * 0.66;
}

// The view box, in world metres: everything that is drawn (the robot's map where it is
// known, the places, the robot, its recent trail and every staged or queued target), with
// a margin, square as the map is, never narrower than 5 m.
function frame(scene) {
  const seen = [];
  if (scene.pose) seen.push(scene.pose);
  for (const place of scene.places) seen.push(place.pose);
  for (const step of scene.steps) {
    if (step.to) seen.push(step.to);
    if (step.from) seen.push(step.from);
  }
  for (const pose of scene.trail.slice(-50)) if (pose) seen.push(pose);
  if (scene.map) {
    const grid = scene.map;
    const known = grid.extent || {
      minX: grid.origin.x, minY: grid.origin.y,
      maxX: grid.origin.x + grid.width * grid.resolution,
      maxY: grid.origin.y + grid.height * grid.resolution,
    };
    seen.push({ x: known.minX, y: known.minY }, { x: known.maxX, y: known.maxY });
  }
  if (!seen.length) seen.push({ x: 0, y: 0 });
  const xs = seen.map((p) => p.x);
  const ys = seen.map((p) => p.y);
  const [minX, maxX, minY, maxY] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const size = Math.max(maxX - minX, maxY - minY, 5);
  const span = size * 1.08 + 1; // room for the labels above the places at the edges
  return { cx: (minX + maxX) / 2, cy: (minY + maxY) / 2, span };
}

function point(pose, radius, angle) {
  return [pose.x + radius * Math.cos(angle), pose.y + radius * Math.sin(angle)];
}

// A turn on the spot would be drawn under the robot: it is drawn around it instead, an arc
// from the heading it starts with to the one it ends with, ending in an arrowhead, and a
// dashed ghost heading from the robot to the arc's end. `ring` moves each later turn at
// the same spot one ring further out.
function turnShapes(step, unit, ring, label, taken) {
  const target = step.order.target_pose;
  let turned = target && target.frame === ROBOT_FRAME ? target.yaw || 0
    : normalize(step.to.yaw - step.from.yaw);
  turned = Math.max(-2 * Math.PI + 0.05, Math.min(2 * Math.PI - 0.05, turned));
  const radius = unit * (5.5 + 2.2 * ring);
  const start = point(step.from, radius, step.from.yaw);
  const end = point(step.to, radius, step.from.yaw + turned);
  const large = Math.abs(turned) > Math.PI ? 1 : 0;
  const sweep = turned > 0 ? 0 : 1; // counter-clockwise in the world is so on screen too
  const shapes = [
    node("path", {
      d: `M ${start[0]} ${-start[1]} A ${radius} ${radius} 0 ${large} ${sweep} ${end[0]} ${-end[1]}`,
      class: "turn", "stroke-width": unit * 0.7, fill: "none",
    }),
    node("line", {
      x1: step.to.x, y1: -step.to.y, x2: end[0], y2: -end[1], class: "heading",
      "stroke-width": unit * 0.5, "stroke-dasharray": `${unit * 1.2} ${unit}`,
    }),
  ];
  const along = step.from.yaw + turned + (turned > 0 ? Math.PI / 2 : -Math.PI / 2);
  shapes.push(arrow({ x: end[0], y: end[1], yaw: along }, unit * 2.2, "target"));
  const [lx, ly] = point(step.to, radius + unit * 1.2, step.from.yaw + turned);
  const spot = placeLabel(taken, lx, -ly, label, unit * 2.6, unit * 1.2);
  shapes.push(node("text", { x: spot.x, y: spot.y, "font-size": unit * 2.6, class: "number" }, label));
  return shapes;
}

// Draw everything into `svg`. `scene`: {pose, trail, places, steps (staged and queued),
// map (the robot's occupancy grid, or null)}; `onPlace(place)` is called when a place is
// chosen with the mouse or the keyboard.
function draw(svg, scene, onPlace) {
  const { cx, cy, span } = frame(scene);
  svg.setAttribute("viewBox", `${cx - span / 2} ${-cy - span / 2} ${span} ${span}`);
  const unit = span / 60; // line widths and text scale with the view
  const layers = [];

  if (scene.map) {
    const grid = scene.map;
    const image = node("image", {
      href: `data:image/png;base64,${grid.png}`,
      x: grid.origin.x, y: grid.origin.y,
      width: grid.width * grid.resolution, height: grid.height * grid.resolution,
      transform: "scale(1,-1)", preserveAspectRatio: "none", class: "grid",
      "image-rendering": "pixelated",
    });
    layers.push(image);
  }
  // The trail in pieces: a null in it is a break (a restart, a jump), never bridged.
  let piece = [];
  for (const pose of [...scene.trail, null]) {
    if (pose) { piece.push(pose); continue; }
    if (piece.length > 1) {
      layers.push(node("polyline", {
        points: piece.map((p) => `${p.x},${-p.y}`).join(" "),
        class: "trail", "stroke-width": unit * 0.6,
      }));
    }
    piece = [];
  }
  // The places are drawn as on a printed map: at the scale of the map and the places alone
  // (`home`), whatever else the view takes in, and each label from the places alone
  // (placeOrder) where it overlaps no other place or label. So every redraw puts each label
  // at the same spot by its own place, whatever the robot and the orders do. The orders'
  // numbers, placed after, keep clear of them and of the robot.
  const home = frame({ places: scene.places, map: scene.map, steps: [], trail: [], pose: null });
  const mark = home.span / 60;
  const taken = [];
  taken.view = { x: home.cx - home.span / 2, y: -home.cy - home.span / 2, w: home.span, h: home.span };
  for (const place of scene.places) {
    taken.push({ x: place.pose.x - mark * 2.2, y: -place.pose.y - mark * 2.2, w: mark * 4.4, h: mark * 4.4 });
  }
  const size = mark * 2.8;
  for (const place of scene.places) {
    const group = node("g", { class: "place", tabindex: "0", role: "button",
      "aria-label": window.voicectlWords.t("map.stage", { phrase: place.phrase }) });
    group.append(node("title", {}, window.voicectlWords.t("map.clickToStage", { description: place.description, phrase: place.phrase })));
    group.append(node("circle", { cx: place.pose.x, cy: -place.pose.y, r: mark * 2.2 }));
    const others = scene.places.filter((other) => other !== place)
      .map((other) => ({ x: other.pose.x, y: -other.pose.y }));
    // At a gap that clears a robot standing on the place.
    const title = place.title || place.name; // in the panel's language
    const spot = placeLabel(taken, place.pose.x, -place.pose.y, title, size, mark * 3.4,
      placeOrder(place, scene.places), others, textWidth(svg, title, size));
    // One target for the mouse: the circle, its label and the gap between them.
    const label = taken[taken.length - 1];
    const left = Math.min(label.x, place.pose.x - mark * 2.2);
    const top = Math.min(label.y, -place.pose.y - mark * 2.2);
    group.append(node("rect", { class: "hit", x: left, y: top,
      width: Math.max(label.x + label.w, place.pose.x + mark * 2.2) - left,
      height: Math.max(label.y + label.h, -place.pose.y + mark * 2.2) - top }));
    group.append(node("text", { x: spot.x, y: spot.y, "font-size": size, class: "label" }, title));
    group.onclick = () => onPlace(place);
    group.onkeydown = (event) => {
      if (event.key === "Enter" || event.key === " ") { event.preventDefault(); onPlace(place); }
    };
    layers.push(group);
  }
  taken.view = { x: cx - span / 2, y: -cy - span / 2, w: span, h: span }; // the orders' numbers
  // The robot under the orders' marks: what it will do is drawn over where it is.
  if (scene.pose) {
    layers.push(arrow(scene.pose, unit * 3, "robot"));
    taken.push({ x: scene.pose.x - unit * 3.4, y: -scene.pose.y - unit * 3.4, w: unit * 6.8, h: unit * 6.8 });
  }
  const rings = []; // the spots turned on so far, one entry per turn
  scene.steps.forEach((step, index) => {
    if (!step.to || !step.from) return;
    const cls = `step ${step.kind}${step.running ? " running" : ""}`;
    const group = node("g", { class: cls, "data-order": step.order.description });
    const label = String(index + 1);
    const moved = Math.hypot(step.to.x - step.from.x, step.to.y - step.from.y);
    if (moved < 0.05) {
      const ring = rings.filter((spot) => Math.hypot(spot.x - step.to.x, spot.y - step.to.y) < 0.05).length;
      rings.push(step.to);
      group.append(...turnShapes(step, unit, ring, label, taken));
    } else {
      group.append(node("line", { x1: step.from.x, y1: -step.from.y, x2: step.to.x, y2: -step.to.y,
        "stroke-width": unit * (step.running ? 0.9 : 0.6), "stroke-dasharray": `${unit * 2} ${unit * 1.5}` }));
      group.append(arrow(step.to, unit * 2.4, "target"));
      const spot = placeLabel(taken, step.to.x, -step.to.y, label, unit * 2.6, unit * 2.5);
      group.append(node("text", { x: spot.x, y: spot.y, "font-size": unit * 2.6, class: "number" }, label));
    }
    if (step.trouble) {
      group.classList.add("warn");
      group.append(node("circle", { cx: step.to.x, cy: -step.to.y, r: unit * 4, class: "goal-warn",
        "stroke-width": unit * 0.6, "stroke-dasharray": `${unit} ${unit * 0.6}` }));
    }
    group.append(node("title", {}, `${index + 1}. ${step.order.description}` +
      (step.trouble ? window.voicectlWords.t("map.theGoal",
        { trouble: window.voicectlWords.t(`trouble.${step.trouble}`) }) : "")));
    layers.push(group);
  });
  svg.replaceChildren(...layers);
}

window.voicectlMap = { plan, compose, draw, knownExtent, goalTrouble };
window.voicectlPlan = plan; // for the browser tests: the same code the map draws with
