// Coupler live map: draws the line once, then applies the server's event stream.
// Events (see mapserver/web.py): snapshot | step | reading | run, each with a sequence number.
"use strict";

(() => {
  const MAX_ROWS = 10000;
  const $ = (id) => document.getElementById(id);
  const rows = document.querySelector("#readings tbody");
  const scroller = $("readings-scroll");

  // Read by the browser tests; handy in the devtools console too.
  const view = {
    ready: false,
    seq: 0,
    nextIndex: 0,
    snapshots: 0,
    train: null,
    trainLatLng: () => (trainMarker ? trainMarker.getLatLng() : null),
    map: null, // the Leaflet map, set below
    following: () => follow.checked,
    trainOnScreen: () => {
      if (!trainMarker) return null;
      const p = map.latLngToContainerPoint(trainMarker.getLatLng());
      const size = map.getSize();
      return { x: p.x, y: p.y, width: size.x, height: size.y };
    },
    readingIds: () => Array.from(rows.children, (tr) => Number(tr.dataset.baliseId)),
    camera: null, // the camera panel's state: frame number, size, time, detection boxes
    localisation: null, // a localisation's estimate, interval and the truth beside them
    estimateLatLng: () => (estimateMarker ? estimateMarker.getLatLng() : null),
    frameLoaded: 0, // number of the frame the <img> shows once loaded
  };
  window.coupler = view;

  const map = L.map("map", { crs: L.CRS.EPSG3857, minZoom: 1, maxZoom: 19 });
  view.map = map;
  L.control.scale({ imperial: false, maxWidth: 160 }).addTo(map);
  let trainMarker = null;
  let estimateMarker = null;
  let intervalLine = null;
  let source = null;

  // Follow the train: keep it in the middle of the map; dragging the map ends following.
  const follow = $("follow");
  follow.addEventListener("change", () => {
    if (follow.checked && trainMarker) map.panTo(trainMarker.getLatLng(), { animate: false });
  });
  map.on("dragstart", () => { follow.checked = false; });

  async function fetchJson(url) {
    const response = await fetch(url, { cache: "no-store" });
    if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
    return response.json();
  }

  async function init() {
    const [config, geojson] = await Promise.all([
      fetchJson("/api/config"),
      fetchJson("/api/geojson"),
    ]);
    if (config.tile_url) {
      L.tileLayer(config.tile_url, {
        attribution: config.tile_attribution || "",
        maxZoom: 19,
      }).addTo(map);
    } else {
      map.getContainer().classList.add("no-tiles"); // plain background, no tile server
    }
    drawLine(geojson);
    view.ready = true;
    connect();
  }

  function drawLine(geojson) {
    const kind = (k) => (feature) => feature.properties.kind === k;
    const track = L.geoJSON(geojson, {
      filter: kind("track"),
      style: { color: "#3a4a5c", weight: 4, opacity: 0.9 },
    }).addTo(map);
    L.geoJSON(geojson, {
      filter: kind("balise"),
      pointToLayer: (feature, latlng) => {
        const p = feature.properties;
        return L.circleMarker(latlng, {
          radius: 4, color: "#7a5b00", weight: 1, fillColor: "#f2c14e", fillOpacity: 1,
        }).bindTooltip(
          `Balise ${p.id} · group ${p.group} · ${p.distance_m.toFixed(1)} m`,
        );
      },
    }).addTo(map);
    L.geoJSON(geojson, {
      filter: kind("station"),
      pointToLayer: (feature, latlng) =>
        L.circleMarker(latlng, {
          radius: 6, color: "#1d232b", weight: 2, fillColor: "#ffffff", fillOpacity: 1,
        }).bindTooltip(feature.properties.name, {
          permanent: true, direction: "top", offset: [0, -6], className: "station-label",
        }),
    }).addTo(map);
    map.fitBounds(track.getBounds(), { padding: [24, 24] });
  }

  function connect() {
    source = new EventSource("/api/events");
    source.onopen = () => setConnection("live", false);
    source.onerror = () => setConnection("reconnecting", true); // EventSource retries itself
    source.onmessage = (message) => apply(JSON.parse(message.data));
  }

  function resync() {
    // A reading is missing: start over from a fresh snapshot.
    source.close();
    setConnection("resyncing", false);
    connect();
  }

  function apply(event) {
    if (event.type === "snapshot") {
      view.snapshots += 1;
      view.seq = event.seq;
      setReadings(event.readings);
      showRun(event.run);
      showTrain(event.train);
      showCamera(event.camera);
      showLocalisation(event.localisation);
      return;
    }
    if (event.seq <= view.seq) return; // already in the snapshot
    view.seq = event.seq;
    if (event.type === "reading") {
      if (event.reading.index !== view.nextIndex) return resync();
      addReading(event.reading);
      $("reading-count").textContent = String(view.nextIndex);
    } else if (event.type === "step") {
      showRun(event.run);
      showTrain(event.train);
      showCamera(event.camera);
      showLocalisation(event.localisation);
    } else if (event.type === "run") {
      if (event.reset) setReadings([]);
      showRun(event.run);
    }
  }

  function setReadings(readings) {
    rows.replaceChildren();
    view.nextIndex = readings.length ? readings[readings.length - 1].index + 1 : 0;
    const fragment = document.createDocumentFragment();
    for (const reading of readings) fragment.appendChild(row(reading));
    rows.appendChild(fragment);
    scroller.scrollTop = scroller.scrollHeight;
  }

  function addReading(reading) {
    const atBottom = scroller.scrollTop + scroller.clientHeight >= scroller.scrollHeight - 4;
    rows.appendChild(row(reading));
    while (rows.children.length > MAX_ROWS) rows.firstElementChild.remove();
    view.nextIndex = reading.index + 1;
    if (atBottom) scroller.scrollTop = scroller.scrollHeight;
  }

  function row(reading) {
    const tr = document.createElement("tr");
    tr.dataset.baliseId = String(reading.balise_id);
    tr.dataset.groupId = String(reading.group_id);
    tr.dataset.index = String(reading.index);
    for (const text of [
      reading.time_s.toFixed(1),
      String(reading.balise_id),
      String(reading.group_id),
      reading.distance_m.toFixed(1),
    ]) {
      const td = document.createElement("td");
      td.textContent = text;
      tr.appendChild(td);
    }
    return tr;
  }

  function showRun(run) {
    $("run-id").textContent = run.run_id || "–";
    const status = $("run-status");
    status.className = run.status;
    status.textContent =
      run.status === "idle" ? "waiting for a run"
        : run.status === "ended" ? `ended (${run.reason})` : run.status;
    if (run.status !== "idle") {
      const stop = run.stop_time_s == null ? "" : ` / ${run.stop_time_s.toFixed(1)}`;
      $("sim-time").textContent = `${run.time_s.toFixed(1)}${stop} s`;
    }
    $("rtf").textContent = run.realtime_factor == null ? "–" : `${run.realtime_factor.toFixed(2)}×`;
    $("reading-count").textContent = String(run.readings_total);
  }

  function showTrain(train) {
    view.train = train;
    if (!train) {
      $("speed").textContent = "–";
      $("distance").textContent = "–";
      return;
    }
    $("speed").textContent =
      `${train.speed_mps.toFixed(1)} m/s (${(train.speed_mps * 3.6).toFixed(0)} km/h)`;
    $("distance").textContent = `${train.distance_m.toFixed(1)} m`;
    const latlng = [train.latitude_deg, train.longitude_deg];
    if (follow.checked) map.panTo(latlng, { animate: false });
    if (trainMarker) {
      trainMarker.setLatLng(latlng);
    } else {
      trainMarker = L.marker(latlng, {
        icon: L.divIcon({ className: "train-marker", iconSize: [16, 16] }),
        title: "Train",
        keyboard: false,
        zIndexOffset: 1000,
      }).addTo(map);
      trainMarker.getElement().id = "train";
    }
  }

  // A localisation under test: its confidence interval as the stretch of track it covers (red
  // when the true front end is outside it), its estimate as a marker, the figures in the panel.
  function showLocalisation(loc) {
    view.localisation = loc || null;
    if (!loc) return;
    $("localisation-panel").hidden = false;
    const width = loc.max_m - loc.min_m;
    $("estimate").textContent = `${loc.estimate_m.toFixed(1)} m`;
    $("interval").textContent =
      `${loc.min_m.toFixed(1)} – ${loc.max_m.toFixed(1)} m (${width.toFixed(1)} m wide)`;
    $("truth").textContent = loc.true_m == null ? "–"
      : `${loc.true_m.toFixed(1)} m (error ${(loc.estimate_m - loc.true_m).toFixed(1)} m)`;
    const inside = $("inside");
    inside.textContent = loc.inside == null ? "–" : loc.inside ? "yes" : "NO: integrity lost";
    inside.className = loc.inside === false ? "bad" : "";
    const linking = $("linking");
    linking.textContent = loc.linking_error ? "LINKING ERROR" : "ok";
    linking.className = loc.linking_error ? "bad" : "";
    const colour = loc.inside === false ? "#b3261e" : "#1f6fd1";
    if (loc.interval.length > 1) {
      if (intervalLine) {
        intervalLine.setLatLngs(loc.interval);
        intervalLine.setStyle({ color: colour });
      } else {
        intervalLine = L.polyline(loc.interval, {
          color: colour, weight: 12, opacity: 0.55, lineCap: "butt", interactive: false,
        }).addTo(map);
        intervalLine.getElement().id = "interval-line";
      }
    }
    if (!loc.estimate) return;
    if (estimateMarker) {
      estimateMarker.setLatLng(loc.estimate);
    } else {
      estimateMarker = L.marker(loc.estimate, {
        icon: L.divIcon({ className: "estimate-marker", html: "<i></i>", iconSize: [14, 14] }),
        title: "Estimated front end",
        keyboard: false,
        zIndexOffset: 1100,
      }).addTo(map);
      estimateMarker.getElement().id = "estimate-marker";
    }
  }

  // The camera panel: the frame the latest detections belong to, their boxes drawn over it.
  const frameImage = $("camera-frame");
  const boxes = $("camera-boxes");
  frameImage.addEventListener("load", () => {
    view.frameLoaded = Number(frameImage.dataset.frame);
  });

  function showCamera(camera) {
    view.camera = camera || null;
    if (!camera) return;
    $("camera-panel").hidden = false;
    if (frameImage.dataset.frame !== String(camera.frame)) {
      frameImage.dataset.frame = String(camera.frame);
      frameImage.src = `/api/frame.jpg?n=${camera.frame}`;
    }
    boxes.setAttribute("viewBox", `0 0 ${camera.width} ${camera.height}`);
    const svg = "http://www.w3.org/2000/svg";
    const shapes = [];
    for (const [index, box] of camera.detections.entries()) {
      const rect = document.createElementNS(svg, "rect");
      const pad = 3; // around the blob, so the balise itself stays visible
      rect.setAttribute("x", box.left - pad);
      rect.setAttribute("y", box.top - pad);
      rect.setAttribute("width", box.right - box.left + 1 + 2 * pad);
      rect.setAttribute("height", box.bottom - box.top + 1 + 2 * pad);
      rect.classList.add("detection");
      // labels of neighbours (a balise group) alternate sides so they do not overlap
      const label = document.createElementNS(svg, "text");
      const right = index % 2 === 0;
      label.setAttribute("x", right ? box.right + pad + 4 : box.left - pad - 4);
      label.setAttribute("y", box.bottom + pad);
      label.setAttribute("text-anchor", right ? "start" : "end");
      label.textContent = `${box.distance_ahead_m.toFixed(1)} m`;
      shapes.push(rect, label);
    }
    boxes.replaceChildren(...shapes);
    const seen = camera.judged ? `, ${camera.detections.length} balise(s) detected` : "";
    $("camera-caption").textContent = `${camera.sensor} at ${camera.time_s.toFixed(1)} s${seen}`;
  }

  function setConnection(text, lost) {
    const element = $("connection");
    element.textContent = text;
    element.className = lost ? "lost" : "";
  }

  init().catch((error) => {
    setConnection(`failed: ${error.message}`, true);
    console.error(error);
  });
})();
