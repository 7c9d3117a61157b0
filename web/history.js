// History: every campaign and job, each reopened with a click; two models compared on one
// campaign; and the view (campaign, job) kept in the URL so that a reload finds it again.
// The last script of the page: it starts it (boot, at the end).
"use strict";

const past = { campaigns: [], jobs: [] };
const HISTORY_ROWS = 200;  // newest first; older ones stay in the API

/** When a time was, short: "14:03:12" today, else the date too. */
function when(iso) {
  if (!iso) return "-";
  const t = new Date(iso);
  return t.toDateString() === new Date().toDateString() ? t.toLocaleTimeString()
    : t.toLocaleString();
}

/** A button that opens a campaign or a job from a history row. */
function openButton(kind, id) {
  const b = Object.assign(document.createElement("button"),
    { type: "button", className: "open", textContent: "open" });
  b.dataset[kind] = id;
  b.title = `make ${kind} ${id} the page's own`;
  return b;
}

/** GET /api/campaigns into the history list; the list. */
async function refreshCampaigns() {
  const list = await api("GET", "/campaigns");
  past.campaigns = list;
  renderCampaigns();
  fillCompareChoices();
  return list;
}

/** GET /api/jobs into the history list; the list. */
async function refreshJobs() {
  const list = await api("GET", "/jobs");
  past.jobs = list;
  renderJobs();
  fillCompareChoices();
  return list;
}

async function refreshHistory() {
  try { await Promise.all([refreshCampaigns(), refreshJobs()]); } catch (e) { say(e); }
}

function renderCampaigns() {
  const rows = past.campaigns.slice(-HISTORY_ROWS).reverse();
  if (!rows.length) { $("h-campaigns").innerHTML = '<p class="muted">no campaign yet</p>'; return; }
  const table = makeTable("h-campaigns-table", ["", "id", "name", "kind", "status", "poses", "created"],
    rows.map((c) => {
      const n = heardPoses(c.id, c.poses_done, c.poses_total);  // app.js: the bar's count too
      return ["", String(c.id), c.name, c.kind, c.status, `${n.done} / ${n.total}`,
              when(c.created_at)];
    }));
  [...table.tBodies[0].rows].forEach((tr, i) => {
    const c = rows[i];
    tr.cells[0].replaceChildren(openButton("campaign", c.id));
    tr.cells[5].className = "poses";
    tr.dataset.campaign = c.id;
    if (c.id === state.campaign) tr.className = "current";
  });
  $("h-campaigns").replaceChildren(table);
  fillHoldoutChoices();
}

/** The calibration's held-out campaign: none, or a done measurement campaign other than the
 * page's (the service refuses one of another cell, with the reason). */
function fillHoldoutChoices() {
  const sel = $("j-holdout");
  const was = sel.value;
  const others = past.campaigns.filter((c) => c.kind === "measurement" && c.status === "done"
    && c.poses_done > 0 && c.id !== state.campaign).reverse();
  sel.replaceChildren(new Option("none (leave-one-pose-out)", ""),
    ...others.map((c) => new Option(`campaign ${c.id}: ${c.name} (${c.poses_done} poses)`, c.id)));
  sel.value = others.some((c) => String(c.id) === was) ? was : "";
}

function renderJobs() {
  const rows = past.jobs.slice(-HISTORY_ROWS).reverse();
  if (!rows.length) { $("h-jobs").innerHTML = '<p class="muted">no job yet</p>'; return; }
  const table = makeTable("h-jobs-table",
    ["", "id", "kind", "method", "campaign", "state", "finished"],
    rows.map((j) => ["", String(j.id), j.kind, j.kind === "calibration" ? j.method : "-",
                     j.campaign_id === null ? "-" : String(j.campaign_id),
                     j.state + (j.reason ? `: ${j.reason}` : ""), when(j.finished_at)]));
  [...table.tBodies[0].rows].forEach((tr, i) => {
    const j = rows[i];
    tr.dataset.job = j.id;
    tr.cells[5].className = "evidence";
    // a calibration opens to its results (or its progress), a diagnosis to its report, a
    // planning job to its campaign
    if (j.kind !== "planning" && j.state !== "failed") tr.cells[0].replaceChildren(openButton("job", j.id));
    if (j.kind === "planning" && j.campaign_id !== null) {
      tr.cells[0].replaceChildren(openButton("campaign", j.campaign_id));
    }
    if (j.id === state.job) tr.className = "current";
  });
  $("h-jobs").replaceChildren(table);
}

$("history").addEventListener("click", (ev) => {
  const b = ev.target.closest("button.open");
  if (!b) return;
  if (b.dataset.campaign) openCampaign(Number(b.dataset.campaign));
  else if (b.dataset.job) openJob(Number(b.dataset.job), true);
});

/** Make a stored campaign the page's current one: its progress, readings and buttons. A
 * verification run of a job's model opens under that job's results, where its figures are. */
async function openCampaign(id, keepResults = false) {
  try {
    const c = await api("GET", `/campaigns/${id}`);
    const model = c.kind === "verification" ? (c.settings || {}).model_job : undefined;
    if (model && !keepResults) return await openVerification(c.id, model);
    if (c.kind === "verification" && !model) {
      say(`verification campaign ${id} checks a model file, not a job of this service: its`
        + ` figures are at /api/campaigns/${id}/verification and its certificate beside them`, true);
    }
    useCampaign(c, keepResults);
    renderCampaigns();
    renderJobs();
    await refreshCampaign();
    if (!keepResults) $("campaign").scrollIntoView({ block: "start" });
    return c;
  } catch (e) { say(e); return null; }
}

/** A verification campaign with the results of the job whose model it ran: its status, and its
 * figures once it is done. */
async function openVerification(id, job) {
  if (state.job !== job) await openJob(job);
  const c = await openCampaign(id, true);
  if (c) {
    state.verify = { campaign: c.id, job };
    showVerifyState(c);
    if (c.status === "done") await showVerification(c.id);
    rememberView();
    $("v-state").scrollIntoView({ block: "center" });
  }
  return c;
}

/** Show a calibration job: its campaign becomes the page's, then its results if it is done (or
 * its progress, followed, if it is not). */
async function openJob(id, scroll = false) {
  try {
    const j = await api("GET", `/jobs/${id}`);
    if (j.campaign_id !== state.campaign) await openCampaign(j.campaign_id, true);
    if (j.kind === "diagnosis") {  // its report, beside a calibration of its campaign
      if (await shownCampaign() !== j.campaign_id) {
        // the report sits under Results: show its campaign's latest calibration there first
        const cal = await latestCalibration(j.campaign_id);
        if (cal === null) {
          say(`diagnosis job ${j.id} is shown beside a calibration of campaign ${j.campaign_id}:`
            + " calibrate that campaign to see it", true);
          return;
        }
        await openJob(cal);
      }
      useDiagnosis(j);
      renderJobs();
      if (scroll) $("diagnosis").scrollIntoView({ block: "start" });
      return;
    }
    state.job = j.id;
    state.diag = null;
    $("diagnosis").hidden = true;
    showJob(j);
    rememberView();
    renderJobs();
    if (j.state === "done") showResults(j);
    else {
      $("results").hidden = true;
      if (BUSY_JOB.has(j.state)) watchJob(j, followJob);
    }
    if (scroll) ($("results").hidden ? $("calibration") : $("results")).scrollIntoView({ block: "start" });
  } catch (e) { say(e); }
}

/** The campaign of the calibration whose results the page shows; null if none is shown. */
async function shownCampaign() {
  if (state.job === null || $("results").hidden) return null;
  return (await api("GET", `/jobs/${state.job}`)).campaign_id;
}

/** The latest done calibration job of a campaign (its id); null if it has none. */
async function latestCalibration(cid) {
  const done = (await api("GET", "/jobs"))
    .filter((x) => x.kind === "calibration" && x.state === "done" && x.campaign_id === cid);
  return done.length ? done[done.length - 1].id : null;
}

/** The URL says which campaign and job the page shows (replaced, not a new history entry). */
function rememberView() {
  const h = new URLSearchParams();
  if (state.campaign !== null) h.set("campaign", state.campaign);
  if (state.job !== null) h.set("job", state.job);
  const hash = h.toString() ? `#${h}` : "";
  if (location.hash !== hash) history.replaceState(null, "", hash || location.pathname);
}

/** Rebuild the view the URL names: its job (with the job's campaign), then its campaign (a
 * verification run of that job's model, say). */
async function restoreView() {
  const h = new URLSearchParams(location.hash.slice(1));
  const cid = Number(h.get("campaign")) || null;
  const jid = Number(h.get("job")) || null;
  if (jid) await openJob(jid);
  if (cid && cid !== state.campaign) {
    const c = await openCampaign(cid, state.job !== null);
    if (c && c.kind === "verification" && state.job !== null && !state.verify) {
      state.verify = { campaign: c.id, job: state.job };
      showVerifyState(c);
      if (c.status === "done") showVerification(c.id);
    }
  }
  rememberView();
}

// Compare two models on one campaign: GET /api/models/{job}/evaluate?campaign_id=N for each.
function fillCompareChoices() {
  const models = past.jobs.filter((j) => j.kind === "calibration" && j.state === "done").reverse();
  const campaigns = past.campaigns
    .filter((c) => c.kind === "measurement" && c.status === "done" && c.poses_done > 0).reverse();
  const fill = (sel, items, label, pick) => {
    const was = sel.value;
    sel.replaceChildren(...items.map((x) => new Option(label(x), x.id)));
    const ids = items.map((x) => String(x.id));
    sel.value = ids.includes(was) ? was : pick;
  };
  const modelLabel = (j) => `job ${j.id}: ${j.method}, campaign ${j.campaign_id}`;
  fill($("cmp-a"), models, modelLabel, models[0] ? String(models[0].id) : "");
  fill($("cmp-b"), models, modelLabel, models[1] ? String(models[1].id) : "");
  // a validation campaign: preferably one model A was not fitted on
  const a = models.find((j) => String(j.id) === $("cmp-a").value);
  const other = campaigns.find((c) => !a || c.id !== a.campaign_id) || campaigns[0];
  fill($("cmp-campaign"), campaigns, (c) => `campaign ${c.id}: ${c.name} (${c.poses_done} poses)`,
    other ? String(other.id) : "");
  $("cmp-run").disabled = models.length < 2 || !campaigns.length;
}

/** Rows of the comparison: [label, value of an evaluation's accuracy dict]. */
const COMPARE_ROWS = [
  ["AP mean / mm", (a) => a.ap && a.ap.mean],
  ["AP max / mm", (a) => a.ap && a.ap.max],
  ["AP std / mm", (a) => a.ap && a.ap.std],
  ["RMSE / mm", (a) => a.rmse],
  ["AO' mean / deg", (a) => a.ao_log && a.ao_log.mean],
  ["poses", (a) => a.n_poses],
];

$("compare-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const ids = [$("cmp-a").value, $("cmp-b").value].map(Number);
  const cid = Number($("cmp-campaign").value);
  if (ids[0] === ids[1]) { say("choose two different models"); return; }
  $("compare").innerHTML = '<p class="muted">evaluating both models...</p>';
  try {
    const evals = await Promise.all(
      ids.map((id) => api("GET", `/models/${id}/evaluate?campaign_id=${cid}`)));
    renderCompare(ids, cid, evals);
  } catch (e) { $("compare").replaceChildren(); say(e); }
});

function renderCompare(ids, cid, evals) {
  const method = (id) => (past.jobs.find((j) => j.id === id) || {}).method || "?";
  const heads = [`on campaign ${cid}`, "nominal",
                 ...ids.map((id) => `job ${id} (${method(id)})`)];
  const nominal = evals[0].nominal || {};
  const rows = COMPARE_ROWS.map(([label, get]) => [label, fmtCount(get(nominal)),
    ...evals.map((e) => fmtCount(get(e.model || {})))]);
  rows.push(["AP mean gain over nominal / %", "",
             ...evals.map((e) => fmtPct(e.improvement_pct && e.improvement_pct.ap_mean))]);
  const table = makeTable("compare-table", heads, rows);
  // the better model on each error row, marked
  [...table.tBodies[0].rows].slice(0, 5).forEach((tr) => {
    const v = [2, 3].map((k) => parseFloat(tr.cells[k].textContent));
    if (v.every(Number.isFinite) && v[0] !== v[1]) tr.cells[v[0] < v[1] ? 2 : 3].className = "chosen";
  });
  // whatever the API warns about (data of another cell, absurd errors), in its own words
  const warnings = evals.flatMap((e, k) => [].concat(e.warnings || e.warning || [])
    .map((w) => `job ${ids[k]}: ${typeof w === "string" ? w : JSON.stringify(w)}`));
  const parts = [table];
  if (warnings.length) {
    parts.push(Object.assign(document.createElement("p"),
      { className: "warn", textContent: warnings.join("; ") }));
  }
  $("compare").replaceChildren(...parts);
}

function fmtCount(v) { return Number.isInteger(v) ? String(v) : fmt(v); }
function fmtPct(v) { return typeof v === "number" && Number.isFinite(v) ? v.toFixed(1) : "-"; }

/** A new token: everything that needs it is asked again. */
function tokenChanged() {
  if (!sessionStorage.getItem(TOKEN_KEY)) return;
  loadCells();
  restartEvents();
  refreshHistory();
  refreshFleet();
  restoreView();
}

function boot() {
  showTokenState();
  showEstimate();
  if (!sessionStorage.getItem(TOKEN_KEY)) return;
  loadCells();
  connectEvents();
  refreshHistory();
  refreshFleet();
  restoreView();
}

boot();
