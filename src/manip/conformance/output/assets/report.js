// manip-conform HTML report: sorting and filtering of the case table, copy buttons, opening the case a
// link points at.  Inlined into the page; reads only the page's own attributes.  The query string can
// preset the filter, and the filter is kept there as it changes: report.html?verdict=fail,error&q=error-string&level=MUST
(function () {
  "use strict";
  const table = document.getElementById("case-table");
  const body = table.tBodies[0];
  const rows = Array.from(body.rows);
  const search = document.getElementById("filter");
  const level = document.getElementById("level");
  const boxes = Array.from(document.querySelectorAll('input[name="verdict"]'));
  const shown = document.getElementById("shown");

  const texts = new Map();
  function searchText(row) {  // the case id and its clauses (and a broken clause it does not cite)
    if (!texts.has(row)) {
      const words = [row.cells[1].textContent, row.cells[2].textContent, row.dataset.search || ""];
      texts.set(row, words.join(" ").toLowerCase());
    }
    return texts.get(row);
  }

  function apply() {
    const words = search.value.toLowerCase().split(/\s+/).filter(Boolean);
    const verdicts = new Set(boxes.filter((b) => b.checked).map((b) => b.value));
    let count = 0;
    for (const row of rows) {
      const text = searchText(row);
      const ok = verdicts.has(row.dataset.verdict) &&
        (!level.value || row.dataset.level === level.value) &&
        words.every((w) => text.includes(w));
      row.hidden = !ok;
      if (ok) count += 1;
    }
    shown.textContent = count + " of " + rows.length + " shown";
    shown.dataset.count = String(count);
  }

  function sortBy(th) {
    const key = th.dataset.sort;
    const descending = th.getAttribute("aria-sort") === "ascending";
    for (const other of table.tHead.querySelectorAll("th")) other.removeAttribute("aria-sort");
    th.setAttribute("aria-sort", descending ? "descending" : "ascending");
    const numeric = key === "rank" || key === "duration";
    const value = (row) => (numeric ? parseFloat(row.dataset[key]) : row.dataset[key]);
    rows.sort((a, b) => {
      const x = value(a), y = value(b);
      const order = x < y ? -1 : x > y ? 1 : a.dataset.id.localeCompare(b.dataset.id);
      return descending ? -order : order;
    });
    for (const row of rows) body.appendChild(row);
  }

  function onlyVerdict(verdict) {
    for (const box of boxes) box.checked = box.value === verdict;
    apply();
    keepInUrl();
    document.getElementById("cases").scrollIntoView();
  }

  function copy(button) {
    const text = button.dataset.copy;
    const say = (word, state) => {
      button.textContent = word;
      button.classList.add(state);
      setTimeout(() => { button.textContent = "Copy"; button.classList.remove(state); }, 1500);
    };
    const done = () => say("Copied", "done");
    const fallback = () => {
      const area = document.createElement("textarea");
      area.value = text;
      document.body.appendChild(area);
      area.select();
      let copied = false;
      try { copied = document.execCommand("copy"); } catch (e) { copied = false; } finally { area.remove(); }
      // execCommand says whether it copied: a browser that refuses must not read "Copied"
      if (copied) done(); else say("Copy failed: select the text", "failed");
    };
    if (navigator.clipboard && window.isSecureContext) {
      navigator.clipboard.writeText(text).then(done, fallback);
    } else {
      fallback();
    }
  }

  function openTarget() {
    const id = decodeURIComponent(location.hash.slice(1));
    const target = id && document.getElementById(id);
    if (!target) return;
    // a case, or a packet row inside a case and maybe a fold: open every details around it
    for (let node = target; node; node = node.parentElement) {
      if (node.tagName === "DETAILS") node.open = true;
    }
    target.scrollIntoView({ block: "center" });
  }

  function keepInUrl() {
    // the filter state lives in the query string, so a reload or a shared link shows the same rows
    const params = new URLSearchParams(location.search);
    const checked = boxes.filter((b) => b.checked).map((b) => b.value);
    if (checked.length === boxes.length) params.delete("verdict"); else params.set("verdict", checked.join(","));
    if (search.value) params.set("q", search.value); else params.delete("q");
    if (level.value) params.set("level", level.value); else params.delete("level");
    const query = params.toString();
    try {
      history.replaceState(null, "", location.pathname + (query ? "?" + query : "") + location.hash);
    } catch (e) { /* a browser that refuses it on file:// keeps the page as it is */ }
  }

  for (const th of table.tHead.querySelectorAll("th[data-sort]")) th.addEventListener("click", () => sortBy(th));
  const applyAndKeep = () => { apply(); keepInUrl(); };
  search.addEventListener("input", applyAndKeep);
  level.addEventListener("change", applyAndKeep);
  for (const box of boxes) box.addEventListener("change", applyAndKeep);
  for (const card of document.querySelectorAll(".card[data-verdict]")) {
    card.addEventListener("click", () => onlyVerdict(card.dataset.verdict));
  }
  for (const button of document.querySelectorAll("button.copy")) button.addEventListener("click", () => copy(button));
  for (const link of document.querySelectorAll("a[data-filter]")) {
    link.addEventListener("click", () => { search.value = link.dataset.filter; apply(); keepInUrl(); });
  }
  window.addEventListener("hashchange", openTarget);

  const params = new URLSearchParams(location.search);
  if (params.has("verdict")) {
    const wanted = new Set(params.get("verdict").split(","));
    for (const box of boxes) box.checked = wanted.has(box.value);
  }
  if (params.has("q")) search.value = params.get("q");
  if (params.has("level")) level.value = params.get("level");
  apply();
  openTarget();
  document.documentElement.dataset.ready = "yes";
  // how long the page took to become usable: parsed to here and its script run (the browser test reads it)
  performance.mark("manip-report-ready");
  document.documentElement.dataset.readyMs = String(Math.round(performance.now()));
})();
