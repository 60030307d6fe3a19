// The panel's words, from the catalogue of its language (shared/words/<language>.json,
// served at /words): the page's own words, marked data-words*, and every sentence the
// scripts write (t). The page follows the browser's language (Accept-Language) unless told:
// ?lang=es in its address, or the header's language menu, which the browser remembers. A
// word the chosen catalogue lacks comes in English (the server fills them in), never as
// its key.
"use strict";

window.voicectlWords = (() => {
  const STORED = "voicectl-language";
  let language = "en";
  let entries = {};
  let offered = [];

  function use(catalogue) {
    language = catalogue.language;
    entries = catalogue.words;
    offered = catalogue.languages || [];
    document.documentElement.lang = language;
  }

  function t(key, values) {
    const text = entries[key];
    if (typeof text !== "string") return "";
    if (!values) return text;
    return text.replace(/\{(\w+)\}/g, (found, name) => (name in values ? String(values[name]) : found));
  }

  function list(key) { return Array.isArray(entries[key]) ? entries[key] : []; }

  function table(key) {
    const entry = entries[key];
    return entry && typeof entry === "object" && !Array.isArray(entry) ? entry : {};
  }

  function translate(root) {
    for (const node of root.querySelectorAll("[data-words]")) node.textContent = t(node.dataset.words);
    for (const node of root.querySelectorAll("[data-words-html]")) node.innerHTML = t(node.dataset.wordsHtml);
    for (const [attribute, name] of [["title", "wordsTitle"], ["placeholder", "wordsPlaceholder"],
      ["aria-label", "wordsLabel"]]) {
      for (const node of root.querySelectorAll(`[data-words-${attribute === "aria-label" ? "label" : attribute}]`)) {
        node.setAttribute(attribute, t(node.dataset[name]));
      }
    }
  }

  function chooser(select) {
    // The languages there are catalogues for, each in its own words; a choice is kept.
    select.replaceChildren(...offered.map(({ code, name }) => {
      const option = document.createElement("option");
      option.value = code;
      option.textContent = name;
      option.selected = code === language;
      return option;
    }));
    select.onchange = () => {
      localStorage.setItem(STORED, select.value);
      const address = new URL(location.href);
      address.searchParams.delete("lang");
      location.replace(address);
    };
  }

  async function load() {
    const told = new URLSearchParams(location.search).get("lang") || localStorage.getItem(STORED) || "";
    try {
      const response = await fetch(`/words?${new URLSearchParams({ language: told })}`);
      if (response.ok) use(await response.json());
    } catch (error) {
      console.error("the panel's words could not be loaded", error);
    }
    translate(document);
  }

  return { use, t, list, table, translate, chooser, load, get language() { return language; } };
})();
