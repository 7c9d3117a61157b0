// robocal page, the shown model's quick checks (spec section 8): the latest check's verdict on the
// model (GET /api/models/{id}/health), the history as a table and a chart (GET .../checks,
// GET /api/charts/models/{id}/checks.png), a check.csv posted (POST .../checks), and a check run
// on the cell, followed to its verdict (POST .../checks/run, then its campaign). Uses
// app.js's globals ($, api, fmt, state, say, makeTable, showImage, clearImage) and history.js's
// when(); model.js calls showChecks(job id) as it shows a model.
"use strict";

// figures in mm (the caption says so); each check's reason on a line of its own below it
const CHECK_COLUMNS = ["#", "when", "file", "poses", "RMS", "max", "expected", "watch at",
  "recalibrate at", "change score", "accumulated", "verdict"];

/** The latest check's verdict on the model, or that it was never checked. */
function renderHealth(h) {
  const box = $("m-health");
  box.hidden = false;
  box.className = h.verdict ? `k-${h.verdict}` : "k-never";
  if (!h.checked) {
    box.textContent = "Never checked since calibrated: post a check.csv under \"Quick checks\".";
    return;
  }
  const badge = Object.assign(document.createElement("span"), { className: "k-badge",
    textContent: h.verdict });
  box.replaceChildren(badge, ` latest check (${h.history} of this model, ${when(h.checked_at)}): `
    + h.reason);
}

/** The model's checks as a table, newest first: a line of figures and verdict, then its reason. */
function renderChecks(hist) {
  const checks = [...hist.checks].reverse();
  if (!checks.length) {
    $("k-history").replaceChildren(Object.assign(document.createElement("p"),
      { className: "muted", textContent: "no check of this model yet" }));
    return;
  }
  const n = hist.checks.length;
  const table = makeTable("k-table", CHECK_COLUMNS, checks.map((c, i) => [String(n - i),
    when(c.checked_at), c.source, String(c.poses), fmt(c.rms_mm), fmt(c.max_mm),
    fmt(c.expected_rms_mm), fmt(c.watch_rms_mm), fmt(c.recalibrate_rms_mm),
    c.change_score.toFixed(2), c.cusum.toFixed(2), c.verdict]));
  [...table.tBodies[0].rows].forEach((tr, i) => {
    tr.className = "k-check";
    tr.cells[11].className = `k-${checks[i].verdict}`;
    const why = document.createElement("tr");
    why.className = "k-reason";
    Object.assign(why.insertCell(), { colSpan: CHECK_COLUMNS.length,
      textContent: checks[i].reason });
    tr.after(why);
  });
  const caption = table.createCaption();
  caption.textContent = "RMS, max, expected and the level's limits in mm; accumulated change: "
    + `watch above ${hist.cusum_watch.toFixed(1)}, recalibrate above `
    + `${hist.cusum_recalibrate.toFixed(1)}`;
  $("k-history").replaceChildren(table);
}

// the model whose checks were shown last: its posted check's warnings stay until another is shown
let shownChecks = null;

/** The shown model's checks: verdict, history table and chart. */
async function showChecks(jobId) {
  $("m-health").hidden = true;
  if (jobId !== shownChecks) {  // another model: the last posted check's words are not its
    $("k-warnings").replaceChildren();
    $("k-warnings").hidden = true;
    $("k-state").textContent = "";
    shownChecks = jobId;
  }
  $("k-history").replaceChildren();
  $("k-charts").hidden = true;
  clearImage($("k-chart"));
  $("k-health-url").textContent = `GET /api/models/${jobId}/health`;
  try {
    const [h, hist] = await Promise.all([api("GET", `/models/${jobId}/health`),
      api("GET", `/models/${jobId}/checks`)]);
    if (state.job !== jobId) return;  // another model was shown meanwhile
    renderHealth(h);
    renderChecks(hist);
    $("k-charts").hidden = !hist.checks.length;
    // the fragment (never sent) tells this history's chart from an earlier one still on its way
    const n = hist.checks.length;
    if (n) showImage($("k-chart"), `/api/charts/models/${jobId}/checks.png#${n}`);
  } catch (e) { say(e); }
}

$("k-post").addEventListener("click", async () => {
  const file = $("k-file").files[0];
  if (!file) { say("choose a check.csv file first"); return; }
  const job = state.job;
  $("k-state").textContent = "checking...";
  try {
    const c = await api("POST", `/models/${job}/checks?filename=${encodeURIComponent(file.name)}`,
      await file.text(), true, "text/csv");
    $("k-state").textContent = `check ${c.history}: ${c.verdict}`;
    renderCheckWarnings(c);
    if (state.job === job) await showChecks(job);
  } catch (e) { $("k-state").textContent = ""; say(e); }
});

/** What the posted check says beside its verdict (the warnings `robocal check` prints, not kept
 * in the history), and that the model itself is not fit to deploy, if so: an "ok" check of it
 * says only that the arm still matches it. */
function renderCheckWarnings(c) {
  const lines = [...(c.warnings || [])];
  if (c.deployable === false) {
    lines.push("the model itself is not fit to deploy: " + (c.not_deployable || []).join("; "));
  }
  const list = $("k-warnings");
  list.replaceChildren(...lines.map((w) => Object.assign(document.createElement("li"),
    { textContent: w })));
  list.hidden = !lines.length;
}

// How often a check run on the cell is asked for its progress (a simulated check takes seconds).
const CHECK_POLL_MS = 500;

/** One line of a check campaign's progress, or its end. */
function checkRunLine(c) {
  const poses = `${c.poses_done} of ${c.poses_total} poses`;
  if (c.run && c.run.active) return `check campaign ${c.id}: ${c.status}, ${poses}`;
  if (c.status === "done") return null;  // judged: the verdict is said instead
  return `check campaign ${c.id} ${c.status} after ${poses}`
    + (c.status === "estopped" ? ": reset it, then run the check again to resume it" : "");
}

/** Follow the check campaign until its run is over; its last state. */
async function followCheck(cid, job) {
  for (;;) {
    const c = await api("GET", `/campaigns/${cid}`);
    if (state.job !== job) return c;  // another model was shown meanwhile
    const line = checkRunLine(c);
    if (line) $("k-run-state").textContent = line;
    if (!(c.run && c.run.active) && c.status !== "running") return c;
    await new Promise((ok) => setTimeout(ok, CHECK_POLL_MS));
  }
}

$("k-run").addEventListener("click", async () => {
  const job = state.job;
  const button = $("k-run");
  button.disabled = true;  // one check at a time from here; the cell refuses a second anyway
  $("k-run-state").textContent = "starting...";
  try {
    // on the cell the model's campaign was measured on, as the calibration read it
    const r = await api("POST", `/models/${job}/checks/run`, {});
    if (r.started) await followCheck(r.campaign_id, job);
    if (state.job !== job) return;
    const h = await api("GET", `/models/${job}/health`);
    const c = await api("GET", `/campaigns/${r.campaign_id}`);
    if (state.job !== job) return;
    if (c.status === "done" && h.checked) {
      $("k-run-state").textContent = `check ${h.history}: ${h.verdict}`;
    }
    await showChecks(job);
  } catch (e) { $("k-run-state").textContent = ""; say(e); }
  finally { button.disabled = false; }
});
