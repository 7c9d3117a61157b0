// The 3-D viewer's side of viewer.html: start rerun's viewer (wasm) on the canvas, then show
// what the page (cell3d.js) posts: a recording's bytes, a pose to go to. No network but this
// service: the recording comes as bytes, never as a URL.
"use strict";

// The viewer asks rerun.io for analytics and GitHub for a newer release: on a cell's network
// nothing is to leave this service, so any request elsewhere fails here, before it is sent.
const ownFetch = window.fetch.bind(window);
window.fetch = function (resource, init) {
  const url = new URL(resource instanceof Request ? resource.url : String(resource), location.href);
  if (url.origin !== location.origin && url.protocol !== "blob:" && url.protocol !== "data:") {
    return Promise.reject(new TypeError(`the 3-D viewer stays on this service (not ${url.origin})`));
  }
  return ownFetch(resource, init);
};

const status = document.getElementById("status");
const canvas = document.getElementById("canvas");
let handle = null;
let channels = 0;  // each recording its own channel (rerun refuses to reopen an id)
let current = null;
let currentKey = null;  // the page's name for what the channel shows (job-N, campaign-N)
let pieces = 0;  // .rrd pieces sent to the current channel
const waiting = [];  // messages posted before the viewer started

/** The viewer's state for the page and for tests: loading, started, shown, failed. */
function setState(s, words) {
  document.body.dataset.state = s;
  status.hidden = s === "started" || s === "shown";
  if (words) status.textContent = words;
  if (window.parent !== window) window.parent.postMessage({ kind: "viewer", state: s, words }, location.origin);
}

// Protocol buffers, as much as the viewer control API needs (rerun's viewer_control.proto):
// varints and length-delimited fields.
function varint(n) {
  const out = [];
  let v = BigInt(n);
  do {
    let b = Number(v & 0x7fn);
    v >>= 7n;
    if (v > 0n) b |= 0x80;
    out.push(b);
  } while (v > 0n);
  return out;
}
const field = (n, bytes) => [...varint((n << 3) | 2), ...varint(bytes.length), ...bytes];
const number = (n, v) => [...varint(n << 3), ...varint(v)];
const text = (s) => [...new TextEncoder().encode(s)];

/** ViewerControlRequest{set_time_cursor: {timeline: {name}, time: {time}, play_state: PAUSED}}. */
function setTimeCursor(timeline, time) {
  const request = [...field(2, field(1, text(timeline))), ...field(3, number(1, time)), ...number(5, 1)];
  return new Uint8Array(field(6, request));
}

function show(m) {
  if (m.kind === "recording" || (m.kind === "more" && m.key !== currentKey)) {
    channels += 1;
    const id = `${m.key}-${channels}`;
    if (current) handle.close_channel(current);
    current = id;
    currentKey = m.key;
    pieces = 0;
    handle.open_channel(id, m.title);
  }
  if (m.kind === "recording" || m.kind === "more") {
    // a whole .rrd each time: a campaign's pieces share its recording id, so they add up
    handle.send_rrd_to_channel(current, new Uint8Array(m.bytes));
    pieces += 1;
    document.body.dataset.source = m.key;
    document.body.dataset.pieces = String(pieces);
    if (m.key.startsWith("job-")) document.body.dataset.job = m.key.slice(4);
    setState("shown");
  } else if (m.kind === "pose") {
    goToPose(m.index, 20);
  }
}

/** The time cursor to a pose; again a little later while the recording just sent is still
 * being read (its timeline "pose" not there yet). */
function goToPose(index, tries) {
  handle.viewer_control(setTimeCursor("pose", index))
    .then(() => { document.body.dataset.pose = String(index); })
    .catch((e) => {
      if (tries > 0) setTimeout(() => goToPose(index, tries - 1), 500);
      else console.warn("the viewer did not go to pose", index, e);
    });
}

window.addEventListener("message", (ev) => {
  if (ev.origin !== location.origin || !ev.data || !ev.data.kind) return;
  if (handle) show(ev.data); else waiting.push(ev.data);
});

async function start() {
  if (typeof wasm_bindgen === "undefined") {
    setState("failed", "The 3-D viewer's code did not load from the service.");
    return;
  }
  try {
    await wasm_bindgen({ module_or_path: fetch("/viewer/re_viewer_bg.wasm") });
    const query = new URLSearchParams(location.search);
    handle = new wasm_bindgen.WebHandle({
      url: [], hide_welcome_screen: true, enable_history: false, persist: false,
      check_for_updates_on_startup: false,
      render_backend: query.get("renderer"),  // webgl or webgpu; the viewer picks when absent
      theme: query.get("theme"),
    });
    await handle.start(canvas);
    canvas.hidden = false;
    setState("started");
    setInterval(() => {
      if (handle.has_panicked()) setState("failed", `The 3-D viewer stopped: ${handle.panic_message()}`);
    }, 1000);
    waiting.splice(0).forEach(show);
  } catch (e) {
    setState("failed", `The 3-D viewer could not start in this browser: ${e}`);
  }
}

setState("loading");
window.addEventListener("load", start);  // after re_viewer.js, which follows this script
