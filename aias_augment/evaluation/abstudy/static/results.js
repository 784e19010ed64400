// aias-abstudy results page: fetches /api/results and fills the tables (plain JS, no dependencies).
"use strict";

const $ = (id) => document.getElementById(id);
const pct = (x) => (x === null || x === undefined ? "–" : (100 * x).toFixed(1) + " %");

function cell(tr, text, cls) {
  const td = document.createElement("td");
  td.textContent = text;
  if (cls) td.className = cls;
  tr.appendChild(td);
  return td;
}

function bar(td, r) {
  const box = document.createElement("div");
  box.className = "scorebar";
  if (r.score !== null) {
    const band = document.createElement("div");
    band.className = "band";
    band.style.left = 100 * r.ci_low + "%";
    band.style.width = 100 * (r.ci_high - r.ci_low) + "%";
    const fill = document.createElement("div");
    fill.className = "fill";
    fill.style.width = 100 * r.score + "%";
    box.append(band, fill);
  }
  const half = document.createElement("div");
  half.className = "half";
  box.appendChild(half);
  td.appendChild(box);
}

async function load() {
  const resp = await fetch("/api/results", { credentials: "same-origin" });
  if (!resp.ok) {
    $("status").textContent = "Could not load the results: HTTP " + resp.status;
    return;
  }
  const rep = await resp.json();
  $("title").textContent = "Results: " + rep.title;
  $("summary").textContent = `${rep.pairs} pairs (${rep.kind}s), ${rep.raters.length} raters, ${rep.votes} votes; ` +
    `baseline: ${rep.baseline}.`;
  const tb = $("comparisons").querySelector("tbody");
  tb.replaceChildren();
  for (const r of rep.comparisons) {
    const tr = document.createElement("tr");
    cell(tr, r.method);
    cell(tr, r.opponent);
    cell(tr, r.votes, "num");
    cell(tr, r.wins, "num");
    cell(tr, r.losses, "num");
    cell(tr, r.ties, "num");
    cell(tr, pct(r.score), "num strong");
    cell(tr, r.ci_low === null ? "–" : `${(100 * r.ci_low).toFixed(1)} – ${(100 * r.ci_high).toFixed(1)} %`, "num");
    cell(tr, r.p_value === null ? "–" : r.p_value.toPrecision(3), "num");
    bar(cell(tr, "", "barcol"), r);
    tb.appendChild(tr);
  }
  const rb = $("raters").querySelector("tbody");
  rb.replaceChildren();
  for (const r of rep.raters) {
    const tr = document.createElement("tr");
    cell(tr, r.rater);
    cell(tr, r.votes, "num");
    cell(tr, r.ties, "num");
    cell(tr, pct(r.left_share), "num");
    cell(tr, pct(r.agreement), "num");
    cell(tr, r.compared, "num");
    cell(tr, r.median_ms === null ? "–" : (r.median_ms / 1000).toFixed(1), "num");
    rb.appendChild(tr);
  }
  const pa = rep.pairwise_agreement;
  $("pairwise").textContent = pa.combinations
    ? `Pairwise agreement: ${pct(pa.rate)} of ${pa.combinations} (pair, two raters) combinations.`
    : "Pairwise agreement: needs two raters on the same pair.";
  document.body.dataset.state = "ready";
}

load();
