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

// Draw everything into `svg`. `scene`: {pose, trail, places, steps (staged and queued),
// map (the robot's occupancy grid, or null)}; `onPlace(place)` is called when a place is
// chosen with the mouse or the keyboard.
function draw(svg, scene, onPlace) {
  const seen = [];
  if (scene.pose) seen.push(scene.pose);
  for (const place of scene.places) seen.push(place.pose);
  for (const step of scene.steps) if (step.to) seen.push(step.to);
  for (const pose of scene.trail.slice(-50)) seen.push(pose);
  if (!seen.length) seen.push({ x: 0, y: 0 });
  const xs = seen.map((p) => p.x);
  const ys = seen.map((p) => p.y);
  const margin = 1.5;
  let [minX, maxX, minY, maxY] = [Math.min(...xs), Math.max(...xs), Math.min(...ys), Math.max(...ys)];
  const span = Math.max(maxX - minX, maxY - minY, 5) + 2 * margin;
  const [cx, cy] = [(minX + maxX) / 2, (minY + maxY) / 2];
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
  if (scene.trail.length > 1) {
    layers.push(node("polyline", {
      points: scene.trail.map((p) => `${p.x},${-p.y}`).join(" "),
      class: "trail", "stroke-width": unit * 0.6,
    }));
  }
  for (const place of scene.places) {
    const group = node("g", { class: "place", tabindex: "0", role: "button",
      "aria-label": `stage "${place.phrase}"` });
    group.append(node("title", {}, `${place.description}: click to stage "${place.phrase}"`));
    group.append(node("circle", { cx: place.pose.x, cy: -place.pose.y, r: unit * 2.2 }));
    group.append(node("text", { x: place.pose.x, y: -place.pose.y - unit * 3,
      "font-size": unit * 3.2, "text-anchor": "middle" }, place.name));
    group.onclick = () => onPlace(place);
    group.onkeydown = (event) => {
      if (event.key === "Enter" || event.key === " ") { event.preventDefault(); onPlace(place); }
    };
    layers.push(group);
  }
  scene.steps.forEach((step, index) => {
    if (!step.to || !step.from) return;
    const cls = `step ${step.kind}${step.running ? " running" : ""}`;
    const group = node("g", { class: cls, "data-order": step.order.description });
    group.append(node("line", { x1: step.from.x, y1: -step.from.y, x2: step.to.x, y2: -step.to.y,
      "stroke-width": unit * (step.running ? 0.9 : 0.6), "stroke-dasharray": `${unit * 2} ${unit * 1.5}` }));
    group.append(arrow(step.to, unit * 2.4, "target"));
    group.append(node("text", { x: step.to.x + unit * 2.5, y: -step.to.y + unit * 1.2,
      "font-size": unit * 2.6 }, String(index + 1)));
    group.append(node("title", {}, `${index + 1}. ${step.order.description}`));
    layers.push(group);
  });
  if (scene.pose) layers.push(arrow(scene.pose, unit * 3, "robot"));
  svg.replaceChildren(...layers);
}

window.voicectlMap = { plan, compose, draw };
window.voicectlPlan = plan; // for the browser tests: the same code the map draws with
