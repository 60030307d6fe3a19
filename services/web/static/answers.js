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

  return { proposalWords, outcomeWords, stoppedWords, spoken };
})();
