// What the panel says aloud: the same sentences as shared/answers.py, in the panel's
// language (words.js), which the tests hold this file to (tests/test_panel_voice.py).
"use strict";

window.voicectlAnswers = (() => {
  const { t, table } = window.voicectlWords;
  const SHORT_REASON = 60;
  const UNITS = [
    [/(?<![\d.])1 m\b/g, "answer.metre", false],
    [/(\d+(?:\.\d+)?) m\b/g, "answer.metres", true],
    [/(?<![\d.])1 s\b/g, "answer.second", false],
    [/(\d+(?:\.\d+)?) s\b/g, "answer.seconds", true],
    [/(\d+(?:\.\d+)?) ?°/g, "answer.degrees", true],
  ];

  function spoken(description) {
    return UNITS.reduce((text, [pattern, key, counted]) =>
      text.replace(pattern, (found, n) => (counted ? t(key, { n }) : t(key))), description);
  }

  function doubtWords(transcript, doubt) {
    const choices = [doubt.words, ...(doubt.alternatives || [])];
    const asked = choices.length === 1 ? choices[0]
      : `${choices.slice(0, -1).join(", ")}${t("answer.or")}${choices[choices.length - 1]}`;
    const after = transcript.split(/\s+/).filter(Boolean)
      .slice(doubt.position + doubt.words.split(/\s+/).filter(Boolean).length).slice(0, 1);
    return `${[asked, ...after].join(" ")}?`;
  }

  function proposalWords(proposal) {
    if (proposal.rejected) return t("answer.notCaught");
    if ((proposal.doubts || []).length) {
      const asked = proposal.doubts.map((doubt) => doubtWords(proposal.transcript, doubt).slice(0, -1));
      return `${asked.join(t("answer.andAsk"))}?`;
    }
    const orders = (proposal.orders || []).map((order) => spoken(order.description)).join(t("answer.then"));
    const missed = (proposal.errors || []).filter((problem) => problem.text)
      .map((problem) => `'${problem.text}'`).join(t("answer.and"));
    if (!orders) return t("answer.notCaught");
    return missed ? t("answer.notCaughtSome", { orders, missed }) : orders;
  }

  function short(reason) {
    const clause = reason.split(/[;(\n]/)[0].trim().replace(/[.,:]+$/, "");
    if (clause.length <= SHORT_REASON) return clause;
    const cut = clause.slice(0, SHORT_REASON);
    return cut.includes(" ") ? cut.slice(0, cut.lastIndexOf(" ")) : cut;
  }

  function outcomeWords(record) {
    const what = spoken(record.order.description);
    const why = record.message ? short(record.message) : "";
    switch (record.status) {
      case "succeeded": {
        const [verb, ...rest] = what.split(" ");
        const past = table("answer.past")[verb];
        return past ? `${past} ${rest.join(" ")}`.trim() : t("answer.done", { what });
      }
      case "failed": return t(why ? "answer.failedWhy" : "answer.failed", { what, why });
      case "cancelled": return t("answer.cancelled", { what });
      case "rejected": return t(why ? "answer.refusedWhy" : "answer.refused", { what, why });
      case "interrupted": return t("answer.interrupted", { what });
      default: return null;
    }
  }

  function stoppedWords(stopped) {
    return t(stopped.confirmed ? "answer.stopped" : "answer.stopUnconfirmed");
  }

  // --- questions about the queue, from the state (shared/answers.py's question_words) ------

  const QUEUE_LABEL = "queue";
  const AT_PLACE = 0.5;
  const SAME_PLACE = 0.01;
  const DOING = {
    reach: "going to", go: "going", turn: "turning", rotate: "turning",
    move: "moving", drive: "driving", wait: "waiting", take: "taking",
  };
  const PLAIN = [
    [/^navigation unavailable/, "my navigation is not running"],
    [/^navigation ended (?:ABORTED|CANCELED)/, "navigation gave up on the way"],
    [/^navigation was cancelled on the robot/, "it was cancelled on the robot"],
    [/^navigation result lost/, "I lost touch with navigation"],
    [/^no progress for/, "I got stuck on the way"],
    [/^no odometry/, "I could not tell where I was"],
    [/^executor lost/, "my driver stopped answering"],
    [/^executor did not take it/, "my driver did not take it"],
    [/^executor unreachable/, "my driver did not answer"],
    [/restarted while it ran/, "I was restarted while doing it"],
    [/^emergency stop/, "the emergency stop ended it"],
    [/no executor serves|no executor for/, "nothing here can do that"],
    [/^busy with order/, "I was busy with another order"],
  ];

  function plainReason(message) {
    for (const [pattern, said] of PLAIN) if (pattern.test(message)) return said;
    return short(message);
  }

  function orders(count) { return `${count} order${count !== 1 ? "s" : ""}`; }

  function idle(state) {
    if (state.stopped) return "the emergency stop is on";
    if (state.queue_length && state.paused) {
      return `${orders(state.queue_length)} ${state.queue_length === 1 ? "waits" : "wait"} until you say go on`;
    }
    if (state.queue_length) return `${orders(state.queue_length)} waiting`;
    return "the queue is empty";
  }

  function placeOf(record, places) {
    const pose = record.order.target_pose;
    if (!pose || pose.frame !== "map") return null;
    return places.find((place) => Math.hypot(place.pose.x - pose.x, place.pose.y - pose.y) <= SAME_PLACE) || null;
  }

  function doingWords(record, places) {
    const place = placeOf(record, places);
    if (place) return `going to the ${place.name}`;
    const what = spoken(record.order.description);
    const [verb, ...rest] = what.split(" ");
    return DOING[verb] ? `${DOING[verb]} ${rest.join(" ")}`.trim() : `doing: ${what}`;
  }

  function metres(distance) {
    // Python's round-half-even and "%g" of one decimal, as shared/answers.py says it.
    const rounded = Math.round(Math.abs(distance) * 10) / 10;
    const shown = String(rounded);
    return shown === "1" ? "1 metre" : `${shown} metres`;
  }

  function distanceWords(record) {
    const progress = record.progress;
    if (!progress) return "";
    const given = (value) => value !== null && value !== undefined;
    if (given(progress.distance_linear)) return `${metres(progress.distance_linear)} to go`;
    if (given(progress.distance_angular)) {
      return `${Math.round((Math.abs(progress.distance_angular) * 180) / Math.PI)} degrees to turn`;
    }
    return "";
  }

  function whereWords(pose, places) {
    if (!pose) return "I do not know: the robot has not said where it is";
    if (!places.length) return `at x ${pose.x.toFixed(1)}, y ${pose.y.toFixed(1)}: no places are named`;
    const away = (place) => Math.hypot(place.pose.x - pose.x, place.pose.y - pose.y);
    const nearest = places.reduce((best, place) => (away(place) < away(best) ? place : best));
    if (away(nearest) <= AT_PLACE) return `at the ${nearest.name}`;
    return `near the ${nearest.name}, ${metres(away(nearest))} from it`;
  }

  function whyWords(state) {
    const ended = { rejected: "was refused", interrupted: "stopped", failed: "failed" };
    for (const record of state.history || []) {
      if (record.order.label === QUEUE_LABEL) continue;
      if (ended[record.status]) {
        const why = record.message ? `: ${plainReason(record.message)}` : "";
        return `${spoken(record.order.description)} ${ended[record.status]}${why}`;
      }
    }
    return "nothing has failed lately";
  }

  function questionWords(question, state, pose = null, places = []) {
    const current = state.current;
    const waiting = state.queue_length || 0;
    const queue = state.queue || [];
    switch (question) {
      case "doing": {
        if (!current) return `nothing: ${idle(state)}`;
        const far = distanceWords(current);
        const after = waiting ? `, ${waiting} more after it` : "";
        return `I am ${doingWords(current, places)}${far ? `, ${far}` : ""}${after}`;
      }
      case "going": {
        if (!current) return `nowhere: ${idle(state)}`;
        const place = placeOf(current, places);
        if (!place) return `I am ${doingWords(current, places)}`;
        const far = distanceWords(current);
        return `to the ${place.name}${far ? `, ${far}` : ""}`;
      }
      case "next":
        if (!queue.length) return "nothing next: the queue is empty";
        return `next: ${spoken(queue[0].order.description)}${waiting > 1 ? `, then ${waiting - 1} more` : ""}`;
      case "left":
        if (!current) return waiting ? `${waiting} waiting${state.paused ? " until you say go on" : ""}` : "nothing left";
        return `${waiting + 1} left: ${spoken(current.order.description)} now${waiting ? `, then ${waiting} more` : ""}`;
      case "far":
        if (!current) return `I am not going anywhere: ${idle(state)}`;
        return distanceWords(current) || "I do not know yet";
      case "where": return whereWords(pose, places);
      case "why": return whyWords(state);
      default: return NOT_CAUGHT;
    }
  }

  function endedByEdit(record) {
    // An order an edit of the queue ended: the edit's answer said so already.
    const message = record.message || "";
    return record.status === "cancelled" &&
      (message.startsWith("cancelled by “") || message.startsWith("replaced by “") || message === "undone");
  }

  return {
    proposalWords, outcomeWords, stoppedWords, spoken, questionWords, plainReason, endedByEdit,
  };
})();
