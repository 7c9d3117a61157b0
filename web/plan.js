// Planning from the page: the campaign form's fields as POST /api/campaigns takes them
// (CampaignCreate), and the campaign's estimated duration before and after it is planned.
"use strict";

// The duration model: each pose is a move, a settle and, per SMR, an aim and a measurement, and
// the first poses search for their SMRs until the predictor knows where the cell is:
//   search + poses x (move + settle + SMRs x (aim + samples / sample rate)).
// Before planning the move is a typical one; once planned, the plan's own tour time
// (settings.plan.move_time_s.after, drivers/planning.py) replaces poses x move. Adaptive settle
// ends once two successive readings agree, at most the pause. The figures are the simulated
// cell's, fitted on campaigns run in its virtual time (3 SMRs; measured against estimated):
// 20 poses, 1000 samples, 10 s pause: fixed 356 s / 355 s, ordered 340 s / 343 s, adaptive
// 249 s / 245 s; 120 poses ordered, 500 samples, 5 s pause: 982 s / 1017 s. A real tracker's
// rate and search times differ: the page says "about".
const EST = {
  moveS: 1.9,  // a random pose after another (mean of a 20-pose plan's tour)
  moveOrderedS: 1.3,  // the same, in the shortest-tour order
  aimS: 0.2,  // point at the predicted SMR and lock on, per SMR
  searchS: 45,  // the first poses' searches, once per campaign
  rateHz: 1000,  // tracker samples per second
  adaptiveSettleS: 4.5,  // adaptive settle on the simulated cell's arm
};
// SMRs of the cell each campaign was planned on from this page (the readings tell later).
const plannedSmrs = new Map();

/** The campaign form as CampaignCreate takes it (server/api/schemas.py). */
function planBody() {
  const body = {
    poses: Number($("c-poses").value), seed: Number($("c-seed").value),
    settle: $("c-settle").value, cell_id: $("c-cell").value || "default",
    pause_s: Number($("c-pause").value), samples: Number($("c-samples").value),
    order: $("c-order").checked,
  };
  if ($("c-name").value.trim()) body.name = $("c-name").value.trim();
  if (Number($("c-choose").value) > 0) body.choose_from = Number($("c-choose").value);
  if (Number($("c-target").value) > 0) body.target_accuracy_mm = Number($("c-target").value);
  return body;
}

/** An adaptive campaign's latest step (a campaign.adaptive event, or the last of its settings'
 * adaptive_steps) beside its target: the predicted held-out RMS, live; the effects its fit
 * includes (named by a checkpoint's diagnosis); why it stopped. */
function showAdaptive(step, target) {
  const el = $("p-adaptive");
  el.hidden = !step && !target;
  if (el.hidden) return;
  if (!step) {
    el.textContent = `target ${target} mm: predicted accuracy after the seed poses`;
    return;
  }
  el.textContent = `predicted held-out RMS ${step.predicted_mm.toFixed(4)} mm at ${step.poses} `
    + `poses (target ${target} mm, floor ${step.floor_mm.toFixed(4)} mm)`
    + (step.effects && step.effects.length ? `, fitted with ${step.effects.join(", ")}` : "")
    + (step.stop ? ` — stopped (${step.reason}): ${step.message}` : "");
}

/** Seconds at each pose besides the move: [typical, at most]. */
function poseSeconds(o, smrs) {
  const measure = smrs * (EST.aimS + o.samples / EST.rateHz);
  const settle = o.settle === "adaptive" ? Math.min(o.pause_s, EST.adaptiveSettleS) : o.pause_s;
  return [settle + measure, o.pause_s + measure];
}

/** "12 min", "40 s", "2 h 5 min". */
function duration(s) {
  if (!Number.isFinite(s)) return "?";
  if (s < 90) return `${Math.round(s)} s`;
  const min = Math.round(s / 60);
  return min < 120 ? `${min} min` : `${Math.floor(min / 60)} h ${min % 60} min`;
}

/** Typical and longest estimate as text: "about 6 min" or "about 4 min (at most 6 min)"; on a
 * simulated cell, said to be a real cell's (the simulator runs in virtual time: seconds). */
function estimateText([typical, most], simulated = false) {
  return `about ${duration(typical)}` + (most > typical * 1.05 ? ` (at most ${duration(most)})` : "")
    + (simulated ? " on a real cell; simulated here in seconds" : "");
}

/** The form's estimate, before anything is planned. */
function showEstimate() {
  const o = planBody();
  const smrs = cellSmrs.get(o.cell_id);
  if (!smrs || !(o.poses > 0)) { $("c-estimate").textContent = ""; return; }
  const move = o.order ? EST.moveOrderedS : EST.moveS;
  const [typ, most] = poseSeconds(o, smrs);
  $("c-estimate").textContent = `Estimated duration: ${estimateText([
    EST.searchS + o.poses * (move + typ), EST.searchS + o.poses * (move + most)],
  cellSimulated.get(o.cell_id))}: `
    + `${o.poses} poses x (move ~${move} s + ${o.settle} settle `
    + `${o.settle === "adaptive" ? `~${Math.min(o.pause_s, EST.adaptiveSettleS)} s, at most ` : ""}`
    + `${o.pause_s} s + ${smrs} SMRs x (aim ~${EST.aimS} s + ${o.samples} samples at `
    + `${EST.rateHz} Hz)) + ~${EST.searchS} s while the first poses find the SMRs`;
}

document.querySelectorAll("#campaign-form input, #campaign-form select, #c-cell").forEach(
  (el) => el.addEventListener("input", showEstimate));

/** SMRs of a campaign: from its readings once there are some, else from its cell. */
function smrsOf(c) {
  if (c.poses_done > 0 && readingsSeen.total > 0 && c.id === state.campaign) {
    return Math.max(1, Math.round(readingsSeen.total / c.poses_done));
  }
  return plannedSmrs.get(c.id) || cellSmrs.get($("c-cell").value) || 3;
}

/** A planned campaign's estimate: its plan's tour time plus the time at each pose; [typical,
 * at most] seconds, or null if its settings say too little. */
function plannedEstimate(c) {
  const o = c.settings && c.settings.options;
  if (!o) return null;
  const plan = c.settings.plan || {};
  const tour = plan.move_time_s && plan.move_time_s.after;
  const moves = typeof tour === "number" ? tour
    : c.poses_total * (o.order ? EST.moveOrderedS : EST.moveS);
  const [typ, most] = poseSeconds(o, smrsOf(c));
  const fixed = EST.searchS + moves;
  return { typical: fixed + c.poses_total * typ, most: fixed + c.poses_total * most,
           moves, planned: typeof tour === "number", simulated: !!c.simulated };
}

/** The estimate under the progress bar: the whole campaign, and what is left while it runs. */
function showPlannedEstimate(c) {
  const e = plannedEstimate(c);
  state.estimate = e;
  if (!e) { $("p-estimate").textContent = ""; return; }
  $("p-estimate").textContent = `Estimated duration: ${estimateText([e.typical, e.most],
    c.simulated)}`
    + (e.planned ? ` (moves ${duration(e.moves)} on the planned tour)` : "");
  showTimeLeft(c.poses_done, c.poses_total, c.status);
}

function showTimeLeft(done, total, status = state.status) {
  const e = state.estimate;
  const running = !FINAL.has(status) && done > 0 && done < total;
  const left = e && running ? duration(e.typical * (1 - done / total)) : null;
  // a simulated run's time left is a real cell's: the simulator itself is done in seconds
  $("p-left").textContent = left === null ? ""
    : `; about ${left} left${e.simulated ? " on a real cell" : ""}`;
}
