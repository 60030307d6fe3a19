// What the panel says aloud: the same sentences as shared/answers.py, which the tests hold
// this file to (tests/test_panel_voice.py).
"use strict";

window.voicectlAnswers = (() => {
  const NOT_CAUGHT = "I did not catch that";
  const SHORT_REASON = 60;
  const UNITS = [
    [/(?<![\d.])1 m\b/g, "1 metre"],
    [/(\d) m\b/g, "$1 metres"],
    [/(?<![\d.])1 s\b/g, "1 second"],
    [/(\d) s\b/g, "$1 seconds"],
    [/(\d) ?°/g, "$1 degrees"],
  ];
  const DONE = { reach: "reached", turn: "turned", move: "moved", go: "went", wait: "waited" };

  function spoken(description) {
    return UNITS.reduce((text, [pattern, said]) => text.replace(pattern, said), description);
  }

  function doubtWords(transcript, doubt) {
    const choices = [doubt.words, ...(doubt.alternatives || [])];
    const asked = choices.length === 1 ? choices[0]
      : `${choices.slice(0, -1).join(", ")} or ${choices[choices.length - 1]}`;
    const after = transcript.split(/\s+/).filter(Boolean)
      .slice(doubt.position + doubt.words.split(/\s+/).filter(Boolean).length).slice(0, 1);
    return `${[asked, ...after].join(" ")}?`;
  }

  function proposalWords(proposal) {
    if (proposal.rejected) return NOT_CAUGHT;
    if ((proposal.doubts || []).length) {
      const asked = proposal.doubts.map((doubt) => doubtWords(proposal.transcript, doubt).slice(0, -1));
      return `${asked.join(", and ")}?`;
    }
    const orders = (proposal.orders || []).map((order) => spoken(order.description)).join(", then ");
    const missed = (proposal.errors || []).filter((problem) => problem.text)
      .map((problem) => `'${problem.text}'`).join(" and ");
    if (!orders) return NOT_CAUGHT;
    return missed ? `${orders}; I did not catch ${missed}` : orders;
  }

  function short(reason) {
    const clause = reason.split(/[;(\n]/)[0].trim().replace(/[.,:]+$/, "");
    if (clause.length <= SHORT_REASON) return clause;
    const cut = clause.slice(0, SHORT_REASON);
    return cut.includes(" ") ? cut.slice(0, cut.lastIndexOf(" ")) : cut;
  }

  function outcomeWords(record) {
    const what = spoken(record.order.description);
    const why = record.message ? `: ${short(record.message)}` : "";
    switch (record.status) {
      case "succeeded": {
        const [verb, ...rest] = what.split(" ");
        return DONE[verb] ? `${DONE[verb]} ${rest.join(" ")}`.trim() : `done: ${what}`;
      }
      case "failed": return `${what} failed${why}`;
      case "cancelled": return `${what} cancelled`;
      case "rejected": return `${what} refused${why}`;
      case "interrupted": return `${what} interrupted`;
      default: return null;
    }
  }

  function stoppedWords(stopped) {
    return stopped.confirmed ? "stopped" : "stop sent, not confirmed";
  }

  return { proposalWords, outcomeWords, stoppedWords, spoken };
})();
