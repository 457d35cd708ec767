// bsn view's page: reads the JSON messages of /ws (see services/view/view_state.hpp) and shows the body in 3D, the
// joint angles of the last 10 s and the state of every node. Earth frame ENU (z up), quaternions (w, x, y, z)
// sensor-to-earth, as everywhere in bsn.
"use strict";

const PLOT_SECONDS = 10;
const FLAG_RESTING = 1, FLAG_MAG_REJECTED = 2, FLAG_STALE = 4, FLAG_INITIALISING = 8;

// Everything the page knows, also read by the browser test (window.bsnView).
const view = {
  connected: false,
  messages: 0,
  segments: {},  // name -> {node, q, ts, err, flags, truth, mesh, ghost}
  joints: {},    // name -> {parent, child, axes, ts, deg, row, chart}
  nodes: {},     // node -> {seg, rate, stale, calib}
  parentOf: {},  // child segment -> parent segment (from the joint angles)
};
window.bsnView = view;

// ---- 3D scene --------------------------------------------------------------------------------------------------
const missing = [];
if (typeof THREE === "undefined") missing.push("three.js (libjs-three)");
if (typeof Chart === "undefined") missing.push("Chart.js (libjs-chart.js)");
if (missing.length) document.getElementById("missing").textContent = "missing: " + missing.join(", ");

let scene = null, camera = null, renderer = null, controls = null;
function initScene() {
  const host = document.getElementById("scene");
  scene = new THREE.Scene();
  scene.background = new THREE.Color(0xdde3ea);
  camera = new THREE.PerspectiveCamera(45, host.clientWidth / host.clientHeight, 0.05, 50);
  camera.up.set(0, 0, 1);  // ENU: z up
  camera.position.set(1.4, -1.7, 1.2);
  try {
    renderer = new THREE.WebGLRenderer({antialias: true, preserveDrawingBuffer: true});
  } catch (e) {
    document.getElementById("missing").textContent = "no WebGL in this browser: " + e.message;
    return;
  }
  renderer.setSize(host.clientWidth, host.clientHeight);
  host.appendChild(renderer.domElement);
  if (THREE.OrbitControls) {
    controls = new THREE.OrbitControls(camera, renderer.domElement);
    controls.target.set(0, 0, 0.6);
    controls.update();
  }
  const grid = new THREE.GridHelper(4, 4, 0x888888, 0xaaaaaa);
  grid.rotation.x = Math.PI / 2;  // three's grid lies in x-z; the floor is x-y
  scene.add(grid);
  scene.add(new THREE.AxesHelper(0.5));  // x red (east), y green (north), z blue (up)
  scene.add(new THREE.AmbientLight(0xffffff, 0.55));
  const sun = new THREE.DirectionalLight(0xffffff, 0.6);
  sun.position.set(1, -2, 3);
  scene.add(sun);
}

// Segment size by name (m): length along the segment's local -z (distal), and width. The body model carries no
// lengths; these are typical adult proportions.
function segmentSize(name) {
  const n = name.toLowerCase();
  if (n.includes("pelvis")) return [0.12, 0.30];
  if (n.includes("thigh")) return [0.42, 0.12];
  if (n.includes("shank") || n.includes("shin")) return [0.40, 0.10];
  if (n.includes("foot")) return [0.20, 0.09];
  if (n.includes("trunk") || n.includes("torso") || n.includes("thorax")) return [0.45, 0.30];
  if (n.includes("head")) return [0.22, 0.18];
  if (n.includes("forearm")) return [0.26, 0.07];
  if (n.includes("arm")) return [0.30, 0.08];
  return [0.30, 0.10];
}

function makeSolid(name, ghost) {
  const [len, width] = segmentSize(name);
  const geometry = new THREE.BoxGeometry(width, Math.min(width, 0.12), len);
  geometry.translate(0, 0, -len / 2);  // the proximal end at the origin, the segment along -z
  const colour = new THREE.Color().setHSL((hash(name) % 360) / 360, 0.55, 0.5);
  const material = ghost ? new THREE.MeshBasicMaterial({color: 0x222222, wireframe: true, transparent: true,
                                                        opacity: 0.5})
                         : new THREE.MeshLambertMaterial({color: colour});
  const mesh = new THREE.Mesh(geometry, material);
  mesh.userData.length = len;
  scene.add(mesh);
  return mesh;
}

function hash(s) {
  let h = 7;
  for (let i = 0; i < s.length; i++) h = (h * 31 + s.charCodeAt(i)) >>> 0;
  return h;
}

function setQuaternion(obj, q) { obj.quaternion.set(q[1], q[2], q[3], q[0]); }  // three: (x, y, z, w)

// Places the solids along the chain: a root at 1 m above the floor, every child at its parent's distal end (a
// child of the pelvis at its left or right hip, by a name ending in _l or _r).
function layout(kind) {
  const placed = {};
  const place = (name, depth) => {
    if (placed[name] || depth > 32) return placed[name];
    const s = view.segments[name];
    const obj = s && s[kind];
    if (!obj) return null;
    const parent = view.parentOf[name];
    const pobj = parent && view.segments[parent] && view.segments[parent][kind];
    if (pobj) place(parent, depth + 1);
    if (!pobj) {
      obj.position.set(0, 0, 1.0);
    } else if (parent.toLowerCase().includes("pelvis")) {
      const side = /_l$|left/i.test(name) ? 1 : /_r$|right/i.test(name) ? -1 : 0;
      const off = new THREE.Vector3(0, 0.1 * side, -0.06).applyQuaternion(pobj.quaternion);
      obj.position.copy(pobj.position).add(off);
    } else {
      const off = new THREE.Vector3(0, 0, -pobj.userData.length).applyQuaternion(pobj.quaternion);
      obj.position.copy(pobj.position).add(off);
    }
    placed[name] = obj;
    return obj;
  };
  for (const name in view.segments) place(name, 0);
}

// ---- tables and plots ------------------------------------------------------------------------------------------
function row(tableId, key, cells) {
  const body = document.querySelector("#" + tableId + " tbody");
  let tr = body.querySelector('tr[data-key="' + CSS.escape(key) + '"]');
  if (!tr) {
    tr = document.createElement("tr");
    tr.dataset.key = key;
    for (let i = 0; i < cells; i++) tr.appendChild(document.createElement("td"));
    body.appendChild(tr);
  }
  return tr;
}

function flagText(f) {
  const out = [];
  if (f & FLAG_RESTING) out.push("resting");
  if (f & FLAG_MAG_REJECTED) out.push("mag rejected");
  if (f & FLAG_STALE) out.push("stale");
  if (f & FLAG_INITIALISING) out.push("initialising");
  return out.join(", ");
}

const axisNames = {x: "x", y: "y", z: "z"};
function makeChart(name, j) {
  if (typeof Chart === "undefined") return null;
  const box = document.createElement("div");
  box.className = "plot";
  const canvas = document.createElement("canvas");
  box.appendChild(canvas);
  document.getElementById("plots").appendChild(box);
  const colours = ["#c33", "#393", "#33c"];
  const axes = (j.axes || "").split("");
  return new Chart(canvas, {
    type: "line",
    data: {datasets: [0, 1, 2].map(i => ({label: (i + 1) + ": about " + (axisNames[axes[i]] || "?"), data: [],
                                          borderColor: colours[i], borderWidth: 1.5, pointRadius: 0}))},
    options: {
      animation: false, responsive: true, maintainAspectRatio: false, parsing: false, normalized: true,
      plugins: {title: {display: true, text: name + " (" + j.parent + " → " + j.child + "), degrees"}},
      scales: {x: {type: "linear", title: {display: true, text: "s"}}, y: {title: {display: false}}},
    },
  });
}

// ---- messages --------------------------------------------------------------------------------------------------
let t0 = null;  // sensor time of the first joint sample, ns
function segment(name) {
  if (!view.segments[name]) view.segments[name] = {name: name};
  return view.segments[name];
}

function onOrientation(m) {
  const s = segment(m.seg);
  Object.assign(s, {node: m.node, q: m.q, ts: m.ts, flags: m.flags});
  if (m.err !== null) s.err = m.err;  // an estimate whose truth has not come (yet) keeps the last error shown
  if (scene && !s.mesh) s.mesh = makeSolid(m.seg, false);
  if (s.mesh) setQuaternion(s.mesh, m.q);
  const tr = row("segments", m.seg, 4);
  tr.cells[0].textContent = m.seg;
  tr.cells[1].textContent = m.node;
  tr.cells[2].textContent = s.err === undefined ? "–" : s.err.toFixed(1) + "°";
  tr.cells[3].textContent = flagText(m.flags);
}

function onTruth(m) {
  const s = segment(m.seg);
  s.truth = m.q;
  s.truthTs = m.ts;
  if (scene && !s.ghost) s.ghost = makeSolid(m.seg, true);
  if (s.ghost) setQuaternion(s.ghost, m.q);
}

function onJoint(m) {
  let j = view.joints[m.joint];
  if (!j) {
    j = view.joints[m.joint] = {hist: [[], [], []]};
  }
  Object.assign(j, {parent: m.parent, child: m.child, axes: m.axes, ts: m.ts, deg: m.deg, flags: m.flags});
  view.parentOf[m.child] = m.parent;
  if (!j.chart) j.chart = makeChart(m.joint, j);
  if (t0 === null) t0 = m.ts;
  const t = (m.ts - t0) / 1e9;
  for (let i = 0; i < 3; i++) {
    j.hist[i].push({x: t, y: m.deg[i]});
    while (j.hist[i].length && j.hist[i][0].x < t - PLOT_SECONDS) j.hist[i].shift();
  }
  const tr = row("joints", m.joint, 5);
  tr.dataset.ts = String(m.ts);
  tr.cells[0].textContent = m.joint;
  tr.cells[1].textContent = m.axes;
  for (let i = 0; i < 3; i++) tr.cells[2 + i].textContent = m.deg[i].toFixed(2);
}

function onStatus(m) {
  for (const n of m.nodes) view.nodes[n.node] = {seg: n.seg, rate: n.rate, stale: n.stale, calib: n.calib};
}

function drawNodes() {
  for (const node in view.nodes) {
    const n = view.nodes[node];
    const f = (view.segments[n.seg] || {}).flags || 0;
    const tr = row("nodes", node, 6);
    tr.cells[0].textContent = node + " (" + n.seg + ")";
    tr.cells[1].textContent = n.rate < 0 ? "?" : n.rate.toFixed(0) + " Hz";
    tr.cells[2].textContent = n.stale ? "STALE" : "no";
    tr.cells[2].className = n.stale ? "bad" : "";
    tr.cells[3].textContent = f & FLAG_MAG_REJECTED ? "yes" : "no";
    tr.cells[4].textContent = f & FLAG_RESTING ? "yes" : "no";
    tr.cells[5].textContent = n.calib ? n.calib : "none";
  }
}

function onMessage(m) {
  view.messages++;
  if (m.k === "o") onOrientation(m);
  else if (m.k === "t") onTruth(m);
  else if (m.k === "j") onJoint(m);
  else if (m.k === "s") onStatus(m);
}

function connect() {
  const ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  const status = document.getElementById("connection");
  ws.onopen = () => { view.connected = true; status.textContent = "live"; status.className = "good"; };
  ws.onclose = () => {
    view.connected = false;
    status.textContent = "disconnected, retrying…";
    status.className = "bad";
    setTimeout(connect, 1000);
  };
  ws.onmessage = ev => {
    let batch;
    try { batch = JSON.parse(ev.data); } catch (e) { return; }
    if (Array.isArray(batch)) batch.forEach(onMessage);
  };
}

// ---- drawing ---------------------------------------------------------------------------------------------------
let lastPlot = 0;
function frame(now) {
  requestAnimationFrame(frame);
  if (scene) {
    layout("mesh");
    layout("ghost");
    if (controls) controls.update();
    renderer.render(scene, camera);
  }
  if (now - lastPlot > 100) {  // plots and tables at 10 Hz: enough for the eye, cheap for 20 open pages
    lastPlot = now;
    for (const name in view.joints) {
      const j = view.joints[name];
      if (!j.chart) continue;
      for (let i = 0; i < 3; i++) j.chart.data.datasets[i].data = j.hist[i];
      j.chart.update("none");
    }
    drawNodes();
  }
}

// One line per joint and segment, for tests and scripts: "J name ts a b c" with the values as the table shows
// them, and "S name ts w x y z | ts w x y z | err" with the solid's and the truth ghost's orientation as drawn (and
// the sensor time of the sample each shows).
view.summary = () => {
  const out = [];
  document.querySelectorAll("#joints tbody tr").forEach(tr => {
    out.push(["J", tr.cells[0].textContent, tr.dataset.ts, tr.cells[2].textContent, tr.cells[3].textContent,
              tr.cells[4].textContent].join(" "));
  });
  const q = o => [o.quaternion.w, o.quaternion.x, o.quaternion.y, o.quaternion.z].join(" ");
  for (const name in view.segments) {
    const s = view.segments[name];
    if (!s.mesh) continue;
    out.push(["S", name, s.ts, q(s.mesh), "|", s.ghost ? s.truthTs + " " + q(s.ghost) : "none", "|",
              s.err === undefined ? "none" : s.err].join(" "));
  }
  return out.join("\n");
};

if (typeof THREE !== "undefined") initScene();
connect();
requestAnimationFrame(frame);
