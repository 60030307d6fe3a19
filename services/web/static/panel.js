// The voicectl panel: speak or type, check what was understood, send, watch the robot.
"use strict";

const $ = (id) => document.getElementById(id);
const { t } = window.voicectlWords; // every word the panel writes, in its language
const PAGE = 20;

const store = {
  get token() { return localStorage.getItem("voicectl-token") || ""; },
  set token(value) { localStorage.setItem("voicectl-token", value); },
  get robot() { return localStorage.getItem("voicectl-robot") || ""; },
  set robot(value) { localStorage.setItem("voicectl-robot", value); },
  get autoSend() { return localStorage.getItem("voicectl-auto-send") === "1"; },
  set autoSend(on) { localStorage.setItem("voicectl-auto-send", on ? "1" : "0"); },
  get speakAnswers() { return localStorage.getItem("voicectl-speak-answers") === "1"; },
  set speakAnswers(on) { localStorage.setItem("voicectl-speak-answers", on ? "1" : "0"); },
};

const view = {
  robot: "",
  staged: [], // {order, said}
  batch: "", // the staged orders the request id below was made for
  batchId: null, // the request id of the staged batch, kept while Send is retried
  labels: null, // the labels the robot's executors serve, once known
  state: null,
  historyOffset: 0,
  events: null, // AbortController of the event stream
  mic: null, // the open microphone, see startMic
  pose: null, // the robot's last pose
  trail: [], // its recent poses
  poseRun: undefined, // the executor run the last pose came from (RobotPose.run)
  places: [], // the named places of the orders
  map: null, // the robot's own map, when it has one
  startedAt: {}, // order id -> the pose where it started (a relative goal is from there)
  drawing: false,
  finished: null, // ids of the history shown, to tell which orders have just ended
  dropped: null, // the closed microphone whose unfinished sentence the person dropped
  unconfirmed: false, // the last STOP pressed here was not confirmed by every part
  photos: new Map(), // order id -> the object URL of the photo it took, once shown
  dismissed: new Set(), // ids of failed orders whose failure the person put away from "Now"
  opened: new Set(), // ids of history rows whose detail the person opened
  talk: null, // the last edit or question heard here and its answer: {said, answer, question}
};
const voice = { context: null, asked: null, playing: null }; // the spoken answers, see say
const answers = window.voicectlAnswers;
const TRAIL = 300;
const JUMP = 4; // metres: more than a drive covers between two poses (0.5 s apart; the simulator runs up to 10x)
const PARTS = ["converter", "stt", "supervisor", "executor", "robot", "navigation"];
// A part that is down, in the words of what the person notices (its name one hover away):
// catalogue entries part.NAME and partDown.NAME.
// How an order that broke its command ended, after its description (broke.STATUS).
const BROKE = new Set(["failed", "rejected", "interrupted"]);
// Orders of this label are the supervisor's own: edits of the queue and questions about it.
const QUEUE_LABEL = "queue";
const isEdit = (order) => order.label === QUEUE_LABEL;
const questionOf = (order) => (isEdit(order) && order.params.edit === "ask" ? order.params.question : null);
const isCorrection = (order) => isEdit(order) && order.params.edit === "replace";

// --- helpers -----------------------------------------------------------------------------------

function setStatus(text) { $("status").textContent = text || ""; } // the login's own line

// --- messages: one place for what just happened -----------------------------------------------
// A message stands next to the control it is about (#add-note under the command line,
// #send-note under Send) or, when it is about the whole panel (the connection, the stop),
// in the banner under the header. Each says what makes it stale (`until`): "connected",
// "released", "staged" (the orders to send changed), "ok" (the next request that worked);
// it goes as soon as that happens, so nothing stays after it stopped being true.
const notes = {}; // element id -> the reason it goes

function note(id, text, until) {
  $(id).textContent = text || "";
  $(id).hidden = !text;
  if (text) notes[id] = until; else delete notes[id];
}

function clearNotes(reason) {
  for (const [id, until] of Object.entries(notes)) if (until === reason) note(id, "");
}

function forPerson(text) {
  // The services' messages serve the command line too: a hint naming a CLI command means
  // nothing to the person at the panel, and is left out. The command is named as it runs
  // where the service runs: `voicectl release`, `.venv/bin/voicectl release`,
  // `/usr/bin/python3 -m voicectl release`.
  return String(text).replace(/\s*\((?:run |use )?`?(?:[^\s()`]+ -m )?[^\s()`]*voicectl [^)]*\)/g, "")
    .replace(/[;,:]?\s*(?:run|use) `?(?:[^\s()`]+ -m )?[^\s()`]*voicectl [^.;]*/g, "");
}

function el(tag, text, cls) {
  const node = document.createElement(tag);
  if (text !== undefined && text !== null) node.textContent = text;
  if (cls) node.className = cls;
  return node;
}

function button(text, cls, onclick, title) {
  const node = el("button", text, cls);
  node.type = "button";
  node.onclick = onclick;
  if (title) node.title = title;
  return node;
}

async function api(path, body, query) {
  const params = new URLSearchParams({ robot: view.robot, ...(query || {}) });
  const init = { headers: { Authorization: `Bearer ${store.token}` } };
  if (body !== undefined) {
    init.method = "POST";
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(`${path}?${params}`, init);
  const data = await response.json().catch(() => ({}));
  if (response.status === 401) showLogin(t("login.wrongToken"));
  if (!response.ok) throw new Error(data.error || response.statusText);
  clearNotes("ok");
  return data;
}

function report(error, where = "banner") { note(where, forPerson(error.message || String(error)), "ok"); }

// --- logging in --------------------------------------------------------------------------------

function tokenFromAddress() {
  // voicectl up prints http://host:port/#token=...: a fragment never reaches the server.
  const match = location.hash.match(/(?:^#|&)token=([^&]+)/);
  if (!match) return false;
  store.token = decodeURIComponent(match[1]);
  history.replaceState(null, "", location.pathname + location.search);
  return true;
}

function showLogin(why) {
  $("panel").hidden = true;
  $("login").hidden = false;
  stopMic();
  if (view.events) view.events.abort();
  showConnected(t("connection.notConnected"));
  setStatus(why || "");
}

function showConnected(trouble) {
  // A panel that cannot reach voicectl must not look live: it says so. Without a token
  // STOP cannot work from here and says why; while the stream reconnects it stays armed
  // (the stop request may still get through).
  const badge = $("connection");
  badge.textContent = trouble || t("connection.connected");
  badge.className = `badge ${trouble ? "offline" : "online"}`;
  const loggedOut = trouble === t("connection.notConnected");
  $("stop").disabled = loggedOut;
  $("stop").title = loggedOut ? t("header.stopOffline") : t("header.stopTitle");
  $("mic").disabled = Boolean(trouble);
  const wasOffline = document.body.classList.contains("offline");
  document.body.classList.toggle("offline", Boolean(trouble));
  // What was shown while connected is the past: the queue's buttons cannot act, the map
  // says its route is not live, the recogniser is not listening.
  for (const control of document.querySelectorAll("#now button")) control.disabled = Boolean(trouble);
  $("map-stale").hidden = !trouble;
  if (trouble) {
    $("current").textContent = trouble;
    $("current").className = "muted";
    $("parts").replaceChildren();
    $("stt-summary").textContent = t("stt.offline");
    if (view.stt) {
      const stale = t("stt.lastKnown", { status: "" });
      const status = $("stt-status").textContent;
      $("stt-status").textContent = t("stt.lastKnown", { status: status.startsWith(stale) ? status.slice(stale.length) : status });
    }
    if (!wasOffline) view.trail.push(null); // whatever comes back, the trail does not join it
  } else {
    clearNotes("connected");
    if (view.stt) showStt(view.stt);
    if (!view.state) $("current").textContent = t("now.waiting");
  }
}

async function start() {
  $("login").hidden = true;
  $("panel").hidden = false;
  $("auto-send").checked = store.autoSend;
  $("speak-answers").checked = store.speakAnswers;
  try {
    const known = await api("/api/robots");
    showRobots(known.robots);
    selectRobot(known.robots.includes(store.robot) ? store.robot : known.default);
  } catch (error) { report(error); }
}

// --- robots and what serves them ----------------------------------------------------------------

function selectRobot(name) {
  view.robot = name;
  store.robot = name;
  view.historyOffset = 0;
  view.state = null;
  // Nothing of the robot shown before stays: not its pose, trail, map or the poses its
  // orders started from; the new robot's come with its event stream.
  view.labels = null;
  view.pose = null;
  view.trail = [];
  view.poseRun = undefined;
  view.map = null;
  view.startedAt = {};
  view.finished = null;
  $("pose").textContent = t("header.noPosition");
  $("parts").replaceChildren();
  $("queue").replaceChildren();
  $("history").replaceChildren();
  $("current").textContent = t("now.waiting");
  $("current").className = "muted";
  showStaged();
  stopMic();
  listen();
}

function showRobots(robots) {
  const select = $("robot");
  if (!view.robot && robots.length) view.robot = robots[0];
  const names = robots.includes(view.robot) ? robots : [view.robot, ...robots];
  select.replaceChildren(...names.map((name) => {
    const option = el("option", name);
    option.value = name;
    option.selected = name === view.robot;
    return option;
  }));
}

function showParts(parts) {
  // Only what is down is shown (what is up is there, hidden, for whoever inspects it), in
  // words of what it means for the person; the part's own name is in its title.
  $("parts").replaceChildren(...Object.entries(parts).map(([name, alive]) => {
    const known = PARTS.includes(name);
    const shown = alive ? (known ? t(`part.${name}`) : name)
      : (known ? t(`partDown.${name}`) : t("partDown.other", { name }));
    const item = el("li", shown, `badge ${alive ? "online" : "offline"}`);
    item.title = t(alive ? "part.online" : "part.offline", { name });
    item.dataset.part = name;
    return item;
  }));
}

function showStt(status) {
  // A calm line for the person at the microphone; what the recogniser listens with one
  // click away, for whoever looks after it.
  view.stt = status;
  const parts = [status.engine, status.grammar_version && t("stt.grammar", { version: status.grammar_version.slice(0, 8) }),
    status.detail, status.sessions ? t("stt.microphones", { count: status.sessions }) : ""];
  $("stt-status").textContent = parts.filter(Boolean).join(" · ");
  if (!document.body.classList.contains("offline")) {
    $("stt-summary").textContent = view.mic && view.mic.socket ? t("stt.listening") : t("stt.ready");
  }
  const deaf = status.unpronounceable || [];
  $("stt-deaf").hidden = !deaf.length;
  $("stt-deaf").textContent = deaf.length ? t("stt.deaf", { words: deaf.join(", ") }) : "";
}

function showPose(pose) {
  const degrees = Math.round((pose.yaw * 180) / Math.PI);
  $("pose").textContent = t("pose.line", { x: pose.x.toFixed(1), y: pose.y.toFixed(1), degrees });
  view.pose = { x: pose.x, y: pose.y, yaw: pose.yaw };
  const last = view.trail[view.trail.length - 1];
  // A restarted executor, or a jump no drive makes between two poses (a relocalised
  // robot), breaks the trail: a straight line across it would be a path never taken.
  const restarted = view.poseRun !== undefined && pose.run !== view.poseRun;
  view.poseRun = pose.run;
  if (last && (restarted || Math.hypot(last.x - pose.x, last.y - pose.y) > JUMP)) view.trail.push(null);
  if (!last || Math.hypot(last.x - pose.x, last.y - pose.y) > 0.02) view.trail.push(view.pose);
  if (view.trail.length > TRAIL) view.trail.splice(0, view.trail.length - TRAIL);
  redraw();
}

// --- the map -----------------------------------------------------------------------------------

function redraw() {
  if (view.drawing) return; // once per frame, however many updates arrive
  view.drawing = true;
  requestAnimationFrame(() => {
    view.drawing = false;
    window.voicectlMap.draw($("map"), scene(), (place) => addText(place.phrase));
  });
}

function showMap(grid) {
  // Drawn at once, framed on the whole grid; framed on its known part once that is found.
  view.map = grid;
  redraw();
  window.voicectlMap.knownExtent(grid).then((extent) => {
    if (view.map !== grid) return;
    grid.extent = extent;
    redraw();
  });
}

function scene() {
  // Where the robot will go: the running order from where it started, then the queue, then
  // what is staged, each from where the one before ends.
  const steps = [];
  let at = view.pose;
  const state = view.state;
  const chain = (orders, kind, from) => {
    const planned = window.voicectlMap.plan(from, orders);
    for (const step of planned) {
      steps.push({ ...step, kind, running: kind === "running" });
      if (step.to) at = step.to;
    }
  };
  if (state && state.current) {
    chain([state.current.order], "running", view.startedAt[state.current.id] || view.pose);
  }
  if (state) chain(state.queue.map((record) => record.order), "queued", at);
  chain(view.staged.filter((item) => !isEdit(item.order)).map((item) => item.order), "staged", at);
  steps.forEach((step, index) => {
    step.number = index + 1; // as the map numbers it
    step.trouble = step.to ? window.voicectlMap.goalTrouble(view.map, step.to) : "";
  });
  showGoalWarning(steps.filter((step) => step.kind === "staged" && step.trouble));
  return { pose: view.pose, trail: view.trail, places: view.places, steps, map: view.map };
}

function showGoalWarning(troubled) {
  // Said before Send, beside it, as on the map: goals the robot's own map cannot hold, one
  // sentence for each kind of trouble, naming every order it concerns (with its number on
  // the map where two have the same words).
  const box = $("goal-warning");
  box.hidden = !troubled.length;
  const kinds = new Map();
  for (const step of troubled) kinds.set(step.trouble, [...(kinds.get(step.trouble) || []), step]);
  const count = (description) => troubled.filter((step) => step.order.description === description).length;
  box.replaceChildren(...[...kinds].map(([trouble, steps]) => {
    const names = steps.map((step) => `“${step.order.description}”` +
      (count(step.order.description) > 1 ? t("staging.onMap", { number: step.number }) : ""));
    const named = names.length > 1 ? `${names.slice(0, -1).join(", ")}${t("list.and")}${names[names.length - 1]}` : names[0];
    const goals = steps.length > 1
      ? t("staging.goals", { trouble: t(`trouble.${trouble}.many`) })
      : t("staging.goal", { trouble: t(`trouble.${trouble}`) });
    return el("span", t("staging.mayNot", { named, goals }));
  }));
}

function placesIn(places) {
  // Each language's orders give their own places: the panel's, else the default's.
  const mine = places.filter((place) => (place.language || "en") === window.voicectlWords.language);
  return mine.length ? mine : places.filter((place) => (place.language || "en") === "en");
}

// --- the live stream ---------------------------------------------------------------------------

async function listen() {
  if (view.events) view.events.abort();
  const controller = new AbortController();
  view.events = controller;
  const query = new URLSearchParams({ robot: view.robot });
  while (!controller.signal.aborted) {
    try {
      // Server-sent events read with fetch, so that the token stays in a header.
      const response = await fetch(`/api/events?${query}`, {
        headers: { Authorization: `Bearer ${store.token}` },
        signal: controller.signal,
      });
      if (response.status === 401) { showLogin(t("login.wrongToken")); return; }
      if (!response.ok) throw new Error((await response.json()).error || response.statusText);
      showConnected("");
      const reader = response.body.getReader();
      const decoder = new TextDecoder();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += decoder.decode(value, { stream: true });
        let end;
        while ((end = buffer.indexOf("\n\n")) >= 0) {
          const frame = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          if (frame.startsWith("data: ")) handle(JSON.parse(frame.slice(6)));
        }
      }
    } catch (error) {
      if (controller.signal.aborted) return;
      showConnected(t("connection.reconnecting"));
      note("banner", t("connection.lost"), "connected");
    }
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

function handle(message) {
  const mine = view.mic && message.session === view.mic.session;
  switch (message.type) {
    case "stateupdate": showState(message.state); break;
    case "parts": if (message.robot === view.robot) showParts(message.parts); break;
    case "robots": showRobots(message.robots); break;
    case "labels": if (message.robot === view.robot) { view.labels = message.labels; showStaged(); } break;
    case "robotpose": showPose(message); showTalk(); break;
    case "places": view.places = placesIn(message.places); redraw(); showTalk(); break;
    case "robotmap": showMap(message); break;
    case "sttstatus": showStt(message); break;
    case "partialtranscript":
      if (mine && view.mic.socket) { showHeard(message.text, "partial"); showEars(null); }
      break;
    case "transcript":
      // What was heard; whether it is a command is the converter's proposal, next.
      if (mine) showHeard((message.transcription || {}).text || message.text, "final");
      break;
    case "proposal":
      if (mine) propose(message);
      else if (view.dropped && message.session === view.dropped.session) {
        showHeard(t("heard.droppedEnded", { text: view.dropped.unfinished, ended: message.transcript }), "partial");
        view.dropped = null;
      }
      break;
    default: break;
  }
}

// --- speaking ----------------------------------------------------------------------------------

function micUnavailable() {
  if (!window.isSecureContext || !navigator.mediaDevices || !window.AudioWorkletNode) {
    return t("mic.insecure");
  }
  return "";
}

async function startMic() {
  const why = micUnavailable();
  if (why) { showMicNote(why); return; }
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia({
      // The recogniser wants the raw voice: no echo cancelling, denoising or gain riding.
      audio: { echoCancellation: false, noiseSuppression: false, autoGainControl: false, channelCount: 1 },
    });
  } catch (error) {
    const reasons = { NotAllowedError: "mic.refused", NotFoundError: "mic.notFound", NotReadableError: "mic.busy" };
    showMicNote(reasons[error.name] ? t(reasons[error.name]) : t("mic.none", { error: error.message }));
    return;
  }
  const context = new AudioContext();
  await context.audioWorklet.addModule("/static/capture.js");
  const node = new AudioWorkletNode(context, "capture");
  const silent = context.createGain();
  silent.gain.value = 0;
  context.createMediaStreamSource(stream).connect(node).connect(silent).connect(context.destination);
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}/api/audio`);
  socket.binaryType = "arraybuffer";
  const mic = { stream, context, node, socket, session: "", waiting: [] };
  view.mic = mic;
  // The recogniser hears the person in the panel's language.
  socket.onopen = () => socket.send(JSON.stringify({ token: store.token, robot: view.robot, language: window.voicectlWords.language }));
  socket.onmessage = (event) => {
    const message = JSON.parse(event.data);
    if (message.type === "session") {
      mic.session = message.session;
      for (const frame of mic.waiting) socket.send(frame); // said before the session opened
      mic.waiting = [];
    } else if (message.type === "error") {
      showMicNote(message.error);
    }
  };
  socket.onclose = () => { if (view.mic === mic) stopMic(); };
  node.port.onmessage = (event) => {
    $("level").style.width = `${Math.min(100, Math.round(event.data.level * 300))}%`;
    if (socket.readyState !== WebSocket.OPEN) return;
    if (mic.session) socket.send(event.data.pcm);
    else if (mic.waiting.length < 100) mic.waiting.push(event.data.pcm);
  };
  showMicNote("");
  showHeard(t("heard.listening"), "partial");
  $("discard").hidden = true;
  $("stt-summary").textContent = t("stt.listening");
  $("mic").setAttribute("aria-pressed", "true");
  $("mic").lastChild.textContent = t("speak.stopListening");
  $("mic").classList.add("live");
}

function stopMic() {
  const mic = view.mic;
  if (!mic || !mic.socket) return;
  // A sentence cut off mid-way is finished by the recogniser: the page says so, and a
  // "discard" drops it. Whatever the person does next with the orders (Send, Add, Clear,
  // Listen again) drops it too: a late answer never fills "To send" behind their back.
  const unfinished = $("heard").classList.contains("partial") && $("heard").textContent !== t("heard.listening")
    ? $("heard").textContent : "";
  view.mic = { session: mic.session, unfinished }; // its last transcript may still come
  if (unfinished) {
    showHeard(t("heard.finishing", { text: unfinished }), "partial");
    $("discard").hidden = false;
  } else if ($("heard").textContent === t("heard.listening")) {
    showHeard("", "partial");
  }
  if (mic.socket.readyState === WebSocket.OPEN) mic.socket.send(JSON.stringify({ type: "stop" }));
  for (const track of mic.stream.getTracks()) track.stop();
  mic.context.close();
  $("level").style.width = "0";
  $("mic").setAttribute("aria-pressed", "false");
  $("mic").lastChild.textContent = t("speak.listen");
  $("mic").classList.remove("live");
  if (!document.body.classList.contains("offline")) $("stt-summary").textContent = t("stt.ready");
}

function discardUnfinished() {
  // The closed microphone's late answer, if any, is dropped (see stopMic).
  const mic = view.mic;
  if (!mic || mic.socket) return;
  view.mic = null;
  if (mic.unfinished && !$("discard").hidden) {
    showHeard(t("heard.dropped", { text: mic.unfinished }), "partial");
    view.dropped = mic; // its answer, when it comes, is shown for what it was and not staged
  }
  $("discard").hidden = true;
}

function showMicNote(text) {
  $("mic-note").textContent = text;
  $("mic-note").hidden = !text;
}

function showHeard(text, kind) {
  $("heard").textContent = text;
  $("heard").className = `heard ${kind}`;
}

// --- checking: staging, errors, suggestions ---------------------------------------------------

function showEars(proposal) {
  // Each ear's words and verdict, and why the decision went the way it did.
  const box = $("ears");
  const hearings = proposal ? proposal.hearings || [] : [];
  $("ears-more").hidden = !hearings.length; // the engines' words, one click away
  box.replaceChildren(...hearings.map((hearing) => {
    const item = el("li", "", hearing.accepted ? "ear accepted" : "ear refused");
    item.append(el("span", hearing.ear === "grammar" ? t("heard.grammar") : hearing.ear, "ear-name"), " ",
      el("q", hearing.text || t("heard.nothing")), " ", el("span", hearing.verdict, "muted"));
    return item;
  }));
  if (hearings.length && proposal.decision) box.append(el("li", proposal.decision, "ear-decision"));
}

async function propose(proposal) {
  if (view.mic && !view.mic.socket) view.mic = null; // the closed microphone's last answer
  $("discard").hidden = true;
  showEars(proposal);
  const asked = !proposal.rejected && !(proposal.doubts || []).length && proposal.orders.length &&
    proposal.orders.every(isEdit) && !proposal.orders.some((order) => order.confirm);
  // An edit or a question is answered (below), not read back.
  if (!asked) say(answers.proposalWords(proposal));
  if (proposal.rejected) {
    // Why, in plain words, on the line that showed what was heard ("I heard '…': not a
    // command"); a suggestion, if the converter had one, below it.
    const [why] = proposal.errors;
    if (why) showHeard(t("heard.rejected", { reason: why.reason, text: proposal.transcript }), "rejected");
    showErrors(proposal.transcript, (why && why.candidates.length) ? [{ ...why, reason: t("errors.didYouMean") }] : []);
    showDoubt(null);
    return;
  }
  if ((proposal.doubts || []).length) {
    // A doubtful value is asked, never guessed: nothing is staged or sent until the person
    // picks what they said.
    showErrors(proposal.transcript, proposal.errors);
    showDoubt(proposal);
    return;
  }
  showDoubt(null);
  showHeard(proposal.transcript, "final"); // the words the orders stand on
  const orders = await take(proposal.orders, proposal.transcript, true);
  if (store.autoSend && orders.length && !proposal.errors.length) {
    submit(orders.map((order) => ({ order, said: proposal.transcript, spoken: true }))).catch(report);
    showErrors(proposal.transcript, []);
    return;
  }
  stage(orders, proposal.transcript, true);
  showErrors(proposal.transcript, proposal.errors);
}

// --- edits of the queue and questions about it --------------------------------------------

async function take(orders, said, spoken) {
  // Questions are asked at once, and a correction of an order staged here corrects it
  // where it stands; what is left (orders, and edits of the queue) is staged.
  const left = [];
  const questions = [];
  for (const order of orders) {
    if (questionOf(order)) questions.push(order);
    else if (!(isCorrection(order) && await correctStaged(order, said))) left.push(order);
  }
  if (questions.length) await ask(questions, said, spoken);
  return left;
}

async function ask(questions, said, spoken) {
  try {
    const result = await api("/api/submit", { orders: questions, transcript: said, via: "panel", spoken });
    const answered = result.answers[result.answers.length - 1];
    talk(said, answered.answer, questionOf(questions[questions.length - 1]));
  } catch (error) { report(error); }
}

async function correctStaged(change, said) {
  // "no, three" or "not the kitchen, the bathroom" for an order staged and not sent: made
  // again by the converter (its own slots and bounds), in its place. False when no staged
  // order is the one named: then it corrects the queue, once sent.
  const which = change.params.which;
  const named = (item) => !isEdit(item.order) &&
    (which === "last" || (item.order.case || item.order.order) === which);
  const index = view.staged.map(named).lastIndexOf(true);
  if (index < 0) return false;
  const before = view.staged[index].order;
  try {
    const result = await api("/api/amend", { order: before, change });
    view.staged[index] = { ...view.staged[index], order: result.order };
    showStaged();
    talk(said, `now ${answers.spoken(result.order.description)}, not ${answers.spoken(before.description)}`);
  } catch (error) {
    talk(said, forPerson(error.message));
  }
  return true;
}

function talk(said, answer, question = null) {
  // What was asked or changed, and the answer: a question's answer is kept true as the
  // robot's state changes (answers.js says it as the supervisor would now).
  view.talk = { said, answer, question };
  showTalk();
  say(answer);
}

function showTalk() {
  const shown = view.talk;
  $("talk").hidden = !shown;
  if (!shown) return;
  $("talk-said").textContent = shown.said;
  $("talk-answer").textContent = shown.question && view.state
    ? answers.questionWords(shown.question, view.state, view.pose, view.places)
    : shown.answer;
}

function showDoubt(proposal) {
  // Every doubtful value is asked, one after another: the sentence shows them all marked,
  // the first still open has its choices, and the words go to the staged orders once each
  // has been answered.
  const box = $("doubt");
  if (!proposal) { box.hidden = true; box.replaceChildren(); return; }
  const words = proposal.transcript.split(" ");
  const open = [...proposal.doubts].sort((a, b) => a.position - b.position);
  const [doubt, ...later] = open;
  const size = doubt.words.split(" ").length;
  const answered = (choice) => {
    // The words with this doubt answered; later doubts move by the words it added.
    const text = [...words.slice(0, doubt.position), ...choice.split(" "), ...words.slice(doubt.position + size)];
    const shift = choice.split(" ").length - size;
    return { transcript: text.join(" "), doubts: later.map((d) => ({ ...d, position: d.position + shift })) };
  };
  const choose = (choice) => {
    const next = answered(choice);
    if (next.doubts.length) { showDoubt(next); return; }
    showDoubt(null);
    addText(next.transcript);
  };
  const marked = new Set(open.flatMap((d) => d.words.split(" ").map((_, i) => d.position + i)));
  const shown = el("span", "", "muted");
  words.forEach((word, i) => {
    if (i) shown.append(" ");
    if (!marked.has(i)) { shown.append(word); return; }
    const mark = el("mark", word);
    if (i >= doubt.position && i < doubt.position + size) mark.className = "asking";
    shown.append(mark);
  });
  const count = open.length > 1 ? t("doubt.toAnswer", { count: open.length }) : "";
  box.replaceChildren(el("strong", t("doubt.didYouSay")), " ", shown, count, " ");
  const staged = (choice) => t(later.length ? "doubt.answerTitle" : "doubt.stageTitle", { text: answered(choice).transcript });
  if (!doubt.alternatives.length) {
    // Nothing to choose between: a yes or a no, not a list of one.
    box.append("? ", button(later.length ? t("doubt.yes") : t("doubt.yesAdd"), "choice", () => choose(doubt.words), staged(doubt.words)), " ");
    box.append(button(t("doubt.sayAgain"), "choice", () => showDoubt(null), t("doubt.sayAgainTitle")));
    box.hidden = false;
    return;
  }
  for (const choice of [doubt.words, ...doubt.alternatives]) {
    box.append(button(choice, "choice", () => choose(choice), staged(choice)), " ");
  }
  box.append(button(t("doubt.sayAgain"), "choice", () => showDoubt(null), t("doubt.sayAgainTitle")));
  box.hidden = false;
}

function stage(orders, said, spoken = false) {
  for (const order of orders) view.staged.push({ order, said, spoken });
  showStaged();
}

function suggestions(error) { return (error.candidates || []).filter((c) => !c.includes("/")); }

function showErrors(said, errors) {
  // A suggestion repairs the sentence: its words take the place of the ones that did not
  // parse and the whole sentence is checked again, so the rest of it is kept (and the
  // other suggestions with it, if they still apply).
  $("errors").replaceChildren(...errors.map((error) => {
    const item = el("li");
    item.append(el("strong", error.text || said || t("heard.nothing")), ` ${t("errors.reason", { reason: error.reason })}`);
    for (const phrase of suggestions(error)) {
      const fixed = error.text && said && said.includes(error.text) ? said.replace(error.text, phrase) : phrase;
      item.append(" ", button(phrase, "suggestion", () => addText(fixed),
        t("errors.checkAgain", { text: fixed })));
    }
    return item;
  }));
}

async function addText(text) {
  // What parses is staged and what did not stays in the input to be fixed, not retyped. A
  // sentence with a suggested repair is staged only once repaired, so that its orders keep
  // the order they were said in.
  discardUnfinished();
  try {
    const result = await api("/api/parse", { text, language: window.voicectlWords.language });
    const repairable = result.errors.some((error) => suggestions(error).length);
    if (!repairable) stage(await take(result.orders, text, false), text);
    const left = result.errors.map((error) => error.text).filter(Boolean);
    $("text").value = repairable ? text : left.join(" then ");
    showErrors(text, result.errors);
    note("add-note", "", "ok");
  } catch (error) { report(error, "add-note"); }
}

function showStaged() {
  const batch = JSON.stringify(view.staged.map((item) => item.order));
  if (batch !== view.batch) { view.batchId = null; clearNotes("staged"); } // a new request
  view.batch = batch;
  const list = $("staged");
  list.replaceChildren(...view.staged.map((item, index) => {
    const row = el("li");
    row.tabIndex = 0;
    row.draggable = true;
    row.dataset.index = String(index);
    // The sentence once, on the first of the orders it gave, not on every row.
    const first = index === 0 || view.staged[index - 1].said !== item.said;
    row.append(el("span", item.order.description, "what"));
    if (isEdit(item.order)) {
      row.classList.add("edit");
      row.append(el("span", t("staging.changesQueue"), "muted edit-note"));
    }
    if (first) row.append(el("span", item.said, "muted said"));
    if (view.labels && !isEdit(item.order) && !view.labels.includes(item.order.label)) {
      // Said before it is sent: the executor would refuse it.
      row.append(el("span", t("staging.unserved", { label: item.order.label }), "unserved"));
    }
    row.append(button("↑", "small", () => move(index, index - 1), t("staging.earlier")));
    row.append(button("↓", "small", () => move(index, index + 1), t("staging.later")));
    row.append(button("✕", "small", () => remove(index), t("staging.remove")));
    row.onkeydown = (event) => {
      if (event.altKey && event.key === "ArrowUp") { move(index, index - 1, true); event.preventDefault(); }
      if (event.altKey && event.key === "ArrowDown") { move(index, index + 1, true); event.preventDefault(); }
      if (event.key === "Delete" || event.key === "Backspace") { remove(index); event.preventDefault(); }
    };
    row.ondragstart = (event) => event.dataTransfer.setData("text/plain", String(index));
    row.ondragover = (event) => event.preventDefault();
    row.ondrop = (event) => {
      event.preventDefault();
      move(Number(event.dataTransfer.getData("text/plain")), index);
    };
    return row;
  }));
  const empty = view.staged.length === 0;
  $("staged-empty").hidden = !empty;
  $("send").disabled = empty;
  $("clear").disabled = empty;
  redraw();
}

function move(from, to, keepFocus) {
  if (to < 0 || to >= view.staged.length || from === to) return;
  const [item] = view.staged.splice(from, 1);
  view.staged.splice(to, 0, item);
  showStaged();
  if (keepFocus) $("staged").children[to].focus();
}

function remove(index) {
  view.staged.splice(index, 1);
  showStaged();
}

function newRequestId() {
  // getRandomValues works without a secure context too (crypto.randomUUID does not).
  const bytes = crypto.getRandomValues(new Uint8Array(16));
  return Array.from(bytes, (byte) => byte.toString(16).padStart(2, "0")).join("");
}

// One request id per batch a person sends: a Send retried after a lost answer carries the
// same id, and the supervisor queues nothing twice. Any change to the batch makes it new.
async function submit(items, requestId = newRequestId()) {
  const said = [...new Set(items.map((item) => item.said))].join(" / ");
  const orders = items.map((item) => item.order);
  const spoken = items.some((item) => item.spoken);
  const result = await api("/api/submit", { orders, transcript: said, request_id: requestId, via: "panel", spoken });
  // What each edit did, said: the last one's answer shown, with undo beside the queue.
  const edits = items.filter((item) => isEdit(item.order));
  if (result.answers.length) {
    talk(edits.length ? edits[edits.length - 1].said : said, result.answers.map((a) => a.answer).join("; "));
  }
}

// --- watching ---------------------------------------------------------------------------------

function progressLine(progress) {
  // The executor's own words when it has any ("2.1 m to go"); the numbers otherwise.
  if (progress.text) return progress.text;
  const given = (value) => value !== null && value !== undefined;
  if (given(progress.distance_linear)) return t("progress.distance", { distance: progress.distance_linear.toFixed(1) });
  if (given(progress.distance_angular)) {
    return t("progress.angle", { degrees: Math.round((progress.distance_angular * 180) / Math.PI) });
  }
  return given(progress.percent) ? t("progress.percent", { percent: Math.round(progress.percent) }) : "";
}

function queueLine(record, index, length) {
  const item = el("li");
  item.append(el("span", record.order.description, "what"));
  if (index > 0) {
    item.append(button("↑", "small", () => reorder(record, index - 1), t("queue.earlier")));
  }
  if (index >= 0 && index < length - 1) {
    item.append(button("↓", "small", () => reorder(record, index + 1), t("queue.later")));
  }
  item.append(button(t("queue.cancel"), "small", () => api("/api/cancel", { order_id: record.id }).catch(report)));
  return item;
}

function reorder(record, position) {
  api("/api/reorder", { order_id: record.id, position }).catch(report);
}

function showState(state) {
  view.state = state;
  const why = state.stopped
    ? t("now.stopped")
    : state.paused;
  $("held").hidden = !why;
  $("held-why").textContent = why || "";
  // What each part did is there for whoever asks, one click away.
  $("held-detail").textContent = state.stopped ? state.stop_detail || "" : "";
  $("held-more").hidden = !$("held-detail").textContent;
  $("release").hidden = !state.stopped;
  $("resume").hidden = state.stopped || !state.paused;
  // The last change to the queue, by whoever made it, can be taken back from here.
  $("undo").hidden = !state.undo;
  $("undo").textContent = state.undo ? t("queue.undoWhat", { what: state.undo }) : t("queue.undo");
  showTalk();
  // Latched, the header itself says so on every screen: "Stopped — Release" in STOP's place.
  $("stop").classList.toggle("latched", state.stopped);
  $("stop").hidden = state.stopped && !view.unconfirmed; // a stop not confirmed stays at hand
  $("latched").hidden = !state.stopped;
  document.body.classList.toggle("latched", state.stopped);
  clearNotes(state.stopped ? "stopped" : "released");
  const current = state.current;
  if (current && !view.startedAt[current.id]) view.startedAt[current.id] = view.pose;
  if (current) {
    const box = el("div", undefined, "current");
    box.append(queueLine(current, -1, 0));
    const progress = current.progress;
    if (progress) {
      box.append(el("div", progressLine(progress), "muted progress-text"));
      if (progress.percent !== null && progress.percent !== undefined) {
        const bar = el("div", undefined, "bar");
        const fill = el("div");
        fill.style.width = `${Math.max(0, Math.min(100, progress.percent))}%`;
        bar.append(fill);
        box.append(bar);
      }
    }
    $("current").replaceChildren(box);
    $("current").className = "";
  } else if (lastFailure(state)) {
    showFailure(lastFailure(state));
  } else {
    $("current").textContent = t("now.idle");
    $("current").className = "muted";
  }
  const length = state.queue_length;
  $("queue").replaceChildren(...state.queue.map((record, index) => queueLine(record, index, length)));
  const more = length - state.queue.length;
  if (more > 0) $("queue").append(el("li", t("queue.more", { count: more }), "muted"));
  if (view.historyOffset === 0) showHistory(state.history, null);
  announceEnded(state);
  redraw();
}

function lastFailure(state) {
  // The newest order that failed (or was refused, or interrupted), while no order has
  // started since: "Now" says so until the next one starts or the person dismisses it.
  if (state.current) return null;
  const index = state.history.findIndex((record) => BROKE.has(record.status));
  if (index < 0 || view.dismissed.has(state.history[index].id)) return null;
  if (state.history.slice(0, index).some((record) => record.started_at)) return null;
  return state.history[index];
}

function showFailure(record) {
  const [said] = splitDetail(forPerson(record.message));
  const box = el("div", undefined, `ended ${record.status}`);
  box.append(el("span", `${record.order.description} ${t(`broke.${record.status}`)}${said ? `: ${said}` : ""}`, "what"),
    " ", button(t("now.dismiss"), "small", () => { view.dismissed.add(record.id); showState(view.state); },
      t("now.dismissTitle")));
  $("current").replaceChildren(box);
  $("current").className = "";
}

function announceEnded(state) {
  // The order that has just ended, said once; the history the page opened with is not
  // news. Under an emergency stop the stop's own answer says it all.
  // An edit's own answer says what it did, and how the orders it ended ended.
  const fresh = view.finished ? state.history.filter((record) => !view.finished.has(record.id) &&
    !isEdit(record.order) && !answers.endedByEdit(record)) : [];
  view.finished = new Set(state.history.map((record) => record.id));
  if (fresh.length && !state.stopped) say(answers.outcomeWords(fresh[0]));
}

// --- answering aloud ---------------------------------------------------------------------------

function voiceContext() {
  // A page may sound only once the person has clicked or typed in it: the context is made,
  // or woken, in such an event (the setting's click, or any later one).
  voice.context = voice.context || new AudioContext();
  if (voice.context.state === "suspended") voice.context.resume();
  return voice.context;
}

function hush() {
  if (voice.asked) voice.asked.abort();
  if (voice.playing) voice.playing.stop();
  voice.asked = null;
  voice.playing = null;
}

async function say(text) {
  // The service speaks `text` (POST /api/speech, a WAV) and the page plays it. A new answer
  // replaces the one asked for or playing: stale speech is never queued.
  if (!store.speakAnswers || !text) return;
  hush();
  const asked = new AbortController();
  voice.asked = asked;
  try {
    const response = await fetch("/api/speech", {
      method: "POST",
      headers: { Authorization: `Bearer ${store.token}`, "Content-Type": "application/json" },
      body: JSON.stringify({ text, language: window.voicectlWords.language }),
      signal: asked.signal,
    });
    if (!response.ok) throw new Error((await response.json().catch(() => ({}))).error || response.statusText);
    const context = voiceContext();
    const sound = await context.decodeAudioData(await response.arrayBuffer());
    if (voice.asked !== asked) return; // a newer answer came meanwhile
    if (context.state !== "running") {
      note("banner", t("voice.click"), "ok");
      return;
    }
    const source = context.createBufferSource();
    source.buffer = sound;
    source.connect(context.destination);
    source.onended = () => { if (voice.playing === source) voice.playing = null; };
    source.start();
    voice.playing = source;
  } catch (error) {
    if (error.name !== "AbortError") note("banner", t("voice.cannot", { error: forPerson(error.message) }), "ok");
  }
}

function showHistory(records, total) {
  $("history").replaceChildren(...records.map((record) => {
    const row = el("tr");
    const ended = record.ended_at ? new Date(record.ended_at * 1000).toLocaleString() : "";
    // Who asked, and how: an edit of the queue says so too.
    const how = record.asked && record.asked.spoken ? t("history.spoken", { via: record.asked.via }) : record.asked ? record.asked.via : "";
    const asked = how ? ` (${how})` : "";
    row.append(el("td", record.order.description, isEdit(record.order) ? "what edit" : "what"),
      el("td", t(`status.${record.status}`) || record.status, record.status),
      resultCell(record), el("td", `${record.transcript}${asked}`, "muted said"),
      el("td", ended, "muted ended"));
    return row;
  }));
  const first = view.historyOffset + 1;
  $("page").textContent = records.length ? `${first}–${view.historyOffset + records.length}` +
    (total !== null ? t("history.of", { total }) : "") : "";
  $("newer").disabled = view.historyOffset === 0;
  $("older").disabled = total !== null ? view.historyOffset + records.length >= total
    : records.length < PAGE; // the live page is the most recent records only
}

function splitDetail(message) {
  // "took a photo (kept on the robot as /home/…/photo.png)": the words for a person, and the
  // detail in brackets at their end, for whoever asks.
  const found = /^(.*?\S)\s*\(([^()]*)\)\s*$/s.exec(message || "");
  return found ? [found[1], found[2]] : [message || "", ""];
}

// A photo stays on the robot: the panel fetches it through the API (with the token) and
// shows it in the row, which keeps it when the history is drawn again. The detail of a
// message is one click away, and stays open when the history is drawn again.
function resultCell(record) {
  const [said, detail] = splitDetail(record.message);
  const cell = el("td", said, "message");
  if (detail) {
    const more = el("details", undefined, "more");
    more.open = view.opened.has(record.id);
    more.ontoggle = () => { if (more.open) view.opened.add(record.id); else view.opened.delete(record.id); };
    more.append(el("summary", t("history.more")), el("span", detail, "detail"));
    cell.append(" ", more);
  }
  if (record.order.label !== "pic" || record.status !== "succeeded") return cell;
  const shown = view.photos.get(record.id);
  if (shown) {
    const image = el("img", undefined, "photo");
    image.src = shown;
    image.alt = t("photo.alt", { what: record.order.description });
    cell.append(image);
  } else {
    cell.append(" ", button(t("photo.show"), "show-photo", () => showPhoto(record, cell)));
  }
  return cell;
}

async function showPhoto(record, cell) {
  try {
    const params = new URLSearchParams({ robot: view.robot, order: record.id });
    const response = await fetch(`/api/photo?${params}`, {
      headers: { Authorization: `Bearer ${store.token}` },
    });
    if (!response.ok) throw new Error((await response.json().catch(() => ({}))).error || response.statusText);
    view.photos.set(record.id, URL.createObjectURL(await response.blob()));
    cell.replaceWith(resultCell(record));
  } catch (error) {
    cell.querySelector(".show-photo")?.remove();
    cell.append(el("span", t("photo.none", { error: forPerson(error.message) }), "muted"));
  }
}

async function page(offset) {
  view.historyOffset = Math.max(0, offset);
  try {
    const result = await api("/api/history", undefined, { offset: view.historyOffset, limit: PAGE });
    showHistory(result.records, result.total);
  } catch (error) { report(error); }
}

// --- controls --------------------------------------------------------------------------------

$("save-token").onclick = () => {
  store.token = $("token").value.trim();
  start();
};
$("robot").onchange = (event) => selectRobot(event.target.value);
$("mic").onclick = () => (view.mic && view.mic.socket ? stopMic() : startMic().catch(report));
$("command").onsubmit = (event) => {
  event.preventDefault();
  const text = $("text").value.trim();
  if (!text) return;
  addText(text);
};
$("send").onclick = async () => {
  discardUnfinished();
  const items = view.staged.slice();
  $("send").disabled = true;
  view.batchId = view.batchId || newRequestId();
  try {
    await submit(items, view.batchId);
    view.staged.splice(0, items.length);
    showStaged();
    note("send-note", "");
  } catch (error) {
    showStaged();
    if (view.state && view.state.stopped) {
      // Said where the person looks, and gone once the stop is released.
      note("send-note", t("send.stopped"), "released");
    } else {
      note("send-note", t("send.failed", { error: forPerson(error.message) }), "staged");
    }
  }
};
$("clear").onclick = () => { discardUnfinished(); view.staged = []; showStaged(); };
$("discard").onclick = () => discardUnfinished();
$("auto-send").onchange = (event) => { store.autoSend = event.target.checked; };
$("speak-answers").onchange = (event) => {
  store.speakAnswers = event.target.checked;
  if (event.target.checked) voiceContext(); else hush();
};
for (const kind of ["pointerdown", "keydown"]) {
  document.addEventListener(kind, () => { if (store.speakAnswers) voiceContext(); }, true);
}
$("cancel-all").onclick = () => {
  if (confirm(t("queue.cancelAllConfirm"))) {
    api("/api/cancel_all", {}).catch(report);
  }
};
// Never asks: it stops now. A confirmed stop shows in the header ("Stopped — Release"), from
// the queue's state; one not confirmed is said in the banner until a request works again.
$("stop").onclick = () =>
  api("/api/stop", {})
    .then((stopped) => {
      view.unconfirmed = !stopped.confirmed;
      if (view.state) showState(view.state);
      if (!stopped.confirmed) {
        note("banner", t("stop.unconfirmed", { detail: forPerson(stopped.detail) }), "ok");
      }
      say(answers.stoppedWords(stopped));
    })
    .catch(report);
$("release").onclick = () => api("/api/release", {}).catch(report);
$("head-release").onclick = () => api("/api/release", {}).catch(report);
$("resume").onclick = () => api("/api/resume", {}).catch(report);
$("undo").onclick = () =>
  api("/api/undo", {}).then((result) => talk("undo", result.answer)).catch(report);
$("newer").onclick = () => page(view.historyOffset - PAGE);
$("older").onclick = () => page(view.historyOffset + PAGE);
document.addEventListener("keydown", (event) => {
  const typing = ["INPUT", "TEXTAREA", "SELECT"].includes(document.activeElement.tagName);
  if (event.key === "m" && !typing && !event.ctrlKey && !event.metaKey && !event.altKey) {
    $("mic").click();
  }
});

window.addEventListener("hashchange", () => {
  if (tokenFromAddress()) start(); // the address voicectl up printed, opened in this tab
});

// The panel's words first (words.js), in its language; then the rest.
window.voicectlWords.load().then(() => {
  window.voicectlWords.chooser($("language"));
  tokenFromAddress();
  showStaged();
  if (store.token) start(); else showLogin();
});
