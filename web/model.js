// robocal page, the shown model: its validation (held-out RMS the headline, "not fit to deploy"
// with the reasons), its identified parameters (GET /api/models/{id}/parameters), how to open
// its recording, and the exports' explicit "export anyway" (force=true). Uses app.js's globals
// ($, api, fmt, state, postDownload); app.js calls showModel(job) once a job's results show.
"use strict";

// A joint table's columns: the kinds of a joint's parameters, in the convention's order.
const JOINT_KINDS = ["theta", "d", "a", "alpha", "beta"];
const BASE_KINDS = ["x", "y", "z", "rz", "ry", "rx"];
const SMR_KINDS = ["x", "y", "z"];

/** A value ± its standard error as the page writes numbers (fmt); "fixed" if held fixed. */
function plusMinus(value, row) {
  if (row.status === "held fixed") return "fixed";
  const se = row.standard_error;
  if (se === null || se === undefined || !Number.isFinite(se)) return fmt(value);
  // both to the standard error's second significant digit, as the command line prints them
  // (server/cli/tables.py plus_minus): 0.01234 ± 0.00089, never 1.234e-2 ± 8.887e-4
  const places = se > 0 ? Math.min(8, Math.max(0, 1 - Math.floor(Math.log10(se)))) : 4;
  return `${value.toFixed(places)} ± ${se.toFixed(places)}`;
}

/** A group's parameters as a table: one line per `key` (joint, SMR), one column per kind, each
 * cell value(row) ± its standard error; a held-fixed cell says why in its tooltip. */
function groupTable(id, first, rows, key, kinds, value, why) {
  const lines = new Map();
  rows.forEach((r) => {
    if (!lines.has(r[key])) lines.set(r[key], {});
    lines.get(r[key])[r.kind] = r;
  });
  const unit = (kind) => rows.find((r) => r.kind === kind).unit;
  const table = makeTable(id, [first, ...kinds.map((k) => `${k} / ${unit(k)}`)],
    [...lines].map(([k, byKind]) => [String(k), ...kinds.map((kind) => {
      const r = byKind[kind];
      return r ? plusMinus(value(r), r) : "-";
    })]));
  [...lines.values()].forEach((byKind, i) => kinds.forEach((kind, k) => {
    const r = byKind[kind];
    if (r && r.status === "held fixed") {
      const td = table.tBodies[0].rows[i].cells[k + 1];
      td.className = "fixed";
      td.title = `${r.parameter} held fixed: ${why[r.parameter] || ""}`;
    } else if (r && r.status === "shrunk toward nominal") {
      const td = table.tBodies[0].rows[i].cells[k + 1];
      td.className = "shrunk";
      td.title = `${r.parameter} shrunk toward nominal: ${why[r.parameter] || ""}`;
    }
  }));
  return table;
}

function heading(text, tag = "h4") {
  return Object.assign(document.createElement(tag), { textContent: text });
}

/** A box that scrolls sideways on its own when its table is wider than the screen. */
function scroller(table) {
  const box = document.createElement("div");
  box.className = "m-scroll";
  box.appendChild(table);
  return box;
}

/** The identified-parameter tables of a model: joints, base, SMRs, held fixed, shrunk toward
 * nominal, correlations. */
function renderParameters(p) {
  const id = p.identified;
  const rows = id.rows;
  const shrunk = id.shrunk || [];  // models written before shrinkage have none
  const share = (s) => `${Math.round(100 * s.data_share)}%`;
  const why = Object.fromEntries([...id.fixed.map((f) => [f.parameter, f.why]),
    ...shrunk.map((s) => [s.parameter, `${share(s)} from the data; ${s.why}`])]);
  const group = (g) => rows.filter((r) => r.group === g);
  // The kinds a group has: the usual ones in their order, then any other the convention has.
  const present = (list, kinds) => [...new Set([...kinds, ...list.map((r) => r.kind)])]
    .filter((k) => list.some((r) => r.kind === k));
  const joints = group("joint"), base = group("base"), smrs = group("smr");
  const parts = [heading(`Identified parameters (${p.method || "model"}, ${id.convention})`, "h3"),
    Object.assign(document.createElement("p"), {
      id: "m-condition",
      textContent: `Condition number ${fmt(id.condition_number)}; standard errors: ${id.estimator}.`,
    })];
  parts.push(heading("Joints: change from nominal ± standard error"));
  parts.push(scroller(groupTable("m-joints", "joint", joints, "joint",
    present(joints, JOINT_KINDS), (r) => r.change, why)));
  if (base.length) {
    // The base has no nominal: its calibrated pose in the tracker frame.
    parts.push(heading("Base in the tracker frame: calibrated ± standard error"));
    parts.push(scroller(groupTable("m-base", "", base, "group", present(base, BASE_KINDS),
      (r) => r.calibrated, why)));
  }
  if (smrs.length) {
    parts.push(heading("SMRs in the flange frame: change from nominal ± standard error"));
    parts.push(scroller(groupTable("m-smrs", "SMR", smrs, "target", present(smrs, SMR_KINDS),
      (r) => (r.change === null ? r.calibrated : r.change), why)));
  }
  parts.push(heading(`Held fixed (${id.fixed.length})`));
  parts.push(id.fixed.length
    ? scroller(makeTable("m-fixed", ["parameter", "why"], id.fixed.map((f) => [f.parameter, f.why])))
    : Object.assign(document.createElement("p"), { className: "muted", textContent: "none" }));
  if (shrunk.length) {
    parts.push(heading(`Shrunk toward nominal (${shrunk.length})`));
    if (id.prior) parts.push(Object.assign(document.createElement("p"), { className: "muted",
      textContent: `Prior: ${id.prior}.` }));
    parts.push(scroller(makeTable("m-shrunk", ["parameter", "from the data", "why"],
      shrunk.map((s) => [s.parameter, share(s), s.why]))));
  }
  if (id.correlations.length) {
    parts.push(heading("Strongest correlations"));
    parts.push(scroller(makeTable("m-correlations", ["parameter", "with", "r"],
      id.correlations.map((c) => [c.a, c.b, c.r.toFixed(3)]))));
  }
  $("m-parameters").replaceChildren(...parts);
  $("m-parameters").hidden = false;
}

/** The validation headline: held-out RMS, the fit RMS beside it; a warning when not deployable.
 * The job's summary has no noise floor nor hold-out method; the parameters' whole block has. */
function renderValidation(v) {
  const box = $("m-validation");
  box.hidden = !v;
  const unfit = !!v && !v.deployable;
  $("m-unfit-exports").hidden = !unfit;
  ["t-joints", "t-rapid", "x-params", "x-urdf"].forEach((b) => {
    $(b).classList.toggle("unfit", unfit);
    $(b).title = unfit ? "not fit to deploy: refused unless \"export anyway\" is ticked" : "";
  });
  if (!v) return box.replaceChildren();
  const h = v.held_out;  // a separate held-out campaign's figure comes first, when there is one
  const headline = Object.assign(document.createElement("p"), { id: "m-headline" });
  headline.append(
    Object.assign(document.createElement("span"), { className: "m-big",
      textContent: h ? `Held-out ${h.file || `campaign ${h.campaign_id}`} RMS ${fmt(h.rms_mm)} mm`
        : `Held-out RMS ${fmt(v.holdout_rms_mm)} mm` }),
    Object.assign(document.createElement("span"), { id: "m-fit", className: "muted",
      textContent: (h ? ` (${h.poses} poses, max ${fmt(h.max_mm)} mm, nominal model`
          + ` ${fmt(h.nominal_rms_mm)} mm) · leave-one-pose-out RMS ${fmt(v.holdout_rms_mm)} mm`
        : "")
        + ` · fit RMS ${fmt(v.fit_rms_mm)} mm`
        + (v.nominal_rms_mm != null ? ` (nominal model ${fmt(v.nominal_rms_mm)} mm)` : "")
        + (v.noise_floor_mm ? ` · noise floor ${fmt(v.noise_floor_mm)} mm` : "")
        + (v.noise_floor_mm && v.noise_floor_source ? ` (from the ${v.noise_floor_source})` : "")
        + (v.holdout && !h ? ` (held out: ${v.holdout})` : "") }));
  const parts = [headline];
  if (h && h.warning) {
    parts.push(Object.assign(document.createElement("p"), { id: "m-held-warning",
      className: "error", role: "alert", textContent: `Held-out campaign: ${h.warning}` }));
  }
  if (unfit) {
    const warn = document.createElement("div");
    warn.id = "m-unfit";
    warn.setAttribute("role", "alert");
    const list = document.createElement("ul");
    v.reasons.forEach((r) => { list.appendChild(document.createElement("li")).textContent = r; });
    warn.append(heading("Not fit to deploy", "strong"), list);
    parts.push(warn);
  } else {
    // the accuracy to expect, against the tolerance when one was given: never a bare "fit to
    // deploy", which a user would read as "accurate enough for anything"
    parts.push(Object.assign(document.createElement("p"), { id: "m-fit-ok", className: "muted",
      textContent: `Deployable: ${v.summary || `expected accuracy ${fmt(v.holdout_rms_mm)} mm `
        + "RMS held out"}.` }));
  }
  if (unfit && v.summary) {
    parts.push(Object.assign(document.createElement("p"), { id: "m-expected", className: "muted",
      textContent: `${v.summary[0].toUpperCase()}${v.summary.slice(1)}.` }));
  }
  if ((v.warnings || []).length) {  // deployable or not: what deserves a look before use
    const list = Object.assign(document.createElement("ul"), { id: "m-warnings" });
    v.warnings.forEach((w) => { list.appendChild(document.createElement("li")).textContent = w; });
    parts.push(list);
  }
  box.replaceChildren(...parts);
}

/** How to open the job's recording: the rerun viewer on the downloaded file. */
function renderRecordingHint(j) {
  $("recording-open").hidden = !j.recording_url;
  $("recording-command").textContent = `rerun job-${j.id}.rrd`;
}

/** The shown job's model: validation, recording hint, then its parameter tables. */
async function showModel(j) {
  $("m-force").checked = false;  // each model is exported anyway only on its own say-so
  renderValidation(j.validation && { ...j.validation, held_out: j.holdout });
  renderRecordingHint(j);
  showChecks(j.id);  // web/checks.js: the latest check's verdict, the history and its chart
  $("m-parameters").hidden = true;
  $("m-parameters").replaceChildren();
  if (!j.parameters_url) return;
  try {
    const p = await api("GET", j.parameters_url.slice(4));
    if (j.id !== state.job) return;  // another job was shown meanwhile
    if (p.validation) renderValidation(p.validation);
    renderParameters(p);
  } catch (e) { say(e); }
}

// The exports (app.js postDownload) carry force=true only when "export anyway" is ticked: a model
// not fit to deploy is otherwise refused by the service (409 with its reasons).
const postDownloadAsIs = postDownload;
postDownload = function (path, body, filename) {  // app.js's buttons call it by this name
  const forced = $("m-force").checked ? `${path}${path.includes("?") ? "&" : "?"}force=true` : path;
  return postDownloadAsIs(forced, body, filename);
};
