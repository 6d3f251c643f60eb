// The semattnet viewer: per-pixel depth readout, layer toggles and a 3D point cloud (Plotly).
// Frame data lives in viewer/NNN.js files that call semattnetViewer.add(index, data); they are
// loaded on demand with <script> tags, so the page works from file:// without a server.
"use strict";
(function () {
  const meta = JSON.parse(document.getElementById("viewer-meta").textContent);
  const byId = (id) => document.getElementById(id);
  const decoded = {};
  const waiting = {};
  const state = { frame: null, layer: null, scale: 1 };

  window.addEventListener("error", (e) => {
    document.body.dataset.error = String(e.message || e);
  });
  window.semattnetViewer = {
    add: (index, data) => {
      if (waiting[index]) waiting[index](data);
    },
  };

  function bytes(b64) {
    const s = atob(b64);
    const out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }

  async function inflate(b64) {
    const stream = new Blob([bytes(b64)]).stream().pipeThrough(new DecompressionStream("deflate"));
    return new Response(stream).arrayBuffer();
  }

  const TYPES = { u8: Uint8Array, u16: Uint16Array, i16: Int16Array };

  async function decode(raw) {
    const arrays = {};
    for (const a of raw.arrays) arrays[a.key] = new TYPES[a.dtype](await inflate(a.data));
    return Object.assign({}, raw, { decoded: arrays });
  }

  function load(index) {
    if (decoded[index]) return Promise.resolve(decoded[index]);
    return new Promise((resolve, reject) => {
      waiting[index] = (data) =>
        decode(data).then((f) => {
          decoded[index] = f;
          resolve(f);
        }, reject);
      const s = document.createElement("script");
      s.src = meta.frames[index].src;
      s.onerror = () => reject(new Error("cannot load " + s.src));
      document.head.appendChild(s);
    });
  }

  function showLayer(key) {
    const f = state.frame;
    const layer = f.layers.find((l) => l.key === key) || f.layers[0];
    state.layer = layer.key;
    byId("base").src = layer.png;
    byId("base").alt = layer.label;
    byId("view").dataset.layer = layer.key;
    for (const input of document.querySelectorAll("#layers input")) input.checked = input.value === layer.key;
  }

  function layerButtons(f) {
    const box = byId("layers");
    box.textContent = "";
    for (const l of f.layers) {
      const label = document.createElement("label");
      const input = document.createElement("input");
      input.type = "radio";
      input.name = "layer";
      input.value = l.key;
      input.addEventListener("change", () => showLayer(l.key));
      label.append(input, " " + l.label);
      box.append(label);
    }
  }

  function setScale() {
    const f = state.frame;
    const chosen = byId("zoom").value;
    state.scale = chosen === "fit" ? Math.max(1, Math.floor(byId("main").clientWidth / f.width)) : Number(chosen);
    const view = byId("view");
    view.style.width = f.width * state.scale + "px";
    view.style.height = f.height * state.scale + "px";
    view.dataset.scale = String(state.scale);
  }

  function readoutRows(f) {
    const table = byId("readout");
    table.textContent = "";
    for (const v of f.values) {
      const tr = document.createElement("tr");
      tr.dataset.key = v.key;
      const th = document.createElement("th");
      th.textContent = v.label;
      const td = document.createElement("td");
      td.textContent = "-";
      tr.append(th, td);
      table.append(tr);
    }
  }

  function readout(u, v) {
    const f = state.frame;
    byId("pixel").textContent = "pixel (u " + u + ", v " + v + ")";
    byId("pixel").dataset.u = String(u);
    byId("pixel").dataset.v = String(v);
    for (const val of f.values) {
      const raw = f.decoded[val.key][v * f.width + u];
      const td = document.querySelector('#readout tr[data-key="' + val.key + '"] td');
      const empty = val.zero_is_empty && raw === 0;
      td.dataset.value = empty ? "" : String(raw * val.scale);
      td.textContent = empty ? "none" : (raw * val.scale).toFixed(val.digits) + " " + val.unit;
    }
  }

  function onMove(e) {
    const f = state.frame;
    const r = byId("view").getBoundingClientRect();
    const u = Math.floor((e.clientX - r.left) / state.scale);
    const v = Math.floor((e.clientY - r.top) / state.scale);
    if (u >= 0 && v >= 0 && u < f.width && v < f.height) readout(u, v);
  }

  function xyz(a) {
    // camera frame (x right, y down, z forward, cm) -> plot axes (x right, y forward, z up, m)
    const x = [], y = [], z = [];
    for (let i = 0; i < a.length; i += 3) {
      x.push(a[i] / 100);
      y.push(a[i + 2] / 100);
      z.push(-a[i + 1] / 100);
    }
    return { x, y, z };
  }

  function cloud(f) {
    const div = byId("cloud");
    if (!f.cloud) {
      Plotly.purge(div);
      div.hidden = true;
      byId("cloud-note").textContent = f.cloud_note;
      return;
    }
    div.hidden = false;
    byId("cloud-note").textContent = f.cloud.note;
    const rgb = f.decoded.cloud_rgb;
    const colors = [];
    for (let i = 0; i < rgb.length; i += 3) colors.push("rgb(" + rgb[i] + "," + rgb[i + 1] + "," + rgb[i + 2] + ")");
    const pred = Object.assign(xyz(f.decoded.cloud_xyz), {
      type: "scatter3d", mode: "markers", name: f.cloud.label, marker: { size: 1.6, color: colors },
    });
    const lidar = Object.assign(xyz(f.decoded.lidar_xyz), {
      type: "scatter3d", mode: "markers", name: "LiDAR points", marker: { size: 2.2, color: "#e0115f" },
    });
    const layout = {
      margin: { l: 0, r: 0, t: 0, b: 0 }, legend: { x: 0, y: 1 },
      scene: { aspectmode: "data", xaxis: { title: { text: "right [m]" } }, yaxis: { title: { text: "forward [m]" } },
               zaxis: { title: { text: "up [m]" } }, camera: { eye: { x: -0.4, y: -2.2, z: 1.1 } } },
    };
    return Plotly.react(div, [pred, lidar], layout, { displaylogo: false, responsive: true });
  }

  async function show(index) {
    document.body.dataset.ready = "loading";
    const f = await load(index);
    state.frame = f;
    byId("frame-title").textContent = f.name + (f.note ? " (" + f.note + ")" : "");
    byId("overlay").src = f.lidar_overlay;
    layerButtons(f);
    readoutRows(f);
    setScale();
    showLayer(f.layers.some((l) => l.key === state.layer) ? state.layer : f.default_layer);
    readout(Math.floor(f.width / 2), Math.floor(f.height / 2));
    await cloud(f);
    document.body.dataset.ready = String(index);
  }

  function init() {
    const select = byId("frame");
    meta.frames.forEach((fr, i) => select.add(new Option(fr.name, String(i))));
    select.addEventListener("change", () => show(Number(select.value)));
    byId("zoom").addEventListener("change", setScale);
    byId("lidar").addEventListener("change", (e) => {
      byId("overlay").hidden = !e.target.checked;
    });
    byId("view").addEventListener("mousemove", onMove);
    show(0).catch((e) => {
      document.body.dataset.error = String(e);
      console.error(e);
    });
  }

  init();
})();
