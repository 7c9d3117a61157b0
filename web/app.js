// robocal page: plain fetch() against the REST API; no framework and no build step on purpose,
// so the page is exactly the files the server sends.
"use strict";

const TOKEN_KEY = "robocal.token";
// Final campaign states (drivers/lifecycle.py): nothing more can happen, so no more refreshes.
const FINAL = new Set(["done", "aborted"]);
const BUSY_JOB = new Set(["queued", "running"]);
const $ = (id) => document.getElementById(id);
// The page's current campaign and jobs; campaign and job are kept in the URL (history.js) so a
// reload finds them again. Updates come from the event stream (live.js), not from polling.
const state = { campaign: null, status: null, job: null, diag: null, failureShown: null,
                jobInfo: null,  // the shown calibration job as last seen
                verify: null,  // the verification run started from the results: {campaign, job}
                target: null };  // the shown campaign's target accuracy (mm), if adaptive
const READINGS_SHOWN = 6;  // the latest readings table keeps this many rows

/** Show a message in the header's notice row: an error (until dismissed or replaced) unless ok
 * (gone after a few seconds). `what` is text or an Error; an API refusal (ApiError) keeps the
 * request and its status one click away, under "details", for an engineer (or `technical`). */
function say(what, ok = false, technical = "") {
  const m = $("message");
  if (what instanceof ApiError) technical = what.technical;
  m.setAttribute("role", ok ? "status" : "alert");
  $("message-text").textContent = what instanceof Error ? what.message : what;
  $("message-technical").textContent = technical;
  $("message-details").hidden = !technical;
  $("message-details").open = false;
  m.className = ok ? "ok" : "";
  m.hidden = false;
  clearTimeout(say.timer);
  if (ok) say.timer = setTimeout(() => { m.hidden = true; }, 6000);
}
$("message-close").addEventListener("click", () => { $("message").hidden = true; });

// The header's height, for the page's scroll padding (style.css): what the page scrolls to (a
// focused field, a result shown) lands below the header and its notices, never under them.
new ResizeObserver(([e]) => document.documentElement.style.setProperty(
  "--header-h", `${Math.ceil(e.target.getBoundingClientRect().height)}px`,
)).observe(document.querySelector("header"));

/** Draw the eye to an element that just changed (a short highlight). */
function flash(el) {
  el.classList.remove("flash");
  void el.offsetWidth;  // restart the animation
  el.classList.add("flash");
}

/** An API refusal in the operator's words (what happened, what to do); `technical` is the
 * request, its status and the API's own words, for an engineer. */
class ApiError extends Error {
  constructor(message, technical, status) {
    super(message);
    this.technical = technical;
    this.status = status;
  }
}

// What the operator was doing, by request: the start of every refusal's message.
const DOING = [
  ["POST", /^\/cells$/, () => "The cell was not uploaded"],
  ["POST", /^\/measurements\/import/, () => "The file was not imported"],
  ["POST", /^\/campaigns$/, () => "The campaign was not planned"],
  ["POST", /^\/campaigns\/(\d+)\/(\w+)$/, (m) => `Campaign ${m[1]} could not ${
    { estop: "be stopped", reset: "be reset" }[m[2]] || m[2]}`],
  ["POST", /^\/estop$/, () => "The emergency stop was not confirmed"],
  ["POST", /^\/jobs$/, () => "The job was not started"],
  ["POST", /^\/models\/\d+\/compensate/, () => "The targets were not compensated"],
  ["POST", /^\/models\/\d+\/export/, () => "The export was not made"],
  ["POST", /^\/models\/\d+\/verify/, () => "The verification run was not planned"],
  ["POST", /^\/models\/\d+\/checks\/run/, () => "The check was not run"],
  ["POST", /^\/models\/\d+\/checks/, () => "The check was not judged"],
  ["GET", /^\/(\w+)/, () => "The page could not load what it shows"],
];

/** The refusal's message for people: what was being done, why not (the API's detail and the
 * fields it names, as the form calls them), and what to do. */
function refusal(method, path, status, data) {
  const found = DOING.find(([m, re]) => m === method && re.test(path));
  const doing = found ? found[2](path.match(found[1])) : "That did not work";
  const fields = Array.isArray(data && data.errors) ? data.errors.map((e) => {
    const at = (e.loc || []).filter((p) => !["body", "query", "path"].includes(p)).join(" ");
    return at ? `${at}: ${e.msg}` : e.msg;
  }).join("; ") : "";
  const detail = String((data && data.detail) || "").trim();
  const why = [detail, fields].filter(Boolean).join("; ");
  const todo = {
    401: "paste the service's API token in section 1 (robocal serve prints it at its first start)",
    403: "paste the service's API token in section 1",
    413: "the file is larger than the service takes; split it",
    429: "the service is busy: try again in a moment",
  }[status] || (status >= 500 ? "the service's log has the details; try again, and report it if it "
    + "happens again" : "");
  const reason = why || (status === 401 ? "the service refuses this tab's API token" : "");
  return `${doing}${reason ? `: ${reason}` : ""}${todo ? `. What to do: ${todo}.` : ""}`;
}

/** Call the API with the tab's token (reads need it too); the Response, or throw an ApiError
 * with the refusal in people's words. The token goes only in the Authorization header, never in
 * a URL. */
async function request(method, path, body, raw = false, contentType = "application/json") {
  const headers = { Accept: "application/json" };
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers["Content-Type"] = contentType;
  // raw: the body is already text, sent as is (a cell.json or meas.csv keeps its lines for the
  // errors).
  let r;
  try {
    r = await fetch(`/api${path}`, {
      method, headers, body: body === undefined ? undefined : raw ? body : JSON.stringify(body),
    });
  } catch (e) {
    throw new ApiError("The service does not answer. What to do: check that robocal serve is "
      + "running on this computer, then try again.", `${method} /api${path}: ${e.message}`, 0);
  }
  if (!r.ok) {
    const type = r.headers.get("content-type") || "";
    const data = type.includes("json") ? await r.json() : { detail: await r.text() };
    // RFC 9457 problem details: the API's own words are the useful part; the request and the
    // status go under "details".
    const technical = `${method} /api${path}: ${r.status} ${data.title || r.statusText}`
      + (data.errors ? `\n${JSON.stringify(data.errors)}` : "");
    throw new ApiError(refusal(method, path, r.status, data), technical, r.status);
  }
  return r;
}

/** Call the API; the JSON (or text) body. */
async function api(method, path, body, raw = false, contentType = "application/json") {
  const r = await request(method, path, body, raw, contentType);
  const type = r.headers.get("content-type") || "";
  return type.includes("json") ? r.json() : r.text();
}

/** An <img> of an API picture: fetched with the token (an src URL cannot carry it). */
async function showImage(img, url) {
  img.dataset.url = url;  // the picture this <img> is to show; an older answer is dropped
  const figure = img.closest("figure");
  // a chart being drawn says so (a grey box with words), never a broken-image icon
  if (figure) { figure.classList.add("loading"); figure.setAttribute("aria-busy", "true"); }
  try {
    const blob = await (await request("GET", url.replace(/^\/api/, ""))).blob();
    if (img.dataset.url !== url) return;
    if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
    img.src = URL.createObjectURL(blob);
  } catch (e) {
    if (img.dataset.url === url) say(e);
  } finally {
    if (figure && img.dataset.url === url) {
      figure.classList.remove("loading");
      figure.removeAttribute("aria-busy");
    }
  }
}

/** Empty an <img> of an API picture (another job's is not to be seen meanwhile). */
function clearImage(img) {
  if (img.src.startsWith("blob:")) URL.revokeObjectURL(img.src);
  img.removeAttribute("src");
  delete img.dataset.url;
}

// Download links to the API (model, recording, report) keep their /api href for people to
// read, but are fetched with the token and saved from memory.
document.addEventListener("click", async (ev) => {
  const a = ev.target.closest("a[href^='/api/']");
  if (!a) return;
  ev.preventDefault();
  try {
    const r = await request("GET", a.getAttribute("href").slice(4));
    const blob = await r.blob();
    const save = Object.assign(document.createElement("a"), {
      href: URL.createObjectURL(blob), download: savedName(r, a.getAttribute("download") || "") });
    save.click();
    setTimeout(() => URL.revokeObjectURL(save.href), 10000);
  } catch (e) { say(e); }
});

/** The name the service gives a download (its Content-Disposition: robot, job and what it
 * is), else `fallback`. */
function savedName(r, fallback) {
  const m = /filename="([^"]+)"/.exec(r.headers.get("content-disposition") || "");
  return m ? m[1] : fallback;
}

function showTokenState() {
  $("token-state").textContent = sessionStorage.getItem(TOKEN_KEY)
    ? "token set for this tab" : "no token: the service answers nothing without it";
}

$("token-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const t = $("token").value.trim();
  if (t) sessionStorage.setItem(TOKEN_KEY, t); else sessionStorage.removeItem(TOKEN_KEY);
  $("token").value = "";
  showTokenState();
  tokenChanged();  // the first loads, without a token, were refused (history.js)
});

/** A cell's picker label: simulated, or the real devices a campaign on it will drive. */
function cellLabel(c) {
  const d = c.cell.devices;
  return c.simulated ? `${c.id} (simulated)`
    : `${c.id} (real: tracker ${d.tracker.host}:${d.tracker.port}, controller ${d.controller.url})`;
}

// SMRs per cell id, and whether it is simulated, for the duration estimate (plan.js).
const cellSmrs = new Map();
const cellSimulated = new Map();

/** Fill the cell picker from GET /api/cells, keeping (or setting) the selection. */
async function loadCells(select) {
  try {
    const ids = await api("GET", "/cells");
    const cells = await Promise.all(ids.map((id) => api("GET", `/cells/${id}`)));
    cells.forEach((c) => {
      cellSmrs.set(c.id, Object.keys(c.cell.targets || {}).length);
      cellSimulated.set(c.id, !!c.simulated);
    });
    const pick = select || $("c-cell").value || "default";
    $("c-cell").replaceChildren(...cells.map((c) => new Option(cellLabel(c), c.id)));
    $("c-cell").value = ids.includes(pick) ? pick : ids[0];
    // the page's own "default" option stands before any cell is known: this marks the API's
    $("c-cell").dataset.loaded = "true";
    showEstimate();
  } catch (e) { say(e); }
}

$("cells-refresh").addEventListener("click", () => loadCells());

$("cell-upload-btn").addEventListener("click", async () => {
  try {
    const c = await api("POST", "/cells", $("cell-json").value, true);
    await loadCells(c.id);
    say(`cell ${c.id} uploaded`, true);
  } catch (e) { say(e); }  // a 422 names the line and column of the problem
});

/** A campaign becomes the page's current one: progress, readings, calibration enabled if done.
 * The results stay shown for a verification run of their model (keepResults). */
function useCampaign(c, keepResults = false) {
  const other = state.campaign !== c.id;
  state.campaign = c.id;
  if (other) readingsSeen.total = 0;
  showCampaign(c);
  if (!keepResults) {
    $("results").hidden = true;
    forgetJob();
  }
  if (other) $("readings").innerHTML = '<p class="muted">none yet</p>';
  followCampaign3d();  // cell3d.js: its readings in 3-D, unless a job's results stay shown
  rememberView();  // history.js: the URL says what the page shows
}

/** No calibration job shown any more (another campaign became the page's). */
function forgetJob() {
  state.job = state.jobInfo = null;
  $("j-state").textContent = "";
  resetVerification();  // the run shown was of that job's model
}

// A meas.csv measured elsewhere (or by `robocal simulate`) becomes a done campaign on the chosen
// cell; a malformed file is refused with its line numbers and nothing is stored.
$("m-import-btn").addEventListener("click", async () => {
  const file = $("m-file").files[0];
  if (!file) { say("choose a meas.csv file first"); return; }
  const query = new URLSearchParams({ filename: file.name, cell_id: $("c-cell").value || "default" });
  if ($("m-name").value.trim()) query.set("name", $("m-name").value.trim());
  try {
    const c = await api("POST", `/measurements/import?${query}`, await file.text(), true, "text/csv");
    useCampaign(c);
    await refreshReadings(c.id);
    say(`${file.name} imported as campaign ${c.id} (${c.poses_done} poses)`, true);
  } catch (e) { say(e); }
});

$("campaign-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const body = planBody();  // plan.js: the form's fields as CampaignCreate takes them
  try {
    const r = await request("POST", "/campaigns", body);
    // 202: a planning that takes seconds (a D-optimal choice) is a job; follow it to its campaign.
    const c = r.status === 202 ? await planned(await r.json()) : await r.json();
    plannedSmrs.set(c.id, cellSmrs.get(body.cell_id));
    useCampaign(c);
    refreshCampaigns().catch(() => {});  // history.js: the new campaign listed at once
    say(`Campaign ${c.id} planned on cell ${body.cell_id}: press Start to run it.`, true);
  } catch (e) { say(e); }
});

/** Follow a planning job, from the event stream, until it is done (its campaign) or failed
 * (throws its reason). */
async function planned(job) {
  const shown = $("c-planning");
  shown.hidden = false;
  try {
    const end = await new Promise((ok) => watchJob(job, (j) => {
      shown.textContent = `planning... ${Math.round(j.progress * 100)} %`;
      if (!BUSY_JOB.has(j.state)) ok(j);
    }));
    if (end.state === "failed") throw new Error(`planning job ${end.id} failed: ${end.reason}`);
    return await api("GET", `/campaigns/${end.campaign_id}`);
  } finally { shown.hidden = true; }
}

// Every campaign button asks for one life-cycle action; which are enabled follows the actions the
// API reports for the campaign's state, so a click the state does not allow cannot be made.
document.querySelectorAll("button[data-action]").forEach((b) => b.addEventListener("click", async () => {
  const action = b.dataset.action;
  b.disabled = true;  // no double click while the request is out; the refresh re-enables
  try {
    const r = await api("POST", `/campaigns/${state.campaign}/${action}`);
    say(`Campaign ${state.campaign} ${DONE_WORDS[action] || action}`, true,
      r.note ? `${action}: ${r.note}` : "");
  } catch (e) { say(e); }
  refreshCampaign();  // the action may have changed the state either way
}));

// What each campaign action did and what comes next, in the operator's words.
const DONE_WORDS = {
  start: "started: the arm moves to its first pose.",
  pause: "pauses after the pose in progress. Resume continues it.",
  resume: "resumed: it goes on at its next pose not yet measured.",
  abort: "aborted: it ends here; its readings are kept.",
  reset: "reset after the stop: it is paused now. Check the cell, then press Resume to go on.",
  estop: "stopped: the arm halts where it is. To go on: check the cell, press Reset, then Resume.",
};

// The header's emergency stop: whatever campaign runs, whichever page state this is.
$("estop-all").addEventListener("click", async () => {
  try {
    const r = await api("POST", "/estop");
    if (r.campaign_id === null || r.campaign_id === undefined) {
      say("Emergency stop: no campaign was running; nothing moved.", true);
    } else {
      say(`Emergency stop: campaign ${r.campaign_id} ${DONE_WORDS.estop}`, true,
        r.note ? `estop: ${r.note}` : "");
    }
  } catch (e) { say(e); }
  if (state.campaign !== null) refreshCampaign();
});

// Poses done per campaign as last heard, from its pose events and its reads alike: the progress
// bar and the history's row show this one count (a list read can lag the events), and a count
// only grows (a resumed run goes on from where it stopped).
const poseCounts = new Map();

/** The campaign's pose count after hearing (done, total); the history's row shows it too. */
function heardPoses(id, done, total) {
  const was = poseCounts.get(id);
  if (!was || done >= was.done) poseCounts.set(id, { done, total });
  const now = poseCounts.get(id);
  const cell = document.querySelector(`#h-campaigns-table tr[data-campaign="${id}"] td.poses`);
  if (cell) cell.textContent = `${now.done} / ${now.total}`;
  return now;
}

/** The progress bar and count (also from each pose's event, without asking the API). */
function showPoseCount(done, total) {
  ({ done, total } = heardPoses(state.campaign, done, total));
  $("p-bar").max = total || 1;
  $("p-bar").value = done;
  $("p-count").textContent = `${done} / ${total} poses`;
  pullCampaign3d();  // cell3d.js: the poses done since, into the 3-D viewer if it shows them
}

function showCampaign(c) {
  $("progress").hidden = false;
  $("p-id").textContent = c.id;
  $("p-name").textContent = c.name;
  $("p-status").textContent = c.status;
  $("p-run").textContent = c.run && c.run.detail
    ? `${c.run.active ? "run" : "last run"}: ${c.run.detail}` : "";
  showPoseCount(c.poses_done, c.poses_total);
  if (c.settings) showPlannedEstimate(c);  // plan.js
  const adaptive = c.settings && c.settings.plan && c.settings.plan.adaptive;
  const steps = (c.settings && c.settings.adaptive_steps) || [];
  state.target = adaptive ? adaptive.target_accuracy_mm : null;
  showAdaptive(steps[steps.length - 1], state.target);  // plan.js
  const actions = new Set(c.actions || []);
  document.querySelectorAll("button[data-action]").forEach((b) => {
    b.disabled = !actions.has(b.dataset.action);
  });
  // A failed device is an error a person must see, once per failure.
  const detail = c.detail || (c.run && c.run.detail) || "";
  $("p-run").className = c.status === "failed" ? "error" : "muted";
  if (c.status === "failed" && state.failureShown !== `${c.id}:${detail}`) {
    state.failureShown = `${c.id}:${detail}`;
    say(`Campaign ${c.id} stopped on a fault${detail ? `: ${detail}` : ""}. What to do: check `
      + "the devices, then press Reset and Resume; the readings so far are kept.");
  }
  state.status = c.status;
  if (c.kind === "verification") showVerifyState(c);
  followCampaign3d();
  refreshCalibrate();
}

/** Calibrate only a done campaign, and not while a calibration of it is queued or running. */
async function refreshCalibrate() {
  const id = state.campaign;
  if (state.status !== "done") { $("calibrate").disabled = true; return; }
  try {
    const jobs = await refreshJobs();  // history.js: the job list, shown there too
    if (id !== state.campaign) return;
    $("calibrate").disabled = jobs.some((j) => j.campaign_id === id && j.kind === "calibration"
                                              && BUSY_JOB.has(j.state));
  } catch (e) { $("calibrate").disabled = false; }  // the API refuses a duplicate anyway (409)
}

/** Whether the current campaign may still change: not final, or its run not yet wound up (the
 * state ends a moment before the run has stored its summary). */
function campaignLive() {
  return state.campaign !== null && (!FINAL.has(state.status) || state.runActive);
}

// Campaign reads in the order asked: an answer can land after a later one (a read asked before
// the run began, answered once poses come in), and the older state must not overwrite the newer.
const campaignReads = { asked: 0, shown: 0 };

/** Read the current campaign and its latest readings once (on its events, after an action). */
async function refreshCampaign() {
  const id = state.campaign;
  if (id === null) return;
  const n = ++campaignReads.asked;
  try {
    const c = await api("GET", `/campaigns/${id}`);
    if (id !== state.campaign) return;  // another campaign was opened meanwhile
    if (n < campaignReads.shown) return;  // a later read is shown already
    campaignReads.shown = n;
    state.runActive = !!(c.run && c.run.active);
    showCampaign(c);
    await refreshReadings(id);
    // a verification's figures come from its stored readings: only once the run has ended
    if (c.kind === "verification" && c.status === "done" && !state.runActive) {
      await showVerification(c.id);
    }
  } catch (e) { say(e); }
}

// The readings total last seen: the next page asked for starts just before it, so one request
// usually brings the last rows (a second one only when more came than that page holds).
const readingsSeen = { total: 0 };
const READINGS_AHEAD = 60;

/** The last few readings of the campaign, newest last (readings come in pages). */
async function refreshReadings(id) {
  try {
    let offset = Math.max(0, readingsSeen.total - READINGS_SHOWN);
    let r = await request("GET",
      `/campaigns/${id}/measurements?offset=${offset}&limit=${READINGS_SHOWN + READINGS_AHEAD}`);
    let total = Number(r.headers.get("X-Total-Count") || 0);
    let rows = await r.json();
    if (offset + rows.length < total || (offset > 0 && offset >= total)) {  // missed the end
      offset = Math.max(0, total - READINGS_SHOWN);
      r = await request("GET", `/campaigns/${id}/measurements?offset=${offset}&limit=${READINGS_SHOWN}`);
      total = Number(r.headers.get("X-Total-Count") || 0);
      rows = await r.json();
    }
    if (id !== state.campaign) return;
    readingsSeen.total = total;
    renderReadings(rows.slice(-READINGS_SHOWN), total);
  } catch (e) { say(e); }
}

function renderReadings(rows, total) {
  if (!rows.length) { $("readings").innerHTML = '<p class="muted">none yet</p>'; return; }
  const table = document.createElement("table");
  table.id = "readings-table";
  const head = table.createTHead().insertRow();
  ["pose", "SMR", "status", "x / mm", "y / mm", "z / mm", "std max / mm", "t / s", "T / °C"]
    .forEach((h) => { head.appendChild(document.createElement("th")).textContent = h; });
  const body = table.createTBody();
  const linked = cell3d.source && cell3d.source.kind === "campaign";
  rows.forEach((r) => {
    const tr = body.insertRow();
    const xyz = r.xyz || [null, null, null];
    // the pose a button when the 3-D viewer shows this campaign: its timeline is the plan's
    if (linked) tr.insertCell().appendChild(poseButton(r.pose_index, r.pose));
    else tr.insertCell().textContent = r.pose;
    [r.target, r.status + (r.detail ? ` (${r.detail})` : ""), ...xyz.map((v) => fmt(v)),
     r.std ? fmt(Math.max(...r.std)) : "-", r.time_s === null ? "-" : r.time_s.toFixed(1),
     r.temp_c === null ? "-" : r.temp_c.toFixed(2)]
      .forEach((v) => { tr.insertCell().textContent = v; });
  });
  const caption = table.createCaption();
  caption.textContent = `last ${rows.length} of ${total} readings`;
  $("readings").replaceChildren(table);
}

$("job-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  $("calibrate").disabled = true;  // until this job ends: no duplicate on a second click
  try {
    const body = { campaign_id: state.campaign, method: $("j-method").value };
    if ($("j-holdout").value) body.holdout_campaign_id = Number($("j-holdout").value);
    // the application's tolerance, over the cell's (empty: the cell's); the diagnosis's too
    const tolerance = $("j-tolerance").value.trim() ? { tolerance_mm: Number($("j-tolerance").value) } : {};
    Object.assign(body, tolerance);
    const j = await api("POST", "/jobs", body);
    state.job = j.id;
    state.diag = null;
    $("results").hidden = true;
    $("diagnosis").hidden = true;
    showJob(j);
    rememberView();
    watchJob(j, followJob);
    // Automatic extensions: a diagnosis job on the same campaign, alongside the calibration.
    if ($("j-auto").checked) {
      const d = await api("POST", "/jobs", { campaign_id: state.campaign, kind: "diagnosis", ...tolerance });
      useDiagnosis(d);  // diagnosis.js
    }
  } catch (e) { say(e); refreshCalibrate(); }
});

function showJob(j) {
  state.jobInfo = j;
  $("j-state").textContent = `job ${j.id} (${j.method}): ${j.state}`
    + (j.state === "running" && j.progress ? ` (${Math.round(j.progress * 100)} %)` : "")
    + (j.reason ? `: ${j.reason}` : "");
}

/** The shown calibration job as its events (live.js) tell it; its results once done (the
 * job-end notice is live.js's, for every job). */
function followJob(j) {
  if (j.id !== state.job) return;
  showJob(j);
  if (!BUSY_JOB.has(j.state)) refreshCalibrate();
  if (j.state === "done") showResults(j);
}

function showResults(j) {
  $("results").hidden = false;
  flash($("results"));
  if (!state.verify || state.verify.job !== j.id) resetVerification();  // another model's run
  $("model-link").href = j.model_url;
  $("model-link").setAttribute("download", `job-${j.id}.model.json`);
  // The Rerun recording: absent if the server could not write one.
  $("recording-link").hidden = !j.recording_url;
  $("recording-none").hidden = !!j.recording_url;
  if (j.recording_url) {
    $("recording-link").href = j.recording_url;
    $("recording-link").setAttribute("download", `job-${j.id}.rrd`);
  }
  const charts = `/api/charts/jobs/${j.id}`;
  ["boxplot", "errors"].forEach((id) => { clearImage($(id)); showImage($(id), `${charts}/${id}.png`); });
  $("table3").innerHTML = '<p class="muted">computing every method on this campaign...</p>';
  // an answer for a job no longer shown is dropped
  api("GET", `${charts.slice(4)}/table3`).then((t) => { if (state.job === j.id) renderTable3(t); })
    .catch((e) => { if (state.job === j.id) $("table3").textContent = e.message; });
  showModel(j);  // web/model.js: validation, identified parameters, recording hint
  showCell3d(j);  // web/cell3d.js: the recording in the 3-D viewer
}

/** Save a POST answer (a compensation or an export of the shown job's model) as a file. */
async function postDownload(path, body, filename) {
  $("t-state").textContent = "computing...";
  try {
    const r = await request("POST", path, body, true, "text/csv");
    const name = savedName(r, filename);
    const save = Object.assign(document.createElement("a"), {
      href: URL.createObjectURL(await r.blob()), download: name });
    save.click();
    setTimeout(() => URL.revokeObjectURL(save.href), 10000);
    $("t-state").textContent = `saved ${name}`;
  } catch (e) { $("t-state").textContent = ""; say(e); }
}

async function targetsUpload(query) {
  const file = $("t-file").files[0];
  if (!file) { say("choose a targets.csv file first"); return null; }
  query.set("filename", file.name);
  return file.text();
}

$("t-joints").addEventListener("click", async () => {
  const query = new URLSearchParams();
  if ($("t-tcp").value.trim()) query.set("tcp", $("t-tcp").value.trim());
  const body = await targetsUpload(query);
  if (body !== null) {
    await postDownload(`/models/${state.job}/compensate?${query}`, body, `job-${state.job}.joints.csv`);
  }
});

$("t-rapid").addEventListener("click", async () => {
  const query = new URLSearchParams({ format: "rapid" });
  const body = await targetsUpload(query);
  if (body !== null) {
    await postDownload(`/models/${state.job}/export?${query}`, body, `job-${state.job}.mod`);
  }
});

[["x-params", "params", "csv"], ["x-urdf", "urdf", "urdf"]].forEach(([id, format, suffix]) => {
  $(id).addEventListener("click", () => postDownload(
    `/models/${state.job}/export?format=${format}`, undefined, `job-${state.job}.${suffix}`));
});

/** Clear the verification block: no run of the shown model yet. */
function resetVerification() {
  state.verify = null;
  $("v-state").textContent = "";
  $("v-report").hidden = true;
  $("v-table").replaceChildren();
}

// A verification run of the shown job's model: planned and started by the API, then followed as
// the page's current campaign, so the progress bar and the campaign buttons (e-stop) are its.
$("v-start").addEventListener("click", async () => {
  const job = state.job;
  const body = { cycles: Number($("v-cycles").value), directions: Number($("v-directions").value) };
  $("v-start").disabled = true;  // planning takes a moment: no second run on a second click
  const shown = $("v-state").textContent;
  $("v-state").textContent = `planning a verification run of job ${job}'s model...`;
  try {
    const c = await api("POST", `/models/${job}/verify`, body);
    resetVerification();  // a refused run (409, 422) leaves the one shown as it was
    state.verify = { campaign: c.id, job };
    useCampaign(c, true);
    refreshCampaign();
    say(`verification campaign ${c.id} of job ${job}'s model started`, true);
  } catch (e) { $("v-state").textContent = shown; say(e); }
  $("v-start").disabled = false;
});

/** The verification block's status line, from its campaign as the progress poll reads it. */
function showVerifyState(c) {
  if (!state.verify || state.verify.campaign !== c.id) return;
  $("v-state").textContent = `verification campaign ${c.id}: ${c.status}`
    + ` (${c.poses_done} / ${c.poses_total} poses)`
    + (FINAL.has(c.status) || c.status === "failed" ? "" : "; its figures come once it is done");
}

/** AP before over AP after, as the certificate says it ("246x"), with a decimal under 10x. */
function gainText(before, after) {
  if (!(after > 0)) return "-";
  const g = before / after;
  return `${g >= 10 ? g.toFixed(0) : g.toFixed(1)}x`;
}

/** A done verification run's worst-point figures, before and after, and its certificate. */
async function showVerification(id) {
  if (!state.verify || state.verify.campaign !== id || state.verify.shown) return;
  try {
    const r = await api("GET", `/campaigns/${id}/verification`);
    if (!state.verify || state.verify.campaign !== id) return;
    state.verify.shown = true;
    const b = r.before, a = r.after;
    const table = makeTable("v-summary", ["", "worst-point AP / mm", "worst-point RP / mm"], [
      ["before (nominal joints)", fmt(b.AP_max_mm), fmt(b.RP_max_mm)],
      ["after (compensated)", fmt(a.AP_max_mm), fmt(a.RP_max_mm)],
      ["gain (AP before / AP after)", gainText(b.AP_max_mm, a.AP_max_mm), ""],
    ]);
    table.createCaption().textContent = `${r.robot}, model ${r.model.path}: ${r.cycles} cycles`
      + ` x ${r.directions} approach directions, ${r.date}`;
    $("v-table").replaceChildren(table, ...verificationUncertainty(r));
    $("v-certificate").dataset.campaign = id;
    $("v-report").hidden = false;
    $("v-state").textContent = `verification campaign ${id}: done`;
  } catch (e) { say(e); }
}

// The certificate is fetched with the token (a link cannot carry it) and shown in a new tab from
// memory; the tab is opened at the click, as popup blockers allow, and filled once it is here.
$("v-certificate").addEventListener("click", async () => {
  const id = $("v-certificate").dataset.campaign;
  const tab = window.open("", "_blank");
  if (tab) tab.document.title = "loading the accuracy certificate...";
  try {
    const blob = await (await request("GET", `/campaigns/${id}/certificate`)).blob();
    const url = URL.createObjectURL(blob);
    if (tab) {
      tab.opener = null;  // the certificate needs nothing from this page
      tab.location.href = url;
    } else {  // no tab allowed: saved as a file instead
      Object.assign(document.createElement("a"), { href: url, download: `certificate-${id}.html` })
        .click();
    }
    setTimeout(() => URL.revokeObjectURL(url), 60000);
  } catch (e) { if (tab) tab.close(); say(e); }
});

function fmt(v) {
  if (v === null || v === undefined) return "-";
  const a = Math.abs(v);
  return a !== 0 && (a >= 1e4 || a < 1e-3) ? v.toExponential(3) : v.toFixed(4);
}

/** Table 3 as an HTML table; built with DOM nodes so no text is parsed as HTML. */
function renderTable3(t) {
  const table = document.createElement("table");
  table.id = "table3-table";
  const head = table.createTHead().insertRow();
  head.appendChild(document.createElement("th")).textContent = `campaign ${t.campaign_id}, ${t.poses} poses`;
  t.columns.forEach((c) => {
    const th = head.appendChild(document.createElement("th"));
    th.textContent = c;
    if (c === t.method) th.className = "chosen";
  });
  const body = table.createTBody();
  t.rows.forEach((row) => {
    const tr = body.insertRow();
    tr.insertCell().textContent = row.label;
    row.values.forEach((v, i) => {
      const td = tr.insertCell();
      // Milliseconds to four decimals is noise.
      td.textContent = row.label.startsWith("time") && v !== null ? v.toFixed(0) : fmt(v);
      if (t.columns[i] === t.method) td.className = "chosen";
    });
  });
  $("table3").replaceChildren(table);
}

// The page starts in history.js, the last script: it restores the view the URL names.
