// Live updates: GET /api/events (server-sent events) read with fetch() and a stream reader, since
// EventSource cannot send the bearer token; each event refreshes only what it concerns. The
// stream is reconnected with a backoff, and only while it is down does the page poll, slowly.
"use strict";

const RETRY_MIN_MS = 1000;
const RETRY_MAX_MS = 30000;
const SLOW_POLL_MS = 5000;  // only while the stream is down
const FINAL_JOB = new Set(["done", "failed"]);
const live = {
  up: false, retryMs: RETRY_MIN_MS, abort: null, pollTimer: null,
  seen: {},  // events received, by type (the page's own count, for a person or a test to read)
  watchers: new Map(),  // job id -> {job, fns}: pages parts following that job
  lastJob: new Map(),  // job id -> its last event, for a watcher registered after it came
  noticed: new Set(),  // job ids whose end was announced
  pending: new Map(),  // key -> timer of a coalesced refresh
};

/** Parse server-sent events from text; onEvent(type, data) for each complete one; the rest
 * (an event not yet ended by its blank line) is returned for the next chunk. */
function parseSse(text, onEvent) {
  const blocks = text.split(/\r\n\r\n|\n\n|\r\r/);
  const rest = blocks.pop();
  for (const block of blocks) {
    let type = "message";
    const data = [];
    for (const line of block.split(/\r\n|\n|\r/)) {
      if (!line || line.startsWith(":")) continue;  // a comment: the keep-alive ping
      const i = line.indexOf(":");
      const field = i < 0 ? line : line.slice(0, i);
      const value = i < 0 ? "" : line.slice(i + 1).replace(/^ /, "");
      if (field === "event") type = value;
      else if (field === "data") data.push(value);
    }
    if (data.length) onEvent(type, data.join("\n"));
  }
  return rest;
}

/** Open the stream (if there is a token and none is open); on a drop, try again later. */
async function connectEvents() {
  const token = sessionStorage.getItem(TOKEN_KEY);
  if (!token || live.abort) return;
  const ctl = new AbortController();
  live.abort = ctl;
  try {
    const r = await fetch("/api/events", {
      headers: { Accept: "text/event-stream", Authorization: `Bearer ${token}` },
      signal: ctl.signal, cache: "no-store",
    });
    if (r.status === 401) $("token-state").textContent = "the service refuses this token (see below)";
    if (!r.ok) throw new Error(`GET /api/events: ${r.status}`);
    // The server subscribes before answering: from here on no event is missed.
    live.retryMs = RETRY_MIN_MS;
    setLive(true);
    const reader = r.body.getReader();
    const decoder = new TextDecoder();
    let rest = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) break;
      rest = parseSse(rest + decoder.decode(value, { stream: true }), dispatch);
    }
  } catch (e) { /* a drop or a refusal: retried below */ }
  if (live.abort === ctl) live.abort = null;
  if (ctl.signal.aborted) return;  // closed on purpose (a new token)
  setLive(false);
  setTimeout(connectEvents, live.retryMs);
  live.retryMs = Math.min(RETRY_MAX_MS, live.retryMs * 2);
}

/** Close the stream and open it again (the token changed). */
function restartEvents() {
  if (live.abort) live.abort.abort();
  live.abort = null;
  connectEvents();
}

/** The stream went up or down: say so, and poll slowly only while it is down. On coming up,
 * read once what may have changed while no event could arrive. */
function setLive(up) {
  live.up = up;
  $("live").textContent = up ? "live" : `updates every ${SLOW_POLL_MS / 1000} s (reconnecting)`;
  $("live").className = up ? "live" : "live down";
  clearInterval(live.pollTimer);
  if (up) {
    catchUp();
  } else {
    live.pollTimer = setInterval(catchUp, SLOW_POLL_MS);
  }
}

/** Read the current campaign, the followed jobs and the lists once (quietly: a service that
 * does not answer is already said by the stream's state). */
async function catchUp() {
  if (campaignLive()) refreshCampaign();
  refreshCampaigns().catch(() => {});
  refreshJobs().catch(() => {});
  for (const id of live.watchers.keys()) {
    try {
      const j = await api("GET", `/jobs/${id}`);
      if (FINAL_JOB.has(j.state)) endJob(j.id, j, true); else tellWatchers(j);
    } catch (e) { /* the next round asks again */ }
  }
}

/** Run fn once after ms, however many events ask for it meanwhile. */
function later(key, fn, ms) {
  if (live.pending.has(key)) return;
  live.pending.set(key, setTimeout(() => { live.pending.delete(key); fn(); }, ms));
}

function dispatch(type, text) {
  let e;
  try { e = JSON.parse(text); } catch (err) { return; }
  live.seen[type] = (live.seen[type] || 0) + 1;
  if (type === "job") onJobEvent(e);
  else if (type.startsWith("campaign.")) onCampaignEvent(type, e);
}

// campaign.pose (each pose done, with the counts), campaign.adaptive (an adaptive campaign's
// step: its predicted accuracy), campaign.state (each state the engine enters) and campaign.run
// (a run wound up, its summary stored): server/acquisition/acquire.py, server/service/acquisitions.py.
function onCampaignEvent(type, e) {
  if (type === "campaign.pose") heardPoses(e.campaign_id, e.poses_done, e.poses_total);
  if (e.campaign_id === state.campaign) {
    if (type === "campaign.adaptive") {
      showAdaptive(e, state.target);  // plan.js; the target as the campaign's settings had it
    } else if (type === "campaign.pose") {
      showPoseCount(e.poses_done, e.poses_total);
      // a pose done means the run moves: a status still shown otherwise is stale (the start
      // request's answer, "planned", can land after the state event it preceded)
      if ($("p-status").textContent !== "running") later("campaign", refreshCampaign, 100);
      later("readings", () => refreshReadings(state.campaign), 700);
      later("estimate", () => showTimeLeft(e.poses_done, e.poses_total), 700);
    } else {
      later("campaign", refreshCampaign, 100);
    }
  }
  later("campaigns", () => refreshCampaigns().catch(() => {}), type === "campaign.pose" ? 2000 : 300);
}

// job: a job's state, progress and reason (server/service/worker.py job_event).
function onJobEvent(e) {
  const j = { ...e, id: e.job_id };
  live.lastJob.set(j.id, j);
  if (FINAL_JOB.has(j.state)) endJob(j.id, null, true);
  else tellWatchers(j);
  later("jobs", () => refreshJobs().catch(() => {}), 500);
}

/** Follow a job: fn(job) at each change, the last time with the whole job (its result URLs)
 * once it has ended. The job as the API answered (its id, state, method...). */
function watchJob(job, fn) {
  const w = live.watchers.get(job.id) || { job, fns: [] };
  w.fns.push(fn);
  live.watchers.set(job.id, w);
  const seen = live.lastJob.get(job.id);
  if (FINAL_JOB.has(job.state) || (seen && FINAL_JOB.has(seen.state))) endJob(job.id);
  else if (seen) tellWatchers(seen);
  else fn(job);
}

function tellWatchers(j) {
  const w = live.watchers.get(j.id);
  if (!w) return;
  w.job = { ...w.job, ...j };
  w.fns.forEach((fn) => fn(w.job));
}

/** A job ended: its watchers get the whole job from the job list (one request, which the
 * history shows too), and a notice says so if it was seen ending (not found ended). */
async function endJob(id, job = null, announce = false) {
  if (!job) {
    try { job = (await refreshJobs()).find((x) => x.id === id); } catch (e) { return; }
  }
  if (!job) return;
  const w = live.watchers.get(id);
  live.watchers.delete(id);
  if (w) w.fns.forEach((fn) => fn(job));
  // every calibration's end is announced; a diagnosis's only if it is the page's own
  const announced = job.kind === "calibration" || (job.kind === "diagnosis" && id === state.diag);
  if (announce && announced && !live.noticed.has(id)) {
    live.noticed.add(id);
    jobNotice(job);
  }
}

/** The banner at the top: a job ended; a click shows its results (or its reason). */
function jobNotice(j) {
  const what = `job ${j.id} (${j.kind === "diagnosis" ? "diagnosis" : j.method})`;
  const box = $("notice");
  const text = $("notice-text");
  box.className = j.state === "done" ? "ok" : "failed";
  text.textContent = j.state === "done" ? `${what} done — view results`
    : `${what} failed: ${j.reason || "no reason given"}`;
  text.dataset.job = j.id;
  text.dataset.kind = j.kind;
  box.hidden = false;
  flash(box);
}

$("notice-text").addEventListener("click", async () => {
  const id = Number($("notice-text").dataset.job);
  $("notice").hidden = true;
  const target = $("notice-text").dataset.kind === "diagnosis" ? "diagnosis" : "results";
  if (id !== state.job && !(target === "diagnosis" && id === state.diag)) await openJob(id);
  const el = $(target).hidden ? $("calibration") : $(target);
  el.scrollIntoView({ behavior: "smooth", block: "start" });
  flash(el);
});

$("notice-close").addEventListener("click", () => { $("notice").hidden = true; });
