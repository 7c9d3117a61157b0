// The diagnosis on the page: its job followed, its report shown (effects, their parameters and
// figures, what is left unexplained, how far off its training poses it holds, the outliers).
// Uses app.js's globals ($, api, say, state).

/** Make a diagnosis job the page's: its block emptied, then followed to its report. */
function useDiagnosis(d) {
  state.diag = d.id;
  $("diagnosis").hidden = false;
  $("d-effects").replaceChildren();
  $("d-unexplained").hidden = $("d-outliers").hidden = $("d-doubt").hidden = true;
  $("d-extrapolation").hidden = $("d-verdict").hidden = true;
  $("d-figures").replaceChildren();
  $("d-links").replaceChildren();
  watchJob(d, followDiagnosis);
}

/** The diagnosis job's state as its events (live.js) tell it; its report once done. */
async function followDiagnosis(d) {
  if (d.id !== state.diag) return;
  $("d-state").textContent = `diagnosis job ${d.id}: ${d.state}`
    + (d.state === "running" ? ` (${Math.round(d.progress * 100)} %)` : "")
    + (d.reason ? `: ${d.reason}` : "");
  try {
    if (d.state === "done") await showDiagnosis(d);
  } catch (e) { say(e); }
}

const UNITS = [["_ppm_per_c", "ppm/°C"], ["_ppm_per_hour", "ppm/h"], ["_deg", "deg"],
               ["_ppm", "ppm"], ["_mm", "mm"], ["_s", "s"]];

/** An effect's parameters as text, each ± its standard error where `errors` gives one, units
 * taken from the key suffixes of the report; each value after `sign` ("± " for standard errors). */
function formatParameters(params, errors = null, sign = "") {
  const pm = (v, se) => fmt(v) + (typeof se === "number" ? ` ± ${fmt(se)}` : "");
  return Object.entries(params || {}).map(([key, v]) => {
    const [suffix, unit] = UNITS.find(([sfx]) => key.endsWith(sfx)) || ["", ""];
    const label = (suffix ? key.slice(0, -suffix.length) : key).replaceAll("_", " ");
    const se = (errors || {})[key];
    const value = Array.isArray(v) ? `(${v.map((x, i) => pm(x, Array.isArray(se) ? se[i] : null)).join(", ")})`
      : typeof v === "number" ? (Number.isInteger(v) ? String(v) : pm(v, se)) : String(v);
    return `${label} ${sign}${value}${unit ? ` ${unit}` : ""}`;
  }).join("; ");
}

/** Optional per-effect keys of the report: [key, column heading, text of its value]. */
const EFFECT_EXTRAS = [
  ["uncertainty", "standard error", (v) => formatParameters(v, null, "± ")],
  ["holdout_gain_interval_mm", "held-out gain interval / mm",
   (v) => `${fmt(v[0])} to ${fmt(v[1])}`],
  ["alternatives", "could not be told apart from",
   (v) => (v.length ? v.map((a) => `${a.label || effectLabel(a)} (held-out RMS `
     + `${fmt(a.holdout_rmse_mm ?? a.holdout_rmse_after_mm)} mm)`).join("; ") : "none")],
];

/** A small table: headings, then rows of cell texts. */
function makeTable(id, headings, rows) {
  const table = document.createElement("table");
  table.id = id;
  const head = table.createTHead().insertRow();
  // an empty heading (the open buttons' column, a row's name) still has words for screen readers
  headings.forEach((h) => {
    const th = head.appendChild(document.createElement("th"));
    if (h) th.textContent = h;
    else th.appendChild(Object.assign(document.createElement("span"), { className: "sr-only", textContent: "row" }));
  });
  const body = table.createTBody();
  rows.forEach((row) => {
    const tr = body.insertRow();
    row.forEach((v) => { tr.insertCell().textContent = v; });
  });
  return table;
}

/** The extended model's verdict: not fit to deploy with each reason, or deployable with the
 * accuracy to expect; the warnings either way. */
function showDiagnosisVerdict(v) {
  const box = $("d-verdict");
  box.hidden = !v;
  if (!v) return box.replaceChildren();
  const parts = [];
  if (!v.deployable) {
    const warn = Object.assign(document.createElement("div"), { id: "d-unfit" });
    warn.setAttribute("role", "alert");
    const list = document.createElement("ul");
    (v.reasons || []).forEach((r) => { list.appendChild(document.createElement("li")).textContent = r; });
    warn.append(heading("Extended model not fit to deploy", "strong"), list);
    parts.push(warn);
    if (v.summary) {
      parts.push(Object.assign(document.createElement("p"), { id: "d-expected", className: "muted",
        textContent: `${v.summary[0].toUpperCase()}${v.summary.slice(1)}.` }));
    }
  } else {
    parts.push(Object.assign(document.createElement("p"), { id: "d-fit-ok", className: "muted",
      textContent: `Extended model deployable: ${v.summary || `expected accuracy `
        + `${fmt(v.holdout_rms_mm)} mm RMS held out`}.` }));
  }
  if ((v.warnings || []).length) {
    const list = Object.assign(document.createElement("ul"), { id: "d-warnings" });
    v.warnings.forEach((w) => { list.appendChild(document.createElement("li")).textContent = w; });
    parts.push(list);
  }
  box.replaceChildren(...parts);
}

/** What the final model leaves unexplained: how much, and the covariates it follows most. */
function showUnexplained(u) {
  const box = $("d-unexplained");
  box.hidden = !u;
  if (!u) return box.replaceChildren();
  const title = Object.assign(document.createElement("h3"), { textContent: "Unexplained" });
  const summary = Object.assign(document.createElement("p"), { id: "u-summary", textContent: u.reading });
  const table = makeTable("unexplained-table", ["covariate", "strength", "through", "reading"],
    u.covariates.map((c) => [c.name, fmt(c.strength), c.channel ?? "-", c.reading]));
  [...table.tBodies[0].rows].forEach((tr, i) => {
    const bar = document.createElement("meter");  // strength 0..1 at a glance
    Object.assign(bar, { min: 0, max: 1, value: u.covariates[i].strength });
    tr.cells[1].prepend(bar, " ");
    tr.cells[3].className = "evidence";
  });
  const parts = [title, summary, table];
  if (u.per_pose_reading) {
    parts.push(Object.assign(document.createElement("p"), {
      id: "u-per-pose", className: u.per_pose_dominates ? "warn" : "muted",
      textContent: `Per pose: ${u.per_pose_reading}` }));
  }
  box.replaceChildren(...parts);
}

/** How far off its training poses the final model was tested (each fold trained on one side of a
 * joint or configuration, tested on the other), the effects refused there, and the joint ranges
 * the data covers: where the model may be trusted. The `diagnose` summary says the same. */
function showExtrapolation(x) {
  const box = $("d-extrapolation");
  box.hidden = !x;
  if (!x) return box.replaceChildren();
  const deg = (v) => v.toFixed(1);
  const parts = [Object.assign(document.createElement("h3"),
    { textContent: "Off the training poses" })];
  let said = "Not tested off its training poses: too few poses to split.";
  if (x.folds.length) {
    const far = x.folds.reduce((a, f) => (f.beyond_training_deg > a.beyond_training_deg ? f : a));
    const worse = x.folds.filter((f) => f.worse_only_in_geometric_span).map((f) => f.test);
    said = `Tested off its training poses on ${x.folds.length} folds (trained on one side, tested `
      + `on the other), reaching up to ${deg(far.beyond_training_deg)} deg beyond them `
      + `(${far.test}): ` + (worse.length ? `above geometry only inside geometry's own span on `
      + `${worse.join(", ")}.` : "no worse than geometry on any.");
  }
  parts.push(Object.assign(document.createElement("p"), { id: "x-summary", textContent: said }));
  if (x.folds.length) {
    parts.push(makeTable("extrapolation-table",
      ["tested on", "poses", "beyond training / deg", "geometric / mm", "final model / mm"],
      x.folds.map((f) => [f.test, String(f.test_poses), deg(f.beyond_training_deg),
                          fmt(f.geometric_rmse_mm), fmt(f.final_rmse_mm)])));
  }
  if (x.refused.length) {
    const list = Object.assign(document.createElement("ul"), { id: "x-refused", className: "warn" });
    x.refused.forEach((r) => {
      list.appendChild(document.createElement("li")).textContent =
        `Refused ${r.label}: ${r.reason || "worse than geometry on " + r.worse_on.join("; ")}`;
    });
    parts.push(list);
  }
  parts.push(Object.assign(document.createElement("p"), { id: "x-trusted",
    textContent: "Trusted within the joint ranges measured (deg); beyond them the model "
      + "extrapolates:" }));
  parts.push(makeTable("trusted-table", ["joint", "from / deg", "to / deg"],
    x.joint_range_deg.map(([lo, hi], j) => [`q${j + 1}`, deg(lo), deg(hi)])));
  box.replaceChildren(...parts);
}

/** Readings excluded as gross errors, by pose and target. */
function showOutliers(list) {
  const box = $("d-outliers");
  box.hidden = !list || !list.length;
  if (box.hidden) return box.replaceChildren();
  box.replaceChildren(
    Object.assign(document.createElement("h3"),
      { textContent: `Readings excluded as gross errors (${list.length})` }),
    makeTable("outliers-table", ["pose", "target", "residual / mm"],
      list.map((o) => [String(o.pose), o.target, fmt(o.residual_mm)])));
  // each pose a button to it in the 3-D viewer, where the shown recording has it (cell3d.js)
  box.querySelectorAll("#outliers-table tbody tr").forEach((tr, i) => {
    tr.cells[0].dataset.poseLabel = String(list[i].pose);
  });
  linkPoses();
}

/** The name a person reads for an effect of the report: type, joint, harmonic, time. */
function effectLabel(e) {
  return e.name + (e.joint !== undefined && e.joint !== null ? `, joint ${e.joint}` : "")
    + (e.harmonic ? `, harmonic ${e.harmonic}` : "")
    + (e.at_s !== undefined && e.at_s !== null ? ` at ${e.at_s.toFixed(0)} s` : "");
}

/** Whether this figure file shows this effect: the report names each effect's figure. */
function figureOf(e, file) {
  return e.figure === file;
}

async function showDiagnosis(d) {
  const [report, figures] = await Promise.all([api("GET", d.report_url.slice(4)),
                                               api("GET", d.figures_url.slice(4))]);
  if (d.id !== state.diag) return;
  // the extended model's own verdict (the job's, as the API gives it): what its download and
  // exports act on, said here as the calibration's is under Results
  const v = d.validation !== undefined ? d.validation : (await api("GET", `/jobs/${d.id}`)).validation;
  if (d.id !== state.diag) return;
  showDiagnosisVerdict(v);
  const b = report.baseline, f = report.final;
  $("d-state").textContent = `geometric model: held-out RMS ${fmt(b.holdout_rmse_mm)} mm; `
    + `${f.model}: ${fmt(f.holdout_rmse_mm)} mm (noise floor `
    + `${report.noise_floor_mm ? `${fmt(report.noise_floor_mm)} mm` : "unknown"}`
    + `${report.noise_floor_source ? `, from the ${report.noise_floor_source}` : ""})`;
  if (!report.effects.length) {
    $("d-effects").innerHTML = '<p id="d-none">No effect beyond geometry pays off on held-out poses.</p>';
  } else {
    const table = document.createElement("table");
    table.id = "effects-table";
    const head = table.createTHead().insertRow();
    ["effect", "joint", "evidence", "parameters", "held-out RMS before / mm", "after / mm"]
      .forEach((h) => { head.appendChild(document.createElement("th")).textContent = h; });
    const body = table.createTBody();
    // Optional columns (FORMATS.md section 5), shown only when some effect carries them.
    const extra = EFFECT_EXTRAS.filter(([key]) => report.effects.some((e) => e[key] !== undefined));
    extra.forEach(([, h]) => { head.appendChild(document.createElement("th")).textContent = h; });
    report.effects.forEach((e, i) => {
      const tr = body.insertRow();
      const name = `Effect ${i + 1}: ${e.name}` + (e.harmonic ? ` (harmonic ${e.harmonic})` : "")
        + (e.at_s !== undefined && e.at_s !== null ? ` at ${e.at_s.toFixed(0)} s` : "");
      [name, e.joint ?? "-", e.evidence, formatParameters(e.parameters, e.uncertainty),
       fmt(e.holdout_rmse_before_mm), fmt(e.holdout_rmse_after_mm),
       ...extra.map(([key, , show]) => (e[key] === undefined ? "-" : show(e[key])))]
        .forEach((v) => { tr.insertCell().textContent = v; });
      tr.cells[2].className = "evidence";
      tr.cells[3].className = "parameters";
      extra.forEach(([key], k) => { tr.cells[6 + k].className = `extra ${key}`; });
    });
    $("d-effects").replaceChildren(table);
  }
  // a small campaign whose resamples name another cause: the cause is in doubt, said so; the
  // cause taken from the resamples in the campaign's own choice's place, said first
  const st = report.stability;
  const said = [st?.agreed, st?.half_way, ...(st?.held ?? []), st?.doubt].filter(Boolean).join(" ");
  Object.assign($("d-doubt"), { hidden: !said, textContent: said });
  showUnexplained(report.unexplained);
  showExtrapolation(report.extrapolation);
  showOutliers(report.outliers);
  // One figure per effect: its caption names the effect it shows.
  $("d-figures").replaceChildren(...figures.map((fig) => {
    const i = report.effects.findIndex((e) => figureOf(e, fig.name));
    const e = report.effects[i];
    const el = document.createElement("figure");
    const img = el.appendChild(document.createElement("img"));
    showImage(img, fig.url);
    img.alt = e ? `residuals against ${effectLabel(e)}, before and after` : fig.name;
    el.appendChild(document.createElement("figcaption")).textContent = e
      ? `Effect ${i + 1}: ${effectLabel(e)}. Residuals before and after, with what the effect `
        + `predicts (${fig.name})` : fig.name;
    return el;
  }));
  const reportLink = Object.assign(document.createElement("a"),
    { href: d.report_url, textContent: "Download report.json" });
  reportLink.setAttribute("download", `job-${d.id}.report.json`);
  const modelLink = Object.assign(document.createElement("a"),
    { href: d.model_url, textContent: "Download extended model.json" });
  modelLink.setAttribute("download", `job-${d.id}.model.json`);
  $("d-links").replaceChildren(reportLink, " · ", modelLink);
}
