// robocal page: plain fetch() against the REST API; no framework and no build step on purpose,
// so the page is exactly the files the server sends.
"use strict";

const TOKEN_KEY = "robocal.token";
const POLL_MS = 400;
const TERMINAL = new Set(["done", "aborted", "failed"]);
const $ = (id) => document.getElementById(id);
const state = { campaign: null, job: null, campaignTimer: null, jobTimer: null };

/** Show a message at the corner (an error unless ok). */
function say(text, ok = false) {
  const m = $("message");
  m.textContent = text;
  m.className = ok ? "ok" : "";
  m.hidden = false;
  clearTimeout(say.timer);
  say.timer = setTimeout(() => { m.hidden = true; }, ok ? 3000 : 10000);
}

/** Call the API; the JSON body, or throw with the problem-detail message. */
async function api(method, path, body) {
  const headers = { Accept: "application/json" };
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (token) headers.Authorization = `Bearer ${token}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const r = await fetch(`/api${path}`, {
    method, headers, body: body === undefined ? undefined : JSON.stringify(body),
  });
  const type = r.headers.get("content-type") || "";
  const data = type.includes("json") ? await r.json() : await r.text();
  if (!r.ok) {
    // RFC 9457 problem details: the API's own words are the useful part.
    const detail = (data && data.detail) || r.statusText;
    throw new Error(`${method} /api${path}: ${r.status} ${data.title || r.statusText}: ${detail}`);
  }
  return data;
}

function showTokenState() {
  $("token-state").textContent = sessionStorage.getItem(TOKEN_KEY)
    ? "token set for this tab" : "no token: reading works, changes are refused";
}

$("token-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const t = $("token").value.trim();
  if (t) sessionStorage.setItem(TOKEN_KEY, t); else sessionStorage.removeItem(TOKEN_KEY);
  $("token").value = "";
  showTokenState();
});

$("campaign-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  const body = {
    poses: Number($("c-poses").value), seed: Number($("c-seed").value),
    settle: $("c-settle").value,
  };
  if ($("c-name").value.trim()) body.name = $("c-name").value.trim();
  try {
    const c = await api("POST", "/campaigns", body);
    state.campaign = c.id;
    showCampaign(c);
    $("start").disabled = false;
    $("calibrate").disabled = true;
    $("results").hidden = true;
    say(`campaign ${c.id} planned`, true);
  } catch (e) { say(e.message); }
});

$("start").addEventListener("click", async () => {
  try {
    showCampaign(await api("POST", `/campaigns/${state.campaign}/start`));
    $("start").disabled = true;
    pollCampaign();
  } catch (e) { say(e.message); }
});

document.querySelectorAll(".controls button").forEach((b) => b.addEventListener("click", async () => {
  const action = b.dataset.action;
  try {
    const r = await api("POST", `/campaigns/${state.campaign}/${action}`);
    say(`${action}: ${r.status || "ok"}${r.note ? ` (${r.note})` : ""}`, true);
  } catch (e) { say(e.message); }
  pollCampaign();  // the action may have changed the state either way
}));

function showCampaign(c) {
  $("progress").hidden = false;
  $("p-id").textContent = c.id;
  $("p-name").textContent = c.name;
  $("p-status").textContent = c.status;
  $("p-run").textContent = c.run
    ? `worker: ${c.run.state}${c.run.detail ? ` (${c.run.detail})` : ""}` : "";
  $("p-bar").max = c.poses_total || 1;
  $("p-bar").value = c.poses_done;
  $("p-count").textContent = `${c.poses_done} / ${c.poses_total} poses`;
  $("calibrate").disabled = c.status !== "done";
  if (["planned", "paused", "failed"].includes(c.status)) $("start").disabled = false;
}

async function pollCampaign() {
  clearTimeout(state.campaignTimer);
  const id = state.campaign;
  try {
    const c = await api("GET", `/campaigns/${id}`);
    if (id !== state.campaign) return;  // another campaign was created meanwhile
    showCampaign(c);
    if (TERMINAL.has(c.status) && !(c.run && c.run.state === "running")) return;
  } catch (e) { say(e.message); }
  state.campaignTimer = setTimeout(pollCampaign, POLL_MS);
}

$("job-form").addEventListener("submit", async (ev) => {
  ev.preventDefault();
  try {
    const j = await api("POST", "/jobs", { campaign_id: state.campaign, method: $("j-method").value });
    state.job = j.id;
    $("results").hidden = true;
    showJob(j);
    pollJob();
  } catch (e) { say(e.message); }
});

function showJob(j) {
  $("j-state").textContent = `job ${j.id} (${j.method}): ${j.state}${j.reason ? `: ${j.reason}` : ""}`;
}

async function pollJob() {
  clearTimeout(state.jobTimer);
  const id = state.job;
  try {
    const j = await api("GET", `/jobs/${id}`);
    if (id !== state.job) return;
    showJob(j);
    if (j.state === "done") return showResults(j);
    if (j.state === "failed") return say(`job ${j.id} failed: ${j.reason}`);
  } catch (e) { say(e.message); }
  state.jobTimer = setTimeout(pollJob, POLL_MS);
}

function showResults(j) {
  $("results").hidden = false;
  $("model-link").href = j.model_url;
  $("model-link").setAttribute("download", `job-${j.id}.model.json`);
  const charts = `/api/charts/jobs/${j.id}`;
  $("boxplot").src = `${charts}/boxplot.png`;
  $("errors").src = `${charts}/errors.png`;
  $("table3").innerHTML = '<p class="muted">computing every method on this campaign...</p>';
  api("GET", `${charts.slice(4)}/table3`).then(renderTable3)
    .catch((e) => { $("table3").textContent = e.message; });
}

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

showTokenState();
