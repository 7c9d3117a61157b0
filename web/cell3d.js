// The cell in 3-D under Results: rerun's web viewer (viewer.html, served by the service) in a
// frame, shown on request (its code is 43 MB). The recording is fetched here with the tab's
// token and handed to the frame as bytes, so no URL ever carries it. Uses app.js's globals ($,
// request, say, state).
"use strict";

const cell3d = { job: null, shown: null, ready: false, frame: null, poses: 0 };

/** The shown job's recording: offered in 3-D if it has one; sent at once if the viewer is open. */
function showCell3d(j) {
  cell3d.job = j.recording_url ? j.id : null;
  $("c3").hidden = !j.recording_url;
  $("c3-pose").value = "";
  cell3d.poses = j.poses_total || 0;
  if (cell3d.frame && cell3d.job !== null) sendRecording();
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

async function sendRecording() {
  const job = cell3d.job;
  if (!cell3d.ready || job === null || cell3d.shown === job) return;
  cell3d.shown = job;
  $("c3-state").textContent = `loading job ${job}'s recording...`;
  try {
    const bytes = await (await request("GET", `/jobs/${job}/recording`)).arrayBuffer();
    if (cell3d.job !== job) return;  // another job was shown meanwhile
    cell3d.frame.contentWindow.postMessage({ kind: "recording", job, bytes }, location.origin, [bytes]);
    $("c3-state").textContent = `job ${job}: drag to turn, scroll to zoom; double-click resets the view`;
    $("c3-go").disabled = false;
  } catch (e) {
    cell3d.shown = null;
    $("c3-state").textContent = "";
    say(e);
  }
}

/** The viewer at one pose: its time cursor on the recording's timeline "pose". */
function goToPose(index) {
  if (!cell3d.frame || cell3d.shown === null) return;
  cell3d.frame.contentWindow.postMessage({ kind: "pose", index }, location.origin);
  $("c3-pose").value = String(index);
  $("c3-state").textContent = `job ${cell3d.shown}: pose ${index} in the view "one pose at a time"`;
}

window.addEventListener("message", (ev) => {
  if (ev.origin !== location.origin || !cell3d.frame || ev.source !== cell3d.frame.contentWindow) return;
  const m = ev.data || {};
  if (m.kind !== "viewer") return;
  if (m.state === "started") { cell3d.ready = true; sendRecording(); }
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
