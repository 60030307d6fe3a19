// The voicectl panel: parse a command, send it, watch the robot carry it out.
"use strict";

const $ = (id) => document.getElementById(id);
let token = localStorage.getItem("voicectl-token") || "";
let proposal = null;

function setStatus(text) { $("status").textContent = text || ""; }

async function api(path, body) {
  const init = { headers: { Authorization: `Bearer ${token}` } };
  if (body !== undefined) {
    init.method = "POST";
    init.headers["Content-Type"] = "application/json";
    init.body = JSON.stringify(body);
  }
  const response = await fetch(path, init);
  const data = await response.json();
  if (response.status === 401) { showLogin("wrong or missing token"); }
  if (!response.ok) { throw new Error(data.error || response.statusText); }
  return data;
}

function el(tag, text, cls) {
  const node = document.createElement(tag);
  if (text !== undefined) node.textContent = text;
  if (cls) node.className = cls;
  return node;
}

function showProposal(transcript, result) {
  proposal = { transcript, orders: result.orders };
  $("transcript").textContent = transcript ? `“${transcript}”` : "";
  $("orders").replaceChildren(...result.orders.map((o) => el("li", o.description)));
  $("errors").replaceChildren(...result.errors.map((e) => {
    const item = el("li", `${e.text || "(empty)"}: ${e.reason}`);
    return item;
  }));
  $("send").disabled = result.orders.length === 0;
}

function orderLine(record, index) {
  const item = el("li", `${record.order.description} `);
  const cancel = el("button", "cancel", "small");
  cancel.onclick = () => api("/api/cancel", { order_id: record.id }).catch((e) => setStatus(e.message));
  item.append(cancel);
  if (index > 0) {
    const up = el("button", "↑", "small");
    up.title = "run earlier";
    up.onclick = () => api("/api/reorder", { order_id: record.id, position: index - 1 })
      .catch((e) => setStatus(e.message));
    item.append(up);
  }
  return item;
}

function showState(state) {
  $("robot").textContent = state.robot;
  const badge = $("executor");
  badge.textContent = state.executor_online ? "executor online" : "executor offline";
  badge.className = "badge " + (state.executor_online ? "online" : "offline");
  const current = state.current;
  if (current) {
    const box = el("div");
    box.append(orderLine(current, 0));
    const p = current.progress;
    if (p) {
      box.append(el("div", p.text, "muted"));
      if (p.percent !== null && p.percent !== undefined) {
        const bar = el("div", undefined, "bar");
        const fill = el("div");
        fill.style.width = `${Math.max(0, Math.min(100, p.percent))}%`;
        bar.append(fill);
        box.append(bar);
      }
    }
    $("current").replaceChildren(box);
    $("current").className = "";
  } else {
    $("current").textContent = "idle";
    $("current").className = "muted";
  }
  $("queue").replaceChildren(...state.queue.map(orderLine));
  const more = state.queue_length - state.queue.length;
  if (more > 0) $("queue").append(el("li", `… and ${more} more`, "muted"));
  $("history").replaceChildren(...state.history.map((r) => {
    const row = el("tr");
    const ended = r.ended_at ? new Date(r.ended_at * 1000).toLocaleTimeString() : "";
    row.append(el("td", r.order.description), el("td", r.status, r.status),
      el("td", r.message), el("td", r.transcript, "muted"), el("td", ended, "muted"));
    return row;
  }));
}

async function listen() {
  // Server-sent events read with fetch so the token stays in a header.
  for (;;) {
    try {
      const response = await fetch("/api/events", { headers: { Authorization: `Bearer ${token}` } });
      if (response.status === 401) { showLogin("wrong or missing token"); return; }
      const reader = response.body.getReader();
      const decoder = new TextDecoder();
      let buffer = "";
      setStatus("");
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += decoder.decode(value, { stream: true });
        let end;
        while ((end = buffer.indexOf("\n\n")) >= 0) {
          const frame = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          if (!frame.startsWith("data: ")) continue;
          const message = JSON.parse(frame.slice(6));
          if (message.type === "stateupdate") showState(message.state);
          if (message.type === "proposal") showProposal(message.transcript, message);
        }
      }
    } catch (error) {
      setStatus(`connection lost: ${error.message}; retrying`);
    }
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

function showLogin(why) {
  $("panel").hidden = true;
  $("login").hidden = false;
  setStatus(why || "");
}

function start() {
  $("login").hidden = true;
  $("panel").hidden = false;
  listen();
}

$("save-token").onclick = () => {
  token = $("token").value.trim();
  localStorage.setItem("voicectl-token", token);
  start();
};

$("command").onsubmit = async (event) => {
  event.preventDefault();
  const text = $("text").value;
  try {
    showProposal(text, await api("/api/parse", { text }));
    setStatus("");
  } catch (error) { setStatus(error.message); }
};

$("send").onclick = async () => {
  if (!proposal) return;
  $("send").disabled = true;
  try {
    await api("/api/submit", { orders: proposal.orders, transcript: proposal.transcript });
    $("text").value = "";
    showProposal("", { orders: [], errors: [] });
    setStatus("");
  } catch (error) { setStatus(error.message); $("send").disabled = false; }
};

$("cancel-all").onclick = () => api("/api/cancel_all", {}).catch((e) => setStatus(e.message));
$("stop").onclick = () => api("/api/stop", {}).catch((e) => setStatus(e.message));

if (token) start(); else showLogin();
