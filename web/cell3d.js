// The cell in 3-D: rerun's web viewer (viewer.html, served by the service) in a frame, shown on
// request (its code is 43 MB). What it shows: the shown job's recording, or else the current
// campaign's readings, live (GET /campaigns/{id}/recording in pieces, one per poll, as poses
// finish). Bytes are fetched here with the tab's token and handed to the frame, so no URL ever
// carries them. Uses app.js's globals ($, request, say, state).
"use strict";

const cell3d = {
  source: null,  // {kind: "job" | "campaign", id}: what the viewer is to show
  shown: null,  // the key of the source whose bytes the viewer has
  ready: false, frame: null,
  nextPose: 0,  // a campaign's: where its next piece starts
  pulling: false, again: false,  // one pull at a time; a pose heard meanwhile asks for another
  pose: null,  // a pose asked for before the viewer had the recording
  labels: new Map(),  // a job's recording: pose label -> index on its timeline "pose"
};

const sourceKey = (s) => (s ? `${s.kind}-${s.id}` : null);
const sourceName = (s) => (s.kind === "job" ? `job ${s.id}` : `campaign ${s.id}`);

/** What the viewer shows from now on (null: nothing, the section hidden). */
function setCell3dSource(src) {
  if (sourceKey(src) === sourceKey(cell3d.source)) return;
  cell3d.source = src;
  cell3d.shown = null;
  cell3d.nextPose = 0;
  $("c3").hidden = !src;
  $("c3-go").disabled = true;
  $("c3-pose").value = "";
  cell3d.labels = new Map();
  linkPoses();
  if (src && src.kind === "job") loadPoseLabels(src);
  if (cell3d.frame && src) loadCell3d();
}

/** A job recording's poses by label, so that tables naming poses by label link to it. */
async function loadPoseLabels(src) {
  try {
    const poses = await api("GET", `/jobs/${src.id}/recording/poses`);
    if (sourceKey(cell3d.source) !== sourceKey(src)) return;
    // a label of the calibration's own poses first: a held-out campaign may reuse it
    poses.forEach((p) => { if (!cell3d.labels.has(p.label)) cell3d.labels.set(p.label, p.index); });
    linkPoses();
  } catch (e) {
    console.warn("the tables' poses stay unlinked to the 3-D viewer:", e);  // nothing is lost
  }
}

/** Table cells naming a pose by label (data-pose-label): a button to it where the viewer's
 * recording has that pose, plain text elsewhere. */
function linkPoses() {
  document.querySelectorAll("td[data-pose-label]").forEach((td) => {
    const label = td.dataset.poseLabel;
    const index = cell3d.labels.get(label);
    if (index === undefined) td.textContent = label;
    else td.replaceChildren(poseButton(index, label));
  });
}

/** The shown job's recording, if it has one; else the current campaign's, live. */
function showCell3d(j) {
  if (j.recording_url) setCell3dSource({ kind: "job", id: j.id });
  else followCampaign3d();
}

/** The current campaign in the viewer, unless a job's results are shown; new poses pulled. */
function followCampaign3d() {
  const job = state.jobInfo;
  if (!$("results").hidden && job && job.recording_url) return;  // the calibration's instead
  setCell3dSource(state.campaign === null ? null : { kind: "campaign", id: state.campaign });
  pullCampaign3d();
}

/** Open the viewer's frame (once); the recording follows when it says it started. */
function openCell3d() {
  if (cell3d.frame) return;
  cell3d.frame = $("c3-frame");
  cell3d.frame.hidden = false;
  $("c3-open").hidden = true;
  $("c3-state").textContent = "loading the 3-D viewer...";
  cell3d.frame.src = "viewer.html";
}

function post(m, transfer = []) {
  cell3d.frame.contentWindow.postMessage(m, location.origin, transfer);
}

function loadCell3d() {
  if (!cell3d.ready || !cell3d.source) return;
  if (cell3d.source.kind === "job") sendRecording(); else pullCampaign3d();
}

async function sendRecording() {
  const src = cell3d.source;
  const key = sourceKey(src);
  if (cell3d.shown === key) return;
  cell3d.shown = key;
  $("c3-state").textContent = `loading job ${src.id}'s recording...`;
  try {
    const bytes = await (await request("GET", `/jobs/${src.id}/recording`)).arrayBuffer();
    if (sourceKey(cell3d.source) !== key) return;  // another was shown meanwhile
    post({ kind: "recording", key, title: `calibration job ${src.id}`, bytes }, [bytes]);
    $("c3-state").textContent = `job ${src.id}: drag to turn, scroll to zoom; double-click resets the view`;
    shownReady();
  } catch (e) {
    cell3d.shown = null;
    $("c3-state").textContent = "";
    say(e);
  }
}

/** The campaign's poses finished since the last piece, added to its recording in the viewer. */
async function pullCampaign3d() {
  if (!cell3d.ready || !cell3d.source || cell3d.source.kind !== "campaign") return;
  if (cell3d.pulling) { cell3d.again = true; return; }
  cell3d.pulling = true;
  try {
    do {
      cell3d.again = false;
      const src = cell3d.source;
      const key = sourceKey(src);
      const from = cell3d.nextPose;
      const r = await request("GET", `/campaigns/${src.id}/recording?from_pose=${from}`);
      const bytes = await r.arrayBuffer();
      if (sourceKey(cell3d.source) !== key || cell3d.nextPose !== from) continue;
      cell3d.nextPose = Number(r.headers.get("X-Next-Pose") || from);
      if (bytes.byteLength) {
        // the first piece opens the recording; the next ones add to it
        const kind = from === 0 ? "recording" : "more";
        post({ kind, key, title: `campaign ${src.id}, live`, bytes }, [bytes]);
        cell3d.shown = key;
      }
      $("c3-state").textContent = `campaign ${src.id}: ${cell3d.nextPose} poses measured in the `
        + "view, each added as it is done";
      if (cell3d.shown === key) shownReady();
    } while (cell3d.again && cell3d.source && cell3d.source.kind === "campaign");
  } catch (e) {
    say(e);
  } finally {
    cell3d.pulling = false;
  }
}

/** The viewer has the source's bytes: poses may be chosen (one asked for earlier goes now). */
function shownReady() {
  $("c3-go").disabled = false;
  if (cell3d.pose !== null) { const p = cell3d.pose; cell3d.pose = null; goToPose(p); }
}

/** The viewer at one pose: its time cursor on the recording's timeline "pose". */
function goToPose(index) {
  if (!cell3d.frame || cell3d.shown === null) { cell3d.pose = index; return; }
  post({ kind: "pose", index });
  $("c3-pose").value = String(index);
  $("c3-state").textContent = `${sourceName(cell3d.source)}: pose ${index}`
    + (cell3d.source.kind === "job" ? ' in the view "one pose at a time"' : " in blue");
}

/** A table's pose as a button: the viewer opened (if it is not) at that pose. */
function poseButton(index, text) {
  const b = Object.assign(document.createElement("button"), {
    type: "button", className: "pose-link", textContent: text,
  });
  b.dataset.pose = String(index);
  b.setAttribute("aria-label", `show pose ${text} in the 3-D viewer`);
  return b;
}

document.addEventListener("click", (ev) => {
  const b = ev.target.closest && ev.target.closest("button.pose-link");
  if (!b) return;
  openCell3d();
  $("c3").scrollIntoView({ block: "start" });
  goToPose(Number(b.dataset.pose));
});

window.addEventListener("message", (ev) => {
  if (ev.origin !== location.origin || !cell3d.frame || ev.source !== cell3d.frame.contentWindow) return;
  const m = ev.data || {};
  if (m.kind !== "viewer") return;
  if (m.state === "started") { cell3d.ready = true; loadCell3d(); }
  if (m.state === "failed") {
    cell3d.ready = false;
    $("c3-state").textContent = m.words || "the 3-D viewer failed";
  }
});

$("c3-open").addEventListener("click", openCell3d);
$("c3-pose-form").addEventListener("submit", (ev) => {
  ev.preventDefault();
  const n = Number($("c3-pose").value);
  if (Number.isInteger(n) && n >= 0) goToPose(n);
});
