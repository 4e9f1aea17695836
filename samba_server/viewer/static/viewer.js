// Samba live viewer page: WebSocket client, 3D skeleton (three.js, or a 2D canvas fallback when
// WebGL is unavailable), per-mote blob views, status panel, recording buttons.
// World frame: Z up, metres (FORMATS.md).
import * as THREE from "/static/three.module.min.js";

const BONE_OK = 0x7aa2f7, BONE_POOR = 0xffa028; // skeleton colour: good / poor pose
const LABEL_COLORS = ["#7aa2f7", "#f7768e", "#9ece6a", "#e0af68", "#bb9af7", "#2ac3de", "#ff9e64", "#c0caf5"];
const $ = (id) => document.getElementById(id);

const state = {
  jointNames: [], markerNames: [], bones: [],
  joints: null, markers: null, poses: 0, recording: false, poor: false, unsure: new Set(),
  t: null, recStartT: null, // pose time (s) now and when the recording started
  motes: new Map(), // id -> {canvas, ctx, count, last}
  status: {},
  cam: { az: -0.6, el: 0.3, dist: 4.2, target: [0, 0, 0.9] }, follow: true,
};

// ---------------------------------------------------------------- 3D view
const canvas = $("scene");
let renderer3d = null;
try {
  renderer3d = makeThree(canvas);
  $("renderer").textContent = "WebGL";
} catch (err) {
  console.warn("WebGL unavailable, using the 2D fallback:", err);
  $("renderer").textContent = "2D fallback (no WebGL)";
}
const ctx2d = renderer3d ? null : canvas.getContext("2d");

function makeThree(cv) {
  // preserveDrawingBuffer: the last frame stays on the canvas for screenshots (headless tests, the
  // browser's own capture) instead of a cleared buffer between frames
  const renderer = new THREE.WebGLRenderer({ canvas: cv, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x15181d);
  const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 100);
  camera.up.set(0, 0, 1);
  const grid = new THREE.GridHelper(6, 12, 0x3a4250, 0x262b33);
  grid.rotation.x = Math.PI / 2; // GridHelper lies in XZ; the floor is XY (Z up)
  scene.add(grid);
  scene.add(new THREE.AxesHelper(0.5));
  scene.add(new THREE.AmbientLight(0xffffff, 0.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.6);
  sun.position.set(2, -3, 5);
  scene.add(sun);
  const jointMat = new THREE.MeshLambertMaterial({ color: 0xe6e6e6 });
  const guessMat = new THREE.MeshLambertMaterial({ color: 0x6b7280, transparent: true, opacity: 0.6 });
  const markerMat = new THREE.MeshLambertMaterial({ color: 0xffb454, transparent: true, opacity: 0.55 });
  const jointGeo = new THREE.SphereGeometry(0.024, 14, 10);
  const markerGeo = new THREE.SphereGeometry(0.036, 14, 10);
  const joints = [], markers = [];
  for (let i = 0; i < 13; i++) { const m = new THREE.Mesh(jointGeo, jointMat); m.visible = false; scene.add(m); joints.push(m); }
  for (let i = 0; i < 8; i++) { const m = new THREE.Mesh(markerGeo, markerMat); m.visible = false; scene.add(m); markers.push(m); }
  const boneGeo = new THREE.BufferGeometry();
  boneGeo.setAttribute("position", new THREE.BufferAttribute(new Float32Array(24 * 3 * 2), 3));
  const bones = new THREE.LineSegments(boneGeo, new THREE.LineBasicMaterial({ color: BONE_OK }));
  bones.frustumCulled = false;
  scene.add(bones);
  return { renderer, scene, camera, joints, markers, bones, jointMat, guessMat };
}

const mid = (a, b) => (a && b ? [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2, (a[2] + b[2]) / 2] : null);

// line segments to draw: the bones, plus torso and neck through the shoulder and hip midpoints
function segments(J) {
  const out = [];
  for (const [a, b] of state.bones) if (J[a] && J[b]) out.push([J[a], J[b]]);
  const ix = (n) => J[state.jointNames.indexOf(n)];
  const sh = mid(ix("left_shoulder"), ix("right_shoulder")), hp = mid(ix("left_hip"), ix("right_hip"));
  if (sh && hp) out.push([sh, hp]);
  if (sh && ix("head")) out.push([sh, ix("head")]);
  return out;
}

function follow() {
  // keep the subject centred: ease the orbit target toward the hip midpoint (x, y only)
  const J = state.joints; if (!state.follow || !J) return;
  const hp = mid(J[state.jointNames.indexOf("left_hip")], J[state.jointNames.indexOf("right_hip")]);
  if (!hp) return;
  const t = state.cam.target;
  t[0] += 0.2 * (hp[0] - t[0]); t[1] += 0.2 * (hp[1] - t[1]);
}

function cameraPosition() {
  const c = state.cam, t = c.target;
  return [t[0] + c.dist * Math.cos(c.el) * Math.sin(c.az), t[1] - c.dist * Math.cos(c.el) * Math.cos(c.az),
          t[2] + c.dist * Math.sin(c.el)];
}

let sized = [0, 0]; // canvas size (CSS px) the renderer was last set to
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  sized = [w, h];
  if (renderer3d) {
    renderer3d.renderer.setSize(w, h, false);
    renderer3d.camera.aspect = w / Math.max(h, 1);
    renderer3d.camera.updateProjectionMatrix();
  } else {
    canvas.width = w; canvas.height = h;
  }
}
window.addEventListener("resize", resize);
resize();

let lastDraw = -Infinity; // performance.now() of the last draw
function draw() {
  lastDraw = performance.now();
  // the canvas may get its size after the script ran (styles still loading) without a window
  // resize event: a renderer left at 0 x 0 draws nothing
  if (canvas.clientWidth !== sized[0] || canvas.clientHeight !== sized[1]) resize();
  follow();
  const [x, y, z] = cameraPosition();
  if (renderer3d) {
    const r = renderer3d;
    r.camera.position.set(x, y, z);
    r.camera.lookAt(...state.cam.target);
    const J = state.joints || [], M = state.markers || [];
    r.joints.forEach((m, i) => {
      const p = J[i]; m.visible = !!p; if (p) m.position.set(p[0], p[1], p[2]);
      m.material = state.unsure.has(i) ? r.guessMat : r.jointMat;
    });
    r.markers.forEach((m, i) => { const p = M[i]; m.visible = !!p; if (p) m.position.set(p[0], p[1], p[2]); });
    const pos = r.bones.geometry.attributes.position;
    let n = 0;
    for (const [a, b] of segments(J)) { pos.setXYZ(n++, ...a); pos.setXYZ(n++, ...b); }
    r.bones.geometry.setDrawRange(0, n);
    r.bones.material.color.setHex(state.poor ? BONE_POOR : BONE_OK);
    pos.needsUpdate = true;
    r.renderer.render(r.scene, r.camera);
  } else {
    draw2d([x, y, z]);
  }
}

function draw2d(eye) {
  // pinhole projection with the same orbit camera, for browsers without WebGL
  const w = canvas.width, h = canvas.height, g = ctx2d, t = state.cam.target;
  g.fillStyle = "#15181d"; g.fillRect(0, 0, w, h);
  const f = [t[0] - eye[0], t[1] - eye[1], t[2] - eye[2]], fl = Math.hypot(...f);
  const fw = f.map((v) => v / fl);
  let r = [fw[1], -fw[0], 0]; const rl = Math.hypot(...r) || 1; r = r.map((v) => v / rl);
  const u = [r[1] * fw[2] - r[2] * fw[1], r[2] * fw[0] - r[0] * fw[2], r[0] * fw[1] - r[1] * fw[0]];
  const foc = h / (2 * Math.tan((45 * Math.PI) / 360));
  const proj = (p) => {
    const d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
    const zc = d[0] * fw[0] + d[1] * fw[1] + d[2] * fw[2];
    if (zc < 0.05) return null;
    return [w / 2 + (foc * (d[0] * r[0] + d[1] * r[1] + d[2] * r[2])) / zc, h / 2 - (foc * (d[0] * u[0] + d[1] * u[1] + d[2] * u[2])) / zc];
  };
  g.strokeStyle = "#262b33"; g.lineWidth = 1;
  for (let k = -3; k <= 3; k += 0.5) {
    for (const [a, b] of [[[k, -3, 0], [k, 3, 0]], [[-3, k, 0], [3, k, 0]]]) {
      const pa = proj(a), pb = proj(b);
      if (pa && pb) { g.beginPath(); g.moveTo(...pa); g.lineTo(...pb); g.stroke(); }
    }
  }
  const J = state.joints || [], M = state.markers || [];
  g.strokeStyle = state.poor ? "#ffa028" : "#7aa2f7"; g.lineWidth = 3;
  for (const [a, b] of segments(J)) {
    const pa = proj(a), pb = proj(b);
    if (pa && pb) { g.beginPath(); g.moveTo(...pa); g.lineTo(...pb); g.stroke(); }
  }
  const dot = (p, rad, col) => { const q = p && proj(p); if (q) { g.fillStyle = col; g.beginPath(); g.arc(q[0], q[1], rad, 0, 7); g.fill(); } };
  J.forEach((p, i) => dot(p, 5, state.unsure.has(i) ? "#6b7280" : "#e6e6e6"));
  M.forEach((p) => dot(p, 4, "#ffb454"));
}

let dirty = true;
function frame() { if (dirty) { draw(); dirty = false; } requestAnimationFrame(frame); }
requestAnimationFrame(frame);
setInterval(() => { if (dirty) { draw(); dirty = false; } }, 250); // hidden/headless tabs throttle rAF

// orbit: drag to rotate, wheel to zoom
let drag = null;
canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
canvas.addEventListener("pointerup", () => { drag = null; });
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  state.cam.az -= (e.clientX - drag[0]) * 0.008;
  state.cam.el = Math.max(-0.2, Math.min(1.5, state.cam.el + (e.clientY - drag[1]) * 0.008));
  drag = [e.clientX, e.clientY]; dirty = true;
});
canvas.addEventListener("wheel", (e) => { e.preventDefault(); state.cam.dist = Math.max(1, Math.min(30, state.cam.dist * Math.exp(e.deltaY * 0.001))); dirty = true; }, { passive: false });

// ---------------------------------------------------------------- motes
function moteView(id) {
  let m = state.motes.get(id);
  if (m) return m;
  const box = document.createElement("div");
  box.className = "mote"; box.dataset.mote = id;
  box.innerHTML = `<div class="name"><span>${id}</span><span class="n">0 blobs</span></div>`;
  const cv = document.createElement("canvas");
  cv.width = 160; cv.height = 120;
  box.appendChild(cv);
  const list = $("mote-views");
  const after = [...list.children].find((c) => c.dataset.mote > id);
  list.insertBefore(box, after || null);
  m = { box, canvas: cv, ctx: cv.getContext("2d"), count: box.querySelector(".n"), blobs: 0 };
  state.motes.set(id, m);
  return m;
}

function drawBlobs(msg) {
  const m = moteView(msg.mote);
  const [w, h] = msg.size;
  if (m.canvas.width !== w || m.canvas.height !== h) { m.canvas.width = w; m.canvas.height = h; }
  const g = m.ctx;
  g.fillStyle = "#0d0f12"; g.fillRect(0, 0, w, h);
  g.font = "9px sans-serif";
  msg.uv.forEach((p, i) => {
    if (!p) return;
    const lab = msg.labels[i];
    g.fillStyle = lab < 8 ? LABEL_COLORS[lab] : "#ffffff";
    g.beginPath(); g.arc(p[0], p[1], 2.5, 0, 7); g.fill();
    if (lab < 8) g.fillText(String(lab), p[0] + 3, p[1] - 3);
  });
  m.blobs = msg.uv.filter((p) => p).length;
  m.count.textContent = `${m.blobs} blobs`;
  m.box.dataset.blobs = m.blobs;
}

// ---------------------------------------------------------------- status
const fmt = (v, d = 1) => (v === null || v === undefined || Number.isNaN(v) ? "–" : Number(v).toFixed(d));

function showStatus(s) {
  state.status = s;
  const motes = s.motes || {};
  const ids = Object.keys(motes).sort();
  const alive = ids.filter((k) => motes[k].alive !== false).length;
  $("st-alive").textContent = ids.length ? `${alive} / ${ids.length}` : (s.motes_alive ?? "–");
  $("st-fps").textContent = s.fps !== undefined ? `${fmt(s.fps)} fps` : "–";
  $("st-latency").textContent = s.latency_ms !== undefined ? `${fmt(s.latency_ms)} ms` : "–";
  $("st-drops").textContent = s.drops ?? "–";
  const body = document.querySelector("#status-motes tbody");
  body.innerHTML = "";
  for (const id of ids) {
    const m = motes[id], tr = document.createElement("tr");
    const ok = m.alive !== false;
    tr.innerHTML = `<td>${id}</td><td class="${ok ? "ok" : "bad"}">${ok ? "yes" : "no"}</td>` +
      `<td>${fmt(m.fps)}</td><td>${m.blobs ?? "–"}</td><td class="${m.drops ? "bad" : ""}">${m.drops ?? "–"}</td>`;
    body.appendChild(tr);
    moteView(id).box.style.opacity = ok ? "1" : "0.4";
  }
  if (s.recording !== undefined) setRecording(!!s.recording);
}

// "m:ss" of a duration in seconds
const clock = (s) => `${Math.floor(s / 60)}:${String(Math.floor(s % 60)).padStart(2, "0")}`;

function setRecording(on) {
  if (on && !state.recording) state.recStartT = state.t; // the take starts now (pose time)
  if (!on) state.recStartT = null;
  state.recording = on;
  const el = $("rec-state");
  el.textContent = on ? "● recording" + (state.recStartT !== null && state.t !== null ? " " + clock(state.t - state.recStartT) : "")
    : "not recording";
  el.className = "pill " + (on ? "rec" : "off");
  $("rec-start").disabled = on;
  $("rec-stop").disabled = !on;
  document.body.dataset.recording = on ? "1" : "0";
}

// a poor pose (few markers, large residual, labels lost or ambiguous, unsolved): amber skeleton,
// amber HUD and a warning sign with the reasons the server gives in quality.poor
function showQuality(q) {
  const reasons = Array.isArray(q.poor) ? q.poor : [];
  state.poor = reasons.length > 0;
  $("hud").classList.toggle("poor", state.poor);
  $("pose-poor").textContent = state.poor ? "⚠ poor pose: " + reasons.join(", ") : "";
  $("pose-mode").textContent = q.label_mode ? `labels ${q.label_mode}` : "";
  // joints whose bound is 20 cm or more: drawn grey, named in the HUD
  const unsure = Array.isArray(q.unsure) ? q.unsure : [];
  state.unsure = new Set(unsure.map((n) => (state.jointNames || []).indexOf(n)).filter((i) => i >= 0));
  $("pose-unsure").textContent = unsure.length ? "guessed: " + unsure.map((n) => n.replace("_", " ")).join(", ") : "";
  document.body.dataset.unsure = unsure.length;
  document.body.dataset.poseQuality = state.poor ? "poor" : "good";
}

// ---------------------------------------------------------------- socket
let ws = null;
function connect() {
  ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/ws`);
  ws.onopen = () => { $("conn").textContent = "connected"; $("conn").className = "pill on"; document.body.dataset.connected = "1"; };
  ws.onclose = () => {
    $("conn").textContent = "disconnected, retrying…"; $("conn").className = "pill off";
    document.body.dataset.connected = "0";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => {
    let msg;
    try { msg = JSON.parse(ev.data); } catch (e) { console.warn("bad message", e); return; }
    if (msg.type === "hello") {
      state.jointNames = msg.joint_names; state.markerNames = msg.marker_names; state.bones = msg.bones;
      setRecording(!!msg.recording);
    } else if (msg.type === "pose") {
      state.joints = msg.joints; state.markers = msg.markers; state.poses += 1; dirty = true;
      const q = msg.quality || {};
      showQuality(q);
      // throttled or headless tabs may not run animation frames: draw from the stream itself
      if (performance.now() - lastDraw > 100) { draw(); dirty = false; }
      $("pose-count").textContent = state.poses;
      document.body.dataset.poses = state.poses;
      // time since the session's first pose (the server's t0), not the clock's epoch
      state.t = msg.t;
      if (state.recording && state.recStartT === null) state.recStartT = msg.t;
      $("pose-t").textContent = fmt(msg.t - (msg.t0 ?? msg.t), 2);
      if (state.recording) setRecording(true);
      $("pose-res").textContent = q.residual_m != null ? fmt(q.residual_m * 1000, 1) : "–";
      $("pose-nm").textContent = q.n_markers ?? msg.markers.filter((p) => p).length;
    } else if (msg.type === "blobs") {
      drawBlobs(msg);
    } else if (msg.type === "status") {
      showStatus(msg);
    }
  };
}
$("rec-start").onclick = () => ws && ws.readyState === 1 && ws.send(JSON.stringify({ type: "record", start: true }));
$("rec-stop").onclick = () => ws && ws.readyState === 1 && ws.send(JSON.stringify({ type: "record", start: false }));
connect();
