// bsn view's page: reads the JSON messages of /ws (see services/view/view_state.hpp) and shows the body in 3D, the
// joint angles of the last 10 s and the state of every node. Earth frame ENU (z up), quaternions (w, x, y, z) to
// earth, as everywhere in bsn. One frame rule: an estimate with FLAG_SEGMENT_FRAME is its segment's ISB frame
// (X anterior, Y superior along the segment, Z right) and is drawn as the segment; one without is its sensor's frame
// and is drawn as the sensor (a box with its axes). The truth ghost is in the same frame as the estimate.
"use strict";

const PLOT_SECONDS = 10;
const FLAG_RESTING = 1, FLAG_MAG_REJECTED = 2, FLAG_STALE = 4, FLAG_INITIALISING = 8, FLAG_SEGMENT_FRAME = 32;

// Everything the page knows, also read by the browser test (window.bsnView).
const view = {
  connected: false,
  messages: 0,
  segments: {},  // name -> {node, q, ts, err, flags, truth, truthFlags, mesh, ghost, label}
  joints: {},    // name -> {parent, child, axes, ts, deg, names, anat, histAnat, histSeq, chart}
  sequenceAngles: false,  // plots and table: the axis-sequence angles instead of the named anatomical ones
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

// Segment size by name (m): length along the segment and width. The body model carries no lengths; these are
// typical adult proportions.
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
const isFoot = name => /foot/i.test(name);
const isUpward = name => /trunk|torso|thorax|head/i.test(name);  // drawn up from the joint, not down

// One drawable per segment and frame, each an Object3D whose origin is the joint to the parent:
// - the segment (ISB frame): a solid along its long axis Y, distal (down) from the joint (up for the trunk and head),
//   a foot forward along X; userData.distal: where its children hang (the trunk's: its top), in its own frame;
//   userData.up: its long axis;
// - the sensor (its own frame): a small box with the sensor's axes (x red, y green, z blue), placed along the chain
//   as if mounted the default way (x anterior, y left, z up), so that children hang along its -z.
function makeSegmentObject(name, ghost) {
  const [len, width] = segmentSize(name);
  const group = new THREE.Group();
  let geometry;
  if (isFoot(name)) {
    geometry = new THREE.BoxGeometry(len, 0.06, width);
    geometry.translate(len / 2 - 0.04, -0.05, 0);  // forward from the ankle, below it
  } else {
    geometry = new THREE.BoxGeometry(Math.min(width, 0.12), len, width);  // X depth, Y length, Z width
    geometry.translate(0, isUpward(name) ? len / 2 : -len / 2, 0);
  }
  const colour = new THREE.Color().setHSL((hash(name) % 360) / 360, 0.55, 0.5);
  const material = ghost ? new THREE.MeshBasicMaterial({color: 0x222222, wireframe: true, transparent: true,
                                                        opacity: 0.5})
                         : new THREE.MeshLambertMaterial({color: colour});
  group.add(new THREE.Mesh(geometry, material));
  group.userData.distal = new THREE.Vector3(0, isFoot(name) ? 0 : isUpward(name) ? len : -len, 0);
  group.userData.hipOffset = side => new THREE.Vector3(0, -0.06, -0.1 * side);  // ISB Z right: left is -Z
  group.userData.up = new THREE.Vector3(0, 1, 0);
  group.userData.frame = "segment";
  scene.add(group);
  return group;
}

function makeSensorObject(name, ghost) {
  const [len] = segmentSize(name);
  const group = new THREE.Group();
  const geometry = new THREE.BoxGeometry(0.06, 0.04, 0.02);
  const colour = new THREE.Color().setHSL((hash(name) % 360) / 360, 0.55, 0.5);
  const material = ghost ? new THREE.MeshBasicMaterial({color: 0x222222, wireframe: true, transparent: true,
                                                        opacity: 0.5})
                         : new THREE.MeshLambertMaterial({color: colour});
  group.add(new THREE.Mesh(geometry, material));
  group.add(new THREE.AxesHelper(ghost ? 0.08 : 0.12));
  group.userData.distal = new THREE.Vector3(0, 0, -len);
  group.userData.hipOffset = side => new THREE.Vector3(0, 0.1 * side, -0.06);
  group.userData.up = new THREE.Vector3(0, 0, 1);
  group.userData.frame = "sensor";
  scene.add(group);
  return group;
}

// A segment's name as a sprite that always faces the camera.
function makeLabel(name) {
  const canvas = document.createElement("canvas");
  canvas.width = 256;
  canvas.height = 64;
  const c = canvas.getContext("2d");
  c.font = "bold 30px sans-serif";
  c.fillStyle = "rgba(255,255,255,0.75)";
  c.fillRect(0, 8, Math.min(256, c.measureText(name).width + 16), 46);
  c.fillStyle = "#123";
  c.fillText(name, 8, 42);
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({map: new THREE.CanvasTexture(canvas), depthTest: false}));
  sprite.scale.set(0.24, 0.06, 1);
  sprite.center.set(0, 0.5);
  scene.add(sprite);
  return sprite;
}

function hash(s) {
  let h = 7;
  for (let i = 0; i < s.length; i++) h = (h * 31 + s.charCodeAt(i)) >>> 0;
  return h;
}

function setQuaternion(obj, q) { obj.quaternion.set(q[1], q[2], q[3], q[0]); }  // three: (x, y, z, w)

// The drawable of a segment for its frame (kind "mesh": the estimate, "ghost": the truth), made on first use; the
// other frame's is hidden.
function drawable(s, kind, segmentFrame) {
  const key = kind + (segmentFrame ? "Segment" : "Sensor");
  const ghost = kind === "ghost";
  if (!s[key]) s[key] = segmentFrame ? makeSegmentObject(s.name, ghost) : makeSensorObject(s.name, ghost);
  const other = s[kind + (segmentFrame ? "Sensor" : "Segment")];
  if (other) other.visible = false;
  s[key].visible = true;
  s[kind] = s[key];
  return s[key];
}

// Places the drawables along the chain: a root at 1 m above the floor, every child at its parent's distal end (a
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
      const off = side === 0 ? new THREE.Vector3(0, 0, 0) : pobj.userData.hipOffset(side);
      obj.position.copy(pobj.position).add(off.applyQuaternion(pobj.quaternion));
    } else {
      const off = pobj.userData.distal.clone().applyQuaternion(pobj.quaternion);
      obj.position.copy(pobj.position).add(off);
    }
    if (kind === "mesh" && s.label) s.label.position.copy(obj.position).add(new THREE.Vector3(0.08, 0, 0.02));
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

// The label of a joint's plotted series i: the anatomical angle's name and its positive direction (the name's first
// word), or the axis-sequence angle by its place and axis.
function seriesLabel(j, i) {
  if (!view.sequenceAngles && j.names && j.names.length === 3) {
    const n = j.names[i];
    return n + " (" + n.split("_")[0] + " +)";
  }
  const axes = (j.axes || "").split("");
  return ["1st", "2nd", "3rd"][i] + " about " + (axes[i] || "?");
}
const usesNames = j => !view.sequenceAngles && j.names && j.names.length === 3;
function series(j) { return usesNames(j) ? j.histAnat : j.histSeq; }

function makeChart(name, j) {
  if (typeof Chart === "undefined") return null;
  const box = document.createElement("div");
  box.className = "plot";
  const canvas = document.createElement("canvas");
  box.appendChild(canvas);
  document.getElementById("plots").appendChild(box);
  const colours = ["#c33", "#393", "#33c"];
  const title = () => name + " (" + j.parent + " → " + j.child + ")" + (j.anatomy ? ", " + j.anatomy : "") +
                      (j.side ? " " + j.side : "") + ", degrees";
  return new Chart(canvas, {
    type: "line",
    data: {datasets: [0, 1, 2].map(i => ({label: seriesLabel(j, i), data: [], borderColor: colours[i],
                                          borderWidth: 1.5, pointRadius: 0}))},
    options: {
      animation: false, responsive: true, maintainAspectRatio: false, parsing: false, normalized: true,
      plugins: {title: {display: true, text: title()}},
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
  const segmentFrame = (m.flags & FLAG_SEGMENT_FRAME) !== 0;
  if (s.segmentFrame !== undefined && s.segmentFrame !== segmentFrame) s.err = undefined;  // another frame's error
  Object.assign(s, {node: m.node, q: m.q, ts: m.ts, flags: m.flags, segmentFrame: segmentFrame});
  if (m.err !== null) s.err = m.err;  // an estimate whose truth has not come (yet) keeps the last error shown
  if (scene) {
    setQuaternion(drawable(s, "mesh", segmentFrame), m.q);
    if (!s.label) s.label = makeLabel(m.seg);
  }
  const tr = row("segments", m.seg, 5);
  tr.cells[0].textContent = m.seg;
  tr.cells[1].textContent = m.node;
  tr.cells[2].textContent = segmentFrame ? "segment" : "sensor";
  tr.cells[3].textContent = s.err === undefined ? "–" : s.err.toFixed(1) + "°";
  tr.cells[4].textContent = flagText(m.flags);
}

function onTruth(m) {
  const s = segment(m.seg);
  s.truth = m.q;
  s.truthTs = m.ts;
  s.truthFlags = m.flags || 0;
  if (scene) setQuaternion(drawable(s, "ghost", (s.truthFlags & FLAG_SEGMENT_FRAME) !== 0), m.q);
}

function onJoint(m) {
  let j = view.joints[m.joint];
  if (!j) {
    j = view.joints[m.joint] = {histAnat: [[], [], []], histSeq: [[], [], []]};
  }
  Object.assign(j, {parent: m.parent, child: m.child, axes: m.axes, ts: m.ts, deg: m.deg, flags: m.flags,
                    anat: m.anat || [0, 0, 0]});
  // The names come when they change (and in a new page's first messages); a message without them keeps the last.
  if (m.names !== undefined) Object.assign(j, {anatomy: m.anatomy || "", side: m.side || "", names: m.names});
  if (!j.names) j.names = [];
  view.parentOf[m.child] = m.parent;
  if (!j.chart) j.chart = makeChart(m.joint, j);
  if (t0 === null) t0 = m.ts;
  const t = (m.ts - t0) / 1e9;
  for (let i = 0; i < 3; i++) {
    j.histAnat[i].push({x: t, y: j.anat[i], ts: m.ts});
    j.histSeq[i].push({x: t, y: m.deg[i], ts: m.ts});
    for (const h of [j.histAnat[i], j.histSeq[i]])
      while (h.length && h[0].x < t - PLOT_SECONDS) h.shift();
  }
  const tr = row("joints", m.joint, 5);
  tr.dataset.ts = String(m.ts);
  tr.cells[0].textContent = m.joint;
  const named = usesNames(j);
  tr.cells[1].textContent = named ? j.anatomy + (j.side ? " " + j.side : "") : m.axes;
  for (let i = 0; i < 3; i++) {
    tr.cells[2 + i].textContent = (named ? j.anat[i] : m.deg[i]).toFixed(2);
    tr.cells[2 + i].title = seriesLabel(j, i);
  }
}

function onStatus(m) {
  for (const n of m.nodes) view.nodes[n.node] = {seg: n.seg, rate: n.rate, stale: n.stale, calib: n.calib};
}

// Per node: its segment, rate, stale, magnetometer rejected, resting, and its mounting: "aligned" once its estimates
// are in the segment frame (an alignment or a known mounting), else "default" (the sensor frame).
function drawNodes() {
  for (const node in view.nodes) {
    const n = view.nodes[node];
    const seg = view.segments[n.seg] || {};
    const f = seg.flags || 0;
    const tr = row("nodes", node, 6);
    tr.cells[0].textContent = node + " (" + n.seg + ")";
    tr.cells[1].textContent = n.rate < 0 ? "?" : n.rate.toFixed(0) + " Hz";
    tr.cells[2].textContent = n.stale ? "STALE" : "no";
    tr.cells[2].className = n.stale ? "bad" : "";
    tr.cells[3].textContent = f & FLAG_MAG_REJECTED ? "yes" : "no";
    tr.cells[4].textContent = f & FLAG_RESTING ? "yes" : "no";
    tr.cells[5].textContent = seg.flags === undefined ? "–" : f & FLAG_SEGMENT_FRAME ? "aligned" : "default";
    tr.cells[5].className = seg.flags !== undefined && f & FLAG_SEGMENT_FRAME ? "good" : "";
    tr.cells[5].title = n.calib ? "last calibration applied: " + n.calib : "no live calibration applied";
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
      const h = series(j);
      for (let i = 0; i < 3; i++) {
        j.chart.data.datasets[i].data = h[i];
        j.chart.data.datasets[i].label = seriesLabel(j, i);
      }
      j.chart.update("none");
    }
    drawNodes();
  }
}

// One line per joint and segment, for tests and scripts:
// "J name ts a b c | names n1 n2 n3 | plot ts p1 p2 p3" with the values as the table shows them, the series' names
// and the latest point of each plotted series (full precision, and its sensor time);
// "S name ts w x y z | ts w x y z | err | frame F | up x y z | truth_up x y z" with the drawn orientation of the
// estimate and of the truth ghost (and the sensor time of the sample each shows), the error, the frame it is drawn
// in (segment or sensor) and the world direction of the drawn long axis of each (segment: Y; sensor: z).
view.summary = () => {
  const out = [];
  document.querySelectorAll("#joints tbody tr").forEach(tr => {
    const j = view.joints[tr.cells[0].textContent] || {};
    const h = j.histAnat ? series(j) : [[], [], []];
    const last = h.map(s => s.length ? s[s.length - 1] : null);
    const named = j.histAnat && usesNames(j);
    out.push(["J", tr.cells[0].textContent, tr.dataset.ts, tr.cells[2].textContent, tr.cells[3].textContent,
              tr.cells[4].textContent, "| names", named ? j.names.join(" ") : "sequence " + j.axes, "| plot",
              last[0] ? last[0].ts : "none", last.map(p => p ? p.y : "none").join(" ")].join(" "));
  });
  const q = o => [o.quaternion.w, o.quaternion.x, o.quaternion.y, o.quaternion.z].join(" ");
  const up = o => { const v = o.userData.up.clone().applyQuaternion(o.quaternion); return [v.x, v.y, v.z].join(" "); };
  for (const name in view.segments) {
    const s = view.segments[name];
    if (!s.mesh) continue;
    out.push(["S", name, s.ts, q(s.mesh), "|", s.ghost ? s.truthTs + " " + q(s.ghost) : "none", "|",
              s.err === undefined ? "none" : s.err, "| frame", s.mesh.userData.frame, "| up", up(s.mesh),
              "| truth_up", s.ghost ? up(s.ghost) : "none"].join(" "));
  }
  return out.join("\n");
};

// The plots' and table's choice: named anatomical angles (default) or the axis-sequence angles.
const toggle = document.getElementById("sequence-angles");
if (toggle) toggle.addEventListener("change", () => { view.sequenceAngles = toggle.checked; });

if (typeof THREE !== "undefined") initScene();
connect();
requestAnimationFrame(frame);
