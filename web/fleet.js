// Fleet: the arms of one robot model (GET /api/fleet/{model}), the flagged ones highlighted,
// and one parameter across the arms beside the fleet's median and limits.
"use strict";

const fleet = { models: [], view: null };
const SVG = "http://www.w3.org/2000/svg";

/** GET /api/fleet into the model choice, then the chosen model's view. */
async function refreshFleet() {
  try {
    fleet.models = await api("GET", "/fleet");
    const sel = $("fleet-model");
    const kept = sel.value;
    sel.replaceChildren(...fleet.models.map((m) => new Option(
      `${m.robot_model} (${m.arms} arms)`, m.robot_model)));
    if (kept && fleet.models.some((m) => m.robot_model === kept)) sel.value = kept;
    if (!fleet.models.length) {
      $("fleet-summary").textContent = "no arm named yet: import campaigns with their arm";
      return;
    }
    await showFleet(sel.value);
  } catch (e) { say(e); }
}

async function showFleet(model) {
  fleet.view = await api("GET", `/fleet/${encodeURIComponent(model)}`);
  const v = fleet.view;
  const off = v.arms.filter((a) => a.flagged || a.jumped).map((a) => a.arm);
  $("fleet-summary").textContent = `${v.arms.length} arms; ` +
    (off.length ? `flagged: ${off.join(", ")}` : "none flagged") +
    ` (limits set for ${Math.round(v.family_rate * 100)}% false alarms a fleet)`;
  const rows = v.arms.map((a) => {
    const far = a.parameters.reduce((b, p) => (Math.abs(p.z ?? 0) > Math.abs(b?.z ?? -1) ? p : b), null);
    const jumps = a.parameters.filter((p) => p.jump_z !== null);
    const big = jumps.reduce((b, p) => (Math.abs(p.jump_z) > Math.abs(b?.jump_z ?? -1) ? p : b), null);
    return [a.arm, String(a.calibrations), String(a.job_id), far ? far.parameter : "-",
      far ? fmt(far.z) : "-", big ? `${big.parameter} ${fmt(big.jump)}` : "-",
      big ? fmt(big.jump_z) : "-",
      [a.flagged ? "off the fleet" : "", a.jumped ? "jumped" : ""].filter(Boolean).join(", ") || "ok"];
  });
  const table = makeTable("fleet-table",
    ["arm", "calibrations", "job", "furthest", "z", "largest jump", "jump z", ""], rows);
  [...table.tBodies[0].rows].forEach((tr, i) => {
    if (v.arms[i].flagged || v.arms[i].jumped) tr.className = "flagged";
  });
  $("fleet-arms").replaceChildren(table);
  const sel = $("fleet-parameter");
  const kept = sel.value;
  sel.replaceChildren(...v.parameters.map((p) => new Option(`${p.parameter} (${p.unit})`, p.parameter)));
  const worst = v.arms.find((a) => a.flagged)?.worst;
  sel.value = v.parameters.some((p) => p.parameter === kept) ? kept : (worst || sel.value);
  plotParameter(sel.value);
}

/** One parameter across the arms: each arm's value with +-2 standard errors, the fleet's median
 * and its limits (median +- limit x spread). */
function plotParameter(name) {
  const v = fleet.view;
  const box = $("fleet-plot");
  const p = v && v.parameters.find((q) => q.parameter === name);
  if (!p) return box.replaceChildren();
  const pts = v.arms.map((a) => [a, a.parameters.find((q) => q.parameter === name)])
    .filter(([, q]) => q);
  const band = p.limit === null ? 0 : p.limit * p.spread;
  const values = pts.flatMap(([, q]) => [q.value - 2 * (q.standard_error || 0), q.value + 2 * (q.standard_error || 0)]);
  const lo = Math.min(...values, p.centre - band), hi = Math.max(...values, p.centre + band);
  const W = 640, H = 240, L = 70, B = 40;
  const x = (i) => L + (i + 0.5) * (W - L - 10) / pts.length;
  const y = (val) => H - B - (val - lo) / ((hi - lo) || 1) * (H - B - 20);
  const svg = document.createElementNS(SVG, "svg");
  svg.setAttribute("viewBox", `0 0 ${W} ${H}`);
  svg.setAttribute("id", "fleet-svg");
  const add = (tag, attrs, text) => {
    const e = document.createElementNS(SVG, tag);
    Object.entries(attrs).forEach(([k, val]) => e.setAttribute(k, val));
    if (text !== undefined) e.textContent = text;
    svg.appendChild(e);
  };
  const hline = (val, color, label) => {
    add("line", { x1: L, x2: W - 10, y1: y(val), y2: y(val), stroke: color, "stroke-dasharray": "4 3" });
    add("text", { x: 2, y: y(val) + 4, "font-size": 11, fill: color }, label);
  };
  hline(p.centre, "#555", "median");
  if (band) { hline(p.centre + band, "#a54e57", "limit"); hline(p.centre - band, "#a54e57", "limit"); }
  pts.forEach(([a, q], i) => {
    const se2 = 2 * (q.standard_error || 0);
    add("line", { x1: x(i), x2: x(i), y1: y(q.value - se2), y2: y(q.value + se2), stroke: "#333" });
    add("circle", { cx: x(i), cy: y(q.value), r: 4, fill: q.flagged ? "#a54e57" : "#2a6fb0" });
    add("text", { x: x(i), y: H - B + 16, "font-size": 10, "text-anchor": "middle" }, a.arm);
  });
  add("text", { x: L, y: 12, "font-size": 12 }, `${name} / ${p.unit}: median ${fmt(p.centre)}, spread ${fmt(p.spread)}`);
  box.replaceChildren(svg);
}

$("fleet-model").addEventListener("change", (e) => showFleet(e.target.value).catch((x) => say(x)));
$("fleet-parameter").addEventListener("change", (e) => plotParameter(e.target.value));
$("fleet-refresh").addEventListener("click", refreshFleet);
