// The run monitor's page: the run's state inlined into the page (painted at once), then one
// server-sent event stream (/api/events?channels=...), whose first frame is that small state
// again, whose second is the whole history and whose later frames carry only what is new.
// Picking a channel opens a new stream (its history comes with it). The header never waits
// for the chart library (loaded async); the charts do. Camera channels show their latest
// frame (/api/frame/NAME, a PNG), fetched again when the run has moved and the last one is in.
"use strict";

const MAX_POINTS = 4000; // per chart; beyond, every other point is dropped (as the server does)
const COLORS = ["#2a7de1", "#e1582a", "#2e9b4f", "#9b2e8f", "#b58400", "#2ab5b5", "#555", "#c93a3a"];
const view = {
  picked: new URLSearchParams(location.search).get("channels")?.split(",").filter(Boolean) || [],
  members: [], channels: [], units: {},
  latency: null, latencyData: null,
  values: {}, // channel -> {chart, data: [[t...], [v...]]}
  cameras: {}, // frame channel -> {img, loading, shown: the run time of the frame asked for}
  source: null, frames: 0, time: null,
};
window.monitor = view; // for tests and the curious

function text(id, value) { document.getElementById(id).textContent = value; }
function fmt(x, digits = 4) { return x === null || x === undefined ? "–" : Number(x).toPrecision(digits); }
// a time of the run as the user wrote its grid (49.1, not 49.1000): the shortest decimal of the
// double, as the server's JSON and results.csv write it
function seconds(x) { return x === null || x === undefined ? "–" : String(x); }
function duration(s) {
  if (s === null || s === undefined || !isFinite(s)) return "–";
  s = Math.round(s);
  return s < 60 ? `${s} s` : s < 3600 ? `${Math.floor(s / 60)} min ${s % 60} s` : `${Math.floor(s / 3600)} h ${Math.floor(s / 60) % 60} min`;
}

function chartWidth() { return Math.max(300, document.querySelector("main > div").clientWidth - 40); }

function thin(data) {
  if (data[0].length <= MAX_POINTS) return data;
  return data.map((column) => column.filter((_, i) => i % 2 === 0));
}

function append(data, times, columns) {
  for (let i = 0; i < times.length; i++) {
    data[0].push(times[i]);
    columns.forEach((column, k) => data[k + 1].push(column[i]));
  }
  return thin(data);
}

function showHeader(h) {
  const status = document.getElementById("status");
  status.textContent = h.status;
  status.className = `status ${h.status}`;
  const waiting = h.waiting_for ? Object.entries(h.waiting_for).map(([n, a]) => `waiting for ${n} at ${a}`).join("; ") : "";
  text("reason", h.reason || waiting);
  text("time", seconds(h.time));
  text("stop", seconds(h.stop_time));
  const share = Math.max(0, Math.min(1, h.progress || 0));
  document.getElementById("progress").style.width = `${share * 100}%`;
  text("percent", `${(share * 100).toFixed(1)} %`);
  text("rtf", h.realtime_factor ? `${fmt(h.realtime_factor, 3)}×` : "–");
  text("elapsed", duration(h.elapsed_s));
  text("eta", duration(h.eta_s));
  text("run", h.run_id ? `run ${h.run_id}` : "");
  const body = document.querySelector("#latency-table tbody");
  body.innerHTML = "";
  const costs = h.cost_ms || {};
  for (const [member, ms] of Object.entries(h.latency_ms || {})) {
    const row = body.insertRow();
    row.insertCell().textContent = member;
    for (const value of [ms, costs[member] ?? null]) {
      const cell = row.insertCell();
      cell.className = "num";
      cell.textContent = value === null ? "–" : `${fmt(value, 3)} ms`;
    }
  }
}

function showLayout(layout) {
  view.members = layout.members;
  view.channels = layout.channels;
  view.units = Object.fromEntries(layout.channels.map((c) => [c.name, c.unit]));
  const list = document.getElementById("channels");
  list.innerHTML = "";
  for (const channel of layout.channels) {
    const label = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.value = channel.name;
    box.checked = view.picked.includes(channel.name);
    box.addEventListener("change", () => pick(channel.name, box.checked));
    label.append(box, ` ${channel.name}${channel.unit ? ` [${channel.unit}]` : ""}`);
    label.title = channel.name;
    list.append(label);
  }
  filterChannels();
  showCameras(layout.frames || []);
  if (view.latency) { view.latency.destroy(); view.latency = null; }
  view.latencyData = [[], ...layout.members.map(() => [])];
  if (layout.members.length) {
    view.latency = new uPlot({
      width: chartWidth(), height: 220, scales: { x: { time: false } },
      series: [{ label: "t [s]" }, ...layout.members.map((m, i) => ({ label: m, stroke: COLORS[i % COLORS.length], width: 1.5 }))],
      axes: [{}, { label: "ms" }],
    }, view.latencyData, document.getElementById("latency-chart"));
  }
}

function showCameras(names) {
  const list = document.getElementById("camera-list");
  list.innerHTML = "";
  view.cameras = {};
  document.getElementById("cameras").hidden = !names.length;
  for (const name of names) {
    const figure = document.createElement("figure");
    const img = document.createElement("img");
    img.alt = `latest frame of ${name}`;
    img.dataset.channel = name;
    const caption = document.createElement("figcaption");
    caption.textContent = name;
    figure.append(img, caption);
    list.append(figure);
    const camera = { img, loading: false, shown: null };
    const done = () => { camera.loading = false; refreshCameras(view.time); }; // caught up?
    img.addEventListener("load", done);
    img.addEventListener("error", done); // no frame yet (204)
    view.cameras[name] = camera;
  }
}

function refreshCameras(time) {
  view.time = time;
  if (time === null || time === undefined) return;
  for (const [name, camera] of Object.entries(view.cameras)) {
    if (camera.loading || camera.shown === time) continue;
    camera.loading = true;
    camera.shown = time;
    camera.img.src = `/api/frame/${encodeURIComponent(name)}?t=${time}`;
  }
}

function filterChannels() {
  const needle = document.getElementById("filter").value.toLowerCase();
  for (const label of document.querySelectorAll("#channels label")) {
    label.style.display = label.title.toLowerCase().includes(needle) ? "" : "none";
  }
}

function resetValueCharts() {
  for (const entry of Object.values(view.values)) entry.chart.destroy();
  view.values = {};
  const box = document.getElementById("value-charts");
  box.innerHTML = view.picked.length ? "" : '<p id="hint">Pick channels on the left to chart them live.</p>';
  view.picked.forEach((name, i) => {
    const div = document.createElement("div");
    div.dataset.channel = name;
    box.append(div);
    const data = [[], []];
    const unit = view.units[name] || "";
    const chart = new uPlot({
      title: name, width: chartWidth(), height: 200, scales: { x: { time: false } },
      series: [{ label: "t [s]" }, { label: name, stroke: COLORS[i % COLORS.length], width: 1.5 }],
      axes: [{}, { label: unit }],
    }, data, div);
    view.values[name] = { chart, data };
  });
}

const chartsReady = new Promise((resolve) => {
  if (window.uPlot) resolve();
  else document.getElementById("uplot").addEventListener("load", resolve);
});

function onFrame(frame) {
  view.frames++;
  showHeader(frame.header);
  chartsReady.then(() => { draw(frame); refreshCameras(frame.header.time); }); // in order
}

function showUnknown(names) {
  const notice = document.getElementById("notice");
  notice.hidden = !names.length;
  notice.textContent = names.length ? `?channels= in this page's address names ` +
    `${names.join(", ")}: no channel of this run that can be charted; pick from the list on the left.` : "";
}

function draw(frame) {
  if (frame.layout) { showLayout(frame.layout); resetValueCharts(); showUnknown(frame.unknown_channels || []); }
  if (frame.latency && view.latency) {
    view.latencyData = append(view.latencyData, frame.latency.t, view.members.map((m) => frame.latency.series[m]));
    view.latency.setData(view.latencyData);
  }
  if (frame.values) {
    for (const [name, series] of Object.entries(frame.values.series)) {
      const entry = view.values[name];
      if (!entry) continue;
      entry.data = append(entry.data, frame.values.t, [series]);
      entry.chart.setData(entry.data);
    }
  }
}

function connect() {
  if (view.source) view.source.close();
  const query = view.picked.length ? `?channels=${encodeURIComponent(view.picked.join(","))}` : "";
  view.source = new EventSource(`/api/events${query}`);
  view.source.onmessage = (event) => onFrame(JSON.parse(event.data));
  view.source.onerror = () => {
    const status = document.getElementById("status");
    if (["completed", "terminated", "failed", "aborted"].includes(status.textContent)) {
      view.source.close(); // the run ended and its server has gone: keep the last picture
    } else if (view.source.readyState === EventSource.CLOSED) {
      // answered but refused (503): the monitor serves a limited number of pages at once
      status.textContent = "not streaming";
      status.className = "status";
      text("reason", "the monitor refused this page's stream: it serves at most 16 pages at " +
        "once; close another page and reload this one");
    } else {
      status.textContent = "reconnecting";
      status.className = "status";
    }
  };
}

function pick(name, on) {
  view.picked = on ? [...view.picked, name] : view.picked.filter((n) => n !== name);
  const url = new URL(location.href);
  if (view.picked.length) url.searchParams.set("channels", view.picked.join(","));
  else url.searchParams.delete("channels");
  history.replaceState(null, "", url);
  connect(); // its first frame brings the history of every picked channel
}

document.getElementById("filter").addEventListener("input", filterChannels);
const inlined = document.getElementById("state");
if (inlined) showHeader(JSON.parse(inlined.textContent).header);
connect();
