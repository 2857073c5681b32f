// fieldspace studio: the page (docs/studio.md). Lists the daemon's bases, shows a basis's mesh
// and the designed field, and turns pointer gestures into design-session edits.
import { Code, ConnectError, createClient } from "@connectrpc/connect";
import { errorFromJson } from "@connectrpc/connect/protocol-connect";
import { createConnectTransport } from "@connectrpc/connect-web";
import {
  BasisState, BuildPhase, FieldEncoding, FieldKind, FieldSpace,
} from "../gen/fieldspace/v1/fieldspace_pb.js";
import { rawfieldBlob, vtuBlob } from "./export.js";
import { constraintValue, faceFrames, fieldGlyphs, sampleFacesSpaced } from "./glyphs.js";
import { DesignSession, History } from "./session.js";
import { View } from "./view.js";

// The glyph sample follows the view: one glyph per GLYPH_PX CSS pixels of the orbit target's
// distance, among the faces in view, at most GLYPH_MAX of them.
const GLYPH_PX = 22;
const GLYPH_MAX = 4000;
const RESAMPLE_MS = 250;    // after the camera stopped moving for this long
const STROKE_STEP_PX = 8;   // a stroke keeps a picked point this far (on screen) from the last
const STROKE_MAX_POINTS = 200;
// Singularities cost the daemon a lift of the whole field per edit: on by default up to this size.
const SINGULARITIES_MAX_FACES = 200000;
const DRAG_START_PX = 4;    // a press moving less than this is a click
const MARKER_PICK_PX = 12;  // a press this close to a constraint marker grabs it
const STORE_PREFIX = "fieldspace.studio.v1.";
const DEFAULT_WEIGHTS = { muS: 1, muB: 0, muC: 1 };
const DEFAULT_MU_A = 1;  // the curvature alignment's weight
// A User Timing mark: the end of the first frame that drew a field (docs/studio.md, "Performance").
const FIRST_FIELD_MARK = "studio:first-field-drawn";
let firstFieldDrawn = false;

const $ = (id) => document.getElementById(id);
const view = new View($("stage"));
let token = sessionStorage.getItem(`${STORE_PREFIX}token`) ?? "";
let config = { tokenRequired: false, daemon: "" };

const api = createClient(FieldSpace, createConnectTransport({
  baseUrl: location.origin,
  useBinaryFormat: true,
  interceptors: [(next) => (request) => {
    if (token) request.header.set("authorization", `Bearer ${token}`);
    return next(request);
  }],
}));

// The studio's state: the chosen basis, its mesh, the session and what the user made.
const studio = {
  basis: null,          // BasisInfo
  field: null,          // { kind: "vector" | "nfield" | "tensor", n }
  geometry: null,       // { meshId, positions, faces, frames }
  sample: null,         // { faces, spacing }: the watched faces
  curvature: false,     // the session has the curvature-alignment data term (2- and 4-fields)
  session: null,
  history: new History(),
  weights: { ...DEFAULT_WEIGHTS },
  constraints: new Map(),  // the confirmed constraints, id -> { face, value, hard, weight }
  nextId: 1,
  selected: null,
  singularities: new Map(),  // vertex -> { index, position }
  singularityN: 1,
  lastTimings: null,
  edits: 0,
  error: null,
};

// ---------------------------------------------------------------------------------------------
// Messages.

function showMessage(text, { error = false } = {}) {
  const box = $("message");
  box.textContent = text;
  box.className = error ? "error" : "";
  box.hidden = !text;
  studio.error = error ? text : null;
}

/** A user's sentence for a failed call: what failed, the gRPC code's meaning and the message. */
function describe(what, e) {
  const err = ConnectError.from(e);
  switch (err.code) {
    case Code.Unavailable:
      return `${what}: the daemon ${config.daemon ? `at ${config.daemon} ` : ""}is not reachable ` +
        `(unavailable: ${err.rawMessage}). Retrying...`;
    case Code.Unauthenticated:
      return `${what}: the token is missing or wrong (${err.rawMessage}). Enter the studio's token.`;
    case Code.FailedPrecondition:
      return `${what} refused (failed precondition): ${err.rawMessage}`;
    case Code.InvalidArgument:
      return `${what} refused (invalid argument): ${err.rawMessage}`;
    default:
      return `${what} failed (${codeName(err.code)}): ${err.rawMessage}`;
  }
}

function askToken() {
  $("token-form").hidden = false;
  $("token").focus();
}

$("token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  token = $("token").value.trim();
  sessionStorage.setItem(`${STORE_PREFIX}token`, token);
  $("token-form").hidden = true;
  showMessage("");
  refreshBases();
});

// ---------------------------------------------------------------------------------------------
// Bases and meshes.

function fieldOf(basis) {
  const kind = basis.field?.kind;
  if (kind === FieldKind.TENSOR) return { kind: "tensor", n: 1 };
  if (kind === FieldKind.NFIELD) return { kind: "nfield", n: basis.field.n };
  return { kind: "vector", n: 1 };
}

function basisLabel(basis, meshes) {
  const mesh = meshes.get(basis.meshId);
  const field = fieldOf(basis);
  const name = field.kind === "nfield" ? `${field.n}-field` : field.kind;
  const state = basis.state === BasisState.BUILDING
    ? ` (building ${Math.round(100 * basis.overallFraction)}%)` : "";
  return `${mesh ? mesh.name : basis.meshId} (${mesh ? mesh.numFaces : "?"} faces) · ${name} ` +
    `d=${basis.dimension}${state}`;
}

let retryTimer = null;
async function refreshBases() {
  clearTimeout(retryTimer);
  let meshes;
  let bases;
  try {
    meshes = new Map((await api.listMeshes({})).meshes.map((m) => [m.id, m]));
    bases = (await api.listBases({})).bases;
  } catch (e) {
    const err = ConnectError.from(e);
    showMessage(describe("Listing the bases", err), { error: true });
    if (err.code === Code.Unauthenticated) askToken();
    else retryTimer = setTimeout(refreshBases, 3000);
    return;
  }
  const select = $("basis");
  select.replaceChildren(new Option(bases.length ? "(choose a basis)" : "(no bases yet)", ""),
    ...bases.map((b) => new Option(basisLabel(b, meshes), b.id)));
  if (studio.error && studio.error.startsWith("Listing")) showMessage("");
  const wanted = studio.basis?.id ?? localStorage.getItem(`${STORE_PREFIX}basis`);
  if (wanted && bases.some((b) => b.id === wanted)) {
    select.value = wanted;
    if (studio.basis?.id !== wanted) chooseBasis(wanted);
  }
  if (bases.some((b) => b.state === BasisState.BUILDING)) {
    retryTimer = setTimeout(refreshBases, 2000);
  }
}

$("show-singularities").addEventListener("change", () => {
  if (!studio.session) return;
  studio.session.close();
  openSession();
});

$("basis").addEventListener("change", () => {
  if ($("basis").value) chooseBasis($("basis").value);
});

let chooseToken = 0;
async function chooseBasis(id) {
  const mine = ++chooseToken;
  studio.session?.close();
  studio.session = null;
  localStorage.setItem(`${STORE_PREFIX}basis`, id);
  let basis;
  for (;;) {
    try {
      basis = await api.getBasis({ basisId: id });
    } catch (e) {
      showMessage(describe("Reading the basis", e), { error: true });
      if (ConnectError.from(e).code === Code.Unauthenticated) askToken();
      return;
    }
    if (mine !== chooseToken) return;
    if (basis.state === BasisState.READY) break;
    showMessage(`The basis ${id} is still building: ${BuildPhase[basis.phase] ?? "queued"} ` +
      `(${Math.round(100 * basis.overallFraction)}% done). The studio opens it when it is ready.`);
    await new Promise((resolve) => setTimeout(resolve, 1000));
    if (mine !== chooseToken) return;
  }
  studio.basis = basis;
  studio.field = fieldOf(basis);
  $("basis-info").textContent = `${basis.id}: ${basis.columns} columns, ${basis.dofs} DOFs`;
  if (studio.geometry?.meshId !== basis.meshId) {
    showMessage("Loading the mesh...");
    try {
      studio.geometry = await loadGeometry(basis.meshId);
    } catch (e) {
      showMessage(describe("Loading the mesh", e), { error: true });
      return;
    }
    if (mine !== chooseToken) return;
    view.setMesh(studio.geometry.positions, studio.geometry.faces);
    studio.sample = viewSample();
    $("show-singularities").checked = studio.geometry.faces.length / 3 <= SINGULARITIES_MAX_FACES;
  }
  restore(basis.id);
  syncTools();
  showMessage("");
  openSession();
}

async function loadGeometry(meshId) {
  let positions = null;
  let faces = null;
  for await (const chunk of api.getMeshGeometry({ meshId })) {
    positions ??= new Float64Array(3 * chunk.numVertices);
    faces ??= new Uint32Array(3 * chunk.numFaces);
    positions.set(chunk.vertices, 3 * chunk.startVertex);
    faces.set(chunk.faces, 3 * chunk.startFace);
  }
  const frames = faceFrames(positions, faces);
  let area = 0;
  let volume = 0;  // 3 x the enclosed volume: its sign says whether the normals point outward
  for (let f = 0; f < frames.areas.length; f++) {
    area += frames.areas[f];
    for (let k = 0; k < 3; k++) {
      volume += frames.areas[f] * frames.centroids[3 * f + k] * frames.normals[3 * f + k];
    }
  }
  // On a closed mesh the faces turned away from the eye are hidden: the sample leaves them out.
  const { numBoundaryLoops } = await api.getMesh({ meshId });
  return { meshId, positions, faces, frames, faceSize: Math.sqrt(area / frames.areas.length),
    outward: numBoundaryLoops === 0 ? Math.sign(volume) : 0 };
}

// ---------------------------------------------------------------------------------------------
// The glyph sample follows the view: after the camera stopped, the faces in view are sampled
// again with a spacing of GLYPH_PX pixels (denser when zoomed in, even on screen) and the
// session watches them instead (a `watch` edit: the next updates carry their values).

function viewSample() {
  const { frames, faceSize, outward } = studio.geometry;
  const inView = view.inView();
  const c = frames.centroids;
  const n = frames.normals;
  const [ex, ey, ez] = view.camera.position.toArray();
  const keep = (f) => inView(c[3 * f], c[3 * f + 1], c[3 * f + 2]) && (outward === 0 ||
    outward * (n[3 * f] * (c[3 * f] - ex) + n[3 * f + 1] * (c[3 * f + 1] - ey) +
      n[3 * f + 2] * (c[3 * f + 2] - ez)) < 0);
  let h = Math.max(GLYPH_PX * view.pixelSize(), faceSize);
  let sample = sampleFacesSpaced(frames, h, keep);
  while (sample.faces.length > GLYPH_MAX) {
    h *= 1.05 * Math.sqrt(sample.faces.length / GLYPH_MAX);
    sample = sampleFacesSpaced(frames, h, keep);
  }
  return sample;
}

let resampleTimer = null;
view.controls.addEventListener("change", () => {
  clearTimeout(resampleTimer);
  resampleTimer = setTimeout(resample, RESAMPLE_MS);
});

function resample() {
  if (!studio.geometry || !studio.session || gesture !== null) return;
  const sample = viewSample();
  const old = studio.sample.faces;
  if (sample.faces.length === old.length && sample.faces.every((f, i) => f === old[i])) return;
  studio.sample = sample;
  edit({ kind: "watch", faces: sample.faces });
  drawMarkers();  // markers are sized by the spacing
}

// ---------------------------------------------------------------------------------------------
// A new mesh: a file dropped on the view (or chosen) is uploaded through the gateway (POST
// /upload, relayed to UploadMesh in chunks), a basis of the kind in the New mesh box is built
// with the daemon's progress, and opened.

async function uploadFile(file) {
  const what = `Uploading ${file.name}`;
  showMessage(`${what} (${(file.size / 1e6).toFixed(1)} MB)...`);
  let mesh;
  try {
    const response = await fetch(`upload?name=${encodeURIComponent(file.name)}`, {
      method: "POST", body: file, headers: token ? { authorization: `Bearer ${token}` } : {} });
    const text = await response.text();
    const fallback = new ConnectError(`HTTP ${response.status}: ${text.slice(0, 200)}`,
      Code.Unknown);
    let json;
    try {
      json = JSON.parse(text);
    } catch {
      throw fallback;
    }
    if (!response.ok) throw errorFromJson(json, undefined, fallback);
    mesh = json;
  } catch (e) {
    showMessage(describe(what, e), { error: true });
    if (ConnectError.from(e).code === Code.Unauthenticated) askToken();
    return;
  }
  const choice = $("build-field").value;
  const field = choice === "vector" ? { kind: FieldKind.VECTOR }
    : choice === "tensor" ? { kind: FieldKind.TENSOR }
    : { kind: FieldKind.NFIELD, n: Number(choice) };
  const dimension = Number($("build-d").value);
  let basis = null;
  try {
    for await (const progress of api.buildBasis({ meshId: mesh.id, field, dimension })) {
      showMessage(`Building a basis of ${file.name} (${mesh.numFaces} faces, d = ${dimension}): ` +
        `${BuildPhase[progress.phase] ?? "queued"}, ` +
        `${Math.round(100 * progress.overallFraction)}% done.`);
      if (progress.basis) basis = progress.basis;
    }
  } catch (e) {
    showMessage(describe(`Building a basis of ${file.name}`, e), { error: true });
    return;
  }
  await refreshBases();
  $("basis").value = basis.id;
  await chooseBasis(basis.id);
}

$("stage").addEventListener("dragover", (event) => {
  if (![...event.dataTransfer.types].includes("Files")) return;
  event.preventDefault();
  $("stage").classList.add("dropping");
});
$("stage").addEventListener("dragleave", () => $("stage").classList.remove("dropping"));
$("stage").addEventListener("drop", (event) => {
  $("stage").classList.remove("dropping");
  const file = event.dataTransfer?.files[0];
  if (!file) return;
  event.preventDefault();
  uploadFile(file);
});
$("mesh-file").addEventListener("change", () => {
  const file = $("mesh-file").files[0];
  if (file) uploadFile(file);
  $("mesh-file").value = "";
});

// ---------------------------------------------------------------------------------------------
// What the user made, kept per basis in localStorage: a reload resumes it.

function storageKey() {
  return `${STORE_PREFIX}session.${studio.basis.id}`;
}

function restore(basisId) {
  let saved = null;
  try {
    saved = JSON.parse(localStorage.getItem(`${STORE_PREFIX}session.${basisId}`));
  } catch {
    saved = null;
  }
  studio.weights = { ...DEFAULT_WEIGHTS, ...(saved?.weights ?? {}) };
  studio.constraints = new Map(saved?.constraints ?? []);
  studio.history = new History(saved?.history);
  studio.nextId = saved?.nextId ?? 1;
  studio.curvature = Boolean(saved?.curvature) && curvatureAllowed();
  studio.selected = null;
  syncWeightSliders();
}

function persist() {
  localStorage.setItem(storageKey(), JSON.stringify({
    weights: studio.weights,
    constraints: [...studio.constraints],
    history: studio.history,
    nextId: studio.nextId,
    curvature: studio.curvature,
  }));
}

// The weights a session opens with: mu_a only with the curvature term (else INVALID_ARGUMENT).
function openWeights() {
  const { muS, muB, muC, muA } = studio.weights;
  return studio.curvature ? { muS, muB, muC, muA: muA ?? DEFAULT_MU_A } : { muS, muB, muC };
}

// ---------------------------------------------------------------------------------------------
// The design session.

const designUrl = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/design`;

function openSession() {
  const session = new DesignSession({
    url: designUrl,
    token,
    open: { basisId: studio.basis.id, watchFaces: studio.sample.faces,
      singularities: studio.field.kind !== "tensor" && $("show-singularities").checked,
      curvature: studio.curvature },
    confirmed: { weights: openWeights(), constraints: studio.constraints },
    handlers: {
      onUpdate: (update, edit, roundTripMs) => {
        if (session !== studio.session) return;
        onUpdate(session, update, edit, roundTripMs);
      },
      onReady: () => {
        if (session === studio.session && studio.error?.startsWith("The session")) showMessage("");
      },
      onRefused: (code, message, edit) => {
        if (session === studio.session) onEditRefused(session, code, message, edit);
      },
      onClosed: (code, message, edit) => {
        if (session === studio.session) onSessionClosed(code, message, edit);
      },
      onEvent: (event) => {
        if (event.resumed) {
          showMessage(`The daemon's replica was lost; the session was reopened (${event.resumed}).`);
        }
      },
    },
  });
  studio.session = session;
  studio.watched = null;  // an earlier session's, not drawn yet
  studio.singularitiesChanged = false;
  studio.singularities = new Map();
  view.setSingularities([]);
}

function onUpdate(session, update, edit, roundTripMs) {
  studio.edits += 1;
  if (studio.error?.startsWith("The daemon refused") && !edit.replay && edit.kind !== "watch") {
    showMessage("");  // the user went on, and the daemon took it
  }
  studio.weights = { ...session.weights };
  studio.constraints = session.constraints;
  if (!made().constraints.has(studio.selected)) studio.selected = null;
  persist();
  const t = update.timings;
  studio.lastTimings = { edit: edit.kind, editMs: t?.editMs ?? 0, liftMs: t?.liftMs ?? 0,
    totalMs: t?.totalMs ?? 0, roundTripMs };
  studio.timingsText = `${edit.kind}: edit ${fmt(t?.editMs)} ms · lift ${fmt(t?.liftMs)} ms` +
    ` · server ${fmt(t?.totalMs)} ms · round trip ${fmt(roundTripMs)} ms` +
    `${t?.refactorized ? " (refactorized)" : ""} · ${update.numConstraints} constraints`;
  // The update's own watched faces (a new sample may be on its way: a watch edit), drawn by the
  // next frame with the latest ones.
  if (update.watched?.values?.length) studio.watched = update.watched;
  const changes = update.singularities;
  if (changes) {
    studio.singularityN = changes.n || 1;
    for (const s of changes.appeared) {
      studio.singularities.set(s.vertex, { vertex: s.vertex, index: s.index, position: s.position });
    }
    for (const v of changes.vanished) studio.singularities.delete(v);
    studio.singularitiesChanged = true;
  }
  syncBeforeFrame();
}

// What an update changes on the page (glyphs, singularities, markers, controls, the timings
// line), once per frame with the latest update: updates arrive faster than frames while a
// drag streams edits, and every DOM or buffer change in between would be work (and, with
// software GL, compositing on the CPU) that the round trips wait behind.
let syncPending = false;
function syncBeforeFrame() {
  if (syncPending) return;
  syncPending = true;
  view.beforeFrame(() => {
    syncPending = false;
    $("timings").textContent = studio.timingsText ?? "";
    if (studio.watched && studio.geometry) {
      const glyphs = fieldGlyphs(studio.field, studio.geometry.frames,
        Int32Array.from(studio.watched.faces), Float32Array.from(studio.watched.values),
        studio.sample.spacing);
      studio.watched = null;
      view.setGlyphs(glyphs.positions, glyphs.colors);
      // After the frame that draws them: the page's first field.
      if (!firstFieldDrawn) {
        firstFieldDrawn = true;
        requestAnimationFrame(() => performance.mark(FIRST_FIELD_MARK));
      }
    }
    if (studio.singularitiesChanged) {
      studio.singularitiesChanged = false;
      view.setSingularities([...studio.singularities.values()].map((s) => ({ ...s,
        n: studio.singularityN })), 0.15 * studio.sample.spacing);
    }
    drawMarkers();
    syncWeightSliders();
    syncSelection();
    syncAlignment();
  });
}

function fmt(ms) {
  return ms === undefined ? "-" : ms < 10 ? ms.toFixed(2) : ms.toFixed(1);
}

// The daemon refused an edit (its answer carries the error) and the session goes on as it was.
function onEditRefused(session, code, message, edit) {
  studio.constraints = session.constraints;
  if (!made().constraints.has(studio.selected)) studio.selected = null;
  persist();
  showMessage(`The daemon refused the edit '${editName(edit)}' (${codeName(code)}): ${message}. ` +
    "The session goes on without it.", { error: true });
  drawMarkers();
  syncWeightSliders();
  syncSelection();
  syncAlignment();
}

// An edit as the user knows it: "add stroke", "add singularity", "remove", ...
function editName(edit) {
  const tool = edit.constraint?.tool;
  return tool ? `${edit.kind} ${TOOL_NAMES[tool]}` : edit.kind;
}

function onSessionClosed(code, message, edit) {
  studio.session = null;
  if (code === Code.Unauthenticated) {
    showMessage(`The design session was refused: the token is missing or wrong (${message}).`,
      { error: true });
    askToken();
    return;
  }
  if (edit === null || edit.kind === "open" || edit.replay || code === null ||
      code === Code.Unavailable) {
    // The session could not be opened or the connection was lost: try again shortly, with what
    // the server had confirmed.
    const reason = code === null ? message : describe("The session", new ConnectError(message, code));
    showMessage(`The session is closed: ${reason}. Reopening...`, { error: true });
    setTimeout(() => {
      if (studio.session === null && studio.basis) openSession();
    }, 2000);
    return;
  }
  // The server refused an edit and ended the stream: reopen with what it had confirmed.
  showMessage(`The daemon refused the edit '${editName(edit)}' (${codeName(code)}): ${message}. ` +
    "The session was reopened without it.", { error: true });
  openSession();
}

function codeName(code) {
  return (Code[code] ?? String(code)).replace(/[A-Z]/g, (c, i) => (i ? " " : "") + c.toLowerCase());
}

function edit(e) {
  studio.session?.edit(e);
}

function perform(edits, record) {
  for (const e of edits) {
    if (e.kind === "curvature") setCurvature(e.on);
    else edit(e);
  }
  if (record) {
    studio.history.push(record);
    persist();
  }
}

// ---------------------------------------------------------------------------------------------
// Constraints: markers and pointer gestures.

function faceCentroid(face) {
  const c = studio.geometry.frames.centroids;
  return [c[3 * face], c[3 * face + 1], c[3 * face + 2]];
}

function faceNormal(face) {
  const n = studio.geometry.frames.normals;
  return [n[3 * face], n[3 * face + 1], n[3 * face + 2]];
}

// The direction a constraint's value shows: the vector (or n-field direction), or a tensor's
// dominant eigenvector (its value is d d^T here).
function valueDirection(value) {
  if (value.length === 3) return unit(value);
  const [xx, yy, zz] = value;
  const d = [Math.sqrt(Math.max(xx, 0)), Math.sqrt(Math.max(yy, 0)), Math.sqrt(Math.max(zz, 0))];
  if (value[3] < 0) d[1] = -d[1];
  if (value[5] < 0) d[2] = -d[2];
  return unit(d);
}

function unit(v) {
  const l = Math.hypot(v[0], v[1], v[2]);
  return l > 0 ? v.map((x) => x / l) : [1, 0, 0];
}

// What the user made so far: the session's desired state (confirmed plus edits on their way).
function made() {
  return studio.session?.desired ?? { weights: studio.weights, constraints: studio.constraints };
}

const TOOL_NAMES = { stroke: "stroke", singularity: "singularity", boundary: "boundary alignment",
  features: "feature alignment" };

function vertexPosition(v) {
  const p = studio.geometry.positions;
  return [p[3 * v], p[3 * v + 1], p[3 * v + 2]];
}

// A point on face f at barycentric coordinates b.
function facePoint(f, b) {
  const [i, j, k] = [0, 1, 2].map((c) => vertexPosition(studio.geometry.faces[3 * f + c]));
  return [0, 1, 2].map((a) => b[0] * i[a] + b[1] * j[a] + b[2] * k[a]);
}

// The barycentric coordinates of a point on face f (clamped to the face, summing to 1).
function barycentric(f, point) {
  const [a, b, c] = [0, 1, 2].map((k) => vertexPosition(studio.geometry.faces[3 * f + k]));
  const sub = (u, v) => [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
  const dot = (u, v) => u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
  const e1 = sub(b, a), e2 = sub(c, a), q = sub(point, a);
  const d11 = dot(e1, e1), d12 = dot(e1, e2), d22 = dot(e2, e2);
  const q1 = dot(q, e1), q2 = dot(q, e2);
  const det = d11 * d22 - d12 * d12;
  const v = det > 0 ? (d22 * q1 - d12 * q2) / det : 1 / 3;
  const w = det > 0 ? (d11 * q2 - d12 * q1) / det : 1 / 3;
  const bary = [1 - v - w, v, w].map((x) => Math.max(0, x));
  const sum = bary[0] + bary[1] + bary[2];
  return bary.map((x) => x / sum);
}

// A stroke's points on screen and in space, lifted off the surface along the face normal.
function strokePositions(c) {
  const lift = 0.05 * studio.sample.spacing;
  return c.points.map((p) => {
    const q = facePoint(p.face, p.barycentric);
    const n = faceNormal(p.face);
    return [0, 1, 2].map((k) => q[k] + lift * n[k]);
  });
}

function drawMarkers() {
  if (!studio.geometry) return;
  const markers = [];
  const strokes = [];
  for (const [id, c] of made().constraints) {
    const selected = id === studio.selected;
    if (c.tool === undefined) {
      markers.push({ id, position: faceCentroid(c.face), direction: valueDirection(c.value),
        hard: c.hard, selected });
    } else if (c.tool === "singularity") {
      markers.push({ id, position: vertexPosition(c.vertex), direction: null, hard: c.hard,
        selected });
    } else if (c.tool === "stroke") {
      strokes.push({ id, points: strokePositions(c), hard: c.hard, selected });
    }
  }
  view.setMarkers(markers, studio.sample.spacing);
  view.setStrokes(strokes, 0.08 * studio.sample.spacing,
    gesture?.kind === "stroke" ? gesture.points.map((p) => p.position) : null);
}

// The constraint, placed singularity or stroke drawn nearest to a canvas point (within
// MARKER_PICK_PX), or null.
function markerNear(x, y) {
  let best = null;
  let bestDistance = MARKER_PICK_PX;
  const consider = (id, point) => {
    const [sx, sy] = view.screenOf(point);
    const d = Math.hypot(sx - x, sy - y);
    if (d <= bestDistance) [best, bestDistance] = [id, d];
  };
  for (const [id, c] of made().constraints) {
    if (c.tool === undefined) consider(id, faceCentroid(c.face));
    else if (c.tool === "singularity") consider(id, vertexPosition(c.vertex));
    else if (c.tool === "stroke") for (const p of strokePositions(c)) consider(id, p);
  }
  return best;
}

// Hard and weight of what the user adds next (the Tool box).
function newKind() {
  const w = Number($("new-weight").value);
  return { hard: $("new-hard").checked, weight: Number.isFinite(w) && w > 0 ? w : 1 };
}

function currentTool(event) {
  if (event.altKey) return "stroke";
  return document.querySelector("input[name=tool]:checked")?.value ?? "constraint";
}

// Adds a new item (a constraint or a tool) under a new id as one undoable action, selected.
function addItem(constraint) {
  const id = studio.nextId++;
  studio.selected = id;
  perform([{ kind: "add", id, constraint }], { do: [{ kind: "add", id, constraint }],
    undo: [{ kind: "remove", id }] });
  drawMarkers();
  syncSelection();
}

let gesture = null;
const canvas = view.renderer.domElement;
const local = (event) => {
  const r = canvas.getBoundingClientRect();
  return [event.clientX - r.left, event.clientY - r.top];
};

// Runs before OrbitControls (capture on the parent): a left press on the mesh is a design
// gesture, anything else orbits.
$("stage").addEventListener("pointerdown", (event) => {
  if (event.button !== 0 || event.target !== canvas || !studio.session || !studio.geometry) return;
  const [x, y] = local(event);
  const tool = currentTool(event);
  const marker = tool === "stroke" ? null : markerNear(x, y);
  const hit = marker === null ? view.pick(x, y) : null;
  if (marker === null && hit === null) return;
  event.stopPropagation();
  canvas.setPointerCapture(event.pointerId);
  if (marker !== null) {
    const c = made().constraints.get(marker);
    studio.selected = marker;
    drawMarkers();
    syncSelection();
    // A constraint's marker moves or turns, a placed singularity's moves to another vertex, a
    // stroke moves as a whole (each point to the surface under its screen position plus the
    // drag); other tools' select only.
    gesture = c.tool === "singularity" ? { kind: "moveSingularity", id: marker, x, y,
      started: false, before: { ...c }, after: { ...c } }
      : c.tool === "stroke" ? { kind: "moveStroke", id: marker, x, y, started: false,
        before: { ...c }, after: { ...c },
        screen: c.points.map((q) => view.screenOf(facePoint(q.face, q.barycentric))) }
      : { kind: c.tool !== undefined ? "select" : event.shiftKey ? "turn" : "move",
        id: marker, x, y, started: false, face0: c.face, value0: c.value && [...c.value],
        face: c.face, value: c.value && [...c.value] };
  } else if (tool === "stroke") {
    gesture = { kind: "stroke", x, y, started: false, points: [], last: null };
    strokePoint(x, y, hit);
  } else if (tool === "singularity") {
    gesture = { kind: "singularity", x, y, started: false, hit };
  } else {
    gesture = { kind: "add", id: studio.nextId, x, y, started: false, face: hit.face,
      point: hit.point, value: null };
  }
}, { capture: true });

// Keeps a stroke's picked point when it is STROKE_STEP_PX from the last kept one on screen.
function strokePoint(x, y, hit, last = false) {
  const g = gesture;
  if (g.last !== null && !last && Math.hypot(x - g.last[0], y - g.last[1]) < STROKE_STEP_PX) return;
  if (g.last !== null && x === g.last[0] && y === g.last[1]) return;
  g.points.push({ face: hit.face, barycentric: barycentric(hit.face, hit.point),
    position: hit.point });
  g.last = [x, y];
  drawMarkers();
}

// Gestures follow `pointerrawupdate` where the browser has it (Chromium, in a secure context such
// as https or http://127.0.0.1): it is dispatched as the input arrives, while `pointermove` waits
// for the next animation frame, which on a large mesh under a software or slow GPU can take
// seconds. Elsewhere, `pointermove`. One of the two only: each would make the same edit.
const GESTURE_MOVE = "onpointerrawupdate" in window ? "pointerrawupdate" : "pointermove";
canvas.addEventListener(GESTURE_MOVE, (event) => {
  if (gesture === null) return;
  const [x, y] = local(event);
  if (!gesture.started && Math.hypot(x - gesture.x, y - gesture.y) < DRAG_START_PX) return;
  if (gesture.kind === "select" || gesture.kind === "singularity") return;
  if (gesture.kind === "stroke") {
    // Every pointer position since the last event (the browser merges moves into one event
    // while the page is busy, and pointermove into one per frame: gaps in the stroke otherwise).
    gesture.started = true;
    for (const e of event.getCoalescedEvents?.() ?? [event]) {
      const [cx, cy] = local(e);
      const hit = view.pick(cx, cy);
      if (hit !== null) strokePoint(cx, cy, hit);
    }
    return;
  }
  if (gesture.kind === "moveStroke") {
    // A pick per point (up to STROKE_MAX_POINTS rays): once per frame with the latest offset,
    // not per pointer event.
    const g = gesture;
    g.offset = [x - g.x, y - g.y];
    if (!g.movePending) {
      g.movePending = true;
      view.beforeFrame(() => moveStroke(g));
    }
    return;
  }
  if (gesture.kind === "moveSingularity") {
    // To the nearest corner of the face under the pointer: one `move {id, group}` per new vertex.
    const hit = view.pick(x, y);
    if (hit === null) return;
    const vertex = nearestCorner(hit);
    if (vertex === gesture.after.vertex) return;
    gesture.started = true;
    gesture.after = { ...gesture.after, vertex };
    edit({ kind: "replace", id: gesture.id, constraint: { ...gesture.after } });
    return;
  }
  if (gesture.kind === "move") {
    const hit = view.pick(x, y);
    if (hit === null || hit.face === gesture.face) return;
    gesture.face = hit.face;
    gesture.started = true;
    edit({ kind: "move", id: gesture.id, face: hit.face, value: gesture.value });
    return;
  }
  // add, turn: the direction from the anchor to the pointer in the face's tangent plane
  const anchor = gesture.point ?? faceCentroid(gesture.face);
  const q = view.planePoint(x, y, anchor, faceNormal(gesture.face));
  if (q === null) return;
  const d = unit([q[0] - anchor[0], q[1] - anchor[1], q[2] - anchor[2]]);
  gesture.value = constraintValue(studio.field, d);
  if (gesture.kind === "add" && !gesture.started) {
    gesture.started = true;
    gesture.constraint = { face: gesture.face, value: gesture.value, ...newKind() };
    studio.nextId += 1;
    studio.selected = gesture.id;
    edit({ kind: "add", id: gesture.id, constraint: { ...gesture.constraint } });
  } else {
    gesture.started = true;
    edit({ kind: "move", id: gesture.id, face: gesture.face, value: gesture.value });
  }
});

// Moves a stroke being dragged by its latest offset: every point to the surface under its screen
// position plus the offset, or nowhere if one would leave the surface. One `move {id, group}`
// (coalesced while one is in flight).
function moveStroke(g) {
  if (!g.movePending) return;
  g.movePending = false;
  const [dx, dy] = g.offset;
  const points = [];
  for (const [sx, sy] of g.screen) {
    const hit = view.pick(sx + dx, sy + dy);
    if (hit === null) return;
    points.push({ face: hit.face, barycentric: barycentric(hit.face, hit.point) });
  }
  g.started = true;
  g.after = { ...g.after, points };
  edit({ kind: "replace", id: g.id, constraint: { ...g.after } });
}

function endGesture(event) {
  if (gesture === null) return;
  const g = gesture;
  if (g.kind === "moveStroke") moveStroke(g);  // the last offset, if its frame has not come
  if (g.kind === "stroke" && event.type === "pointerup") {
    const [x, y] = local(event);
    const hit = view.pick(x, y);
    if (hit !== null) strokePoint(x, y, hit, true);
  }
  gesture = null;
  if (canvas.hasPointerCapture(event.pointerId)) canvas.releasePointerCapture(event.pointerId);
  if (g.kind === "stroke") {
    drawMarkers();  // without the preview
    if (event.type !== "pointerup") return;
    if (g.points.length < 2) {
      showMessage("A stroke needs a drag across the surface (at least two points).",
        { error: true });
      return;
    }
    addItem({ tool: "stroke", points: decimate(g.points).map(({ face, barycentric: b }) =>
      ({ face, barycentric: b })), ...newKind() });
    return;
  }
  if (g.kind === "singularity") {
    if (!g.started && event.type === "pointerup") placeSingularity(g.hit);
    return;
  }
  if (!g.started) {
    if (g.kind === "add") {  // a click on the surface: nothing selected
      studio.selected = null;
      drawMarkers();
      syncSelection();
    }
    return;
  }
  if (g.kind === "add") {
    const c = { ...g.constraint, value: g.value };
    studio.history.push({ do: [{ kind: "add", id: g.id, constraint: c }],
      undo: [{ kind: "remove", id: g.id }] });
  } else if (g.kind === "moveSingularity" || g.kind === "moveStroke") {
    studio.history.push({ do: [{ kind: "replace", id: g.id, constraint: g.after }],
      undo: [{ kind: "replace", id: g.id, constraint: g.before }] });
  } else if (g.kind !== "select") {
    studio.history.push({
      do: [{ kind: "move", id: g.id, face: g.face, value: g.value }],
      undo: [{ kind: "move", id: g.id, face: g.face0, value: g.value0 }] });
  }
  persist();
}
canvas.addEventListener("pointerup", endGesture);
canvas.addEventListener("pointercancel", endGesture);

// At most STROKE_MAX_POINTS points, the first and the last kept.
function decimate(points) {
  if (points.length <= STROKE_MAX_POINTS) return points;
  const step = (points.length - 1) / (STROKE_MAX_POINTS - 1);
  return Array.from({ length: STROKE_MAX_POINTS }, (_, i) => points[Math.round(i * step)]);
}

// A singularity of the toolbar's index at the vertex of the clicked face nearest the click.
function placeSingularity(hit) {
  if (studio.field.kind === "tensor") {
    showMessage("Singularities are placed in vector and n-field bases, not tensor bases.",
      { error: true });
    return;
  }
  addItem({ tool: "singularity", vertex: nearestCorner(hit), index: Number($("sing-index").value),
    ...newKind() });
}

// The corner of the hit face nearest the hit point.
function nearestCorner(hit) {
  let vertex = -1;
  let best = Infinity;
  for (let k = 0; k < 3; k++) {
    const v = studio.geometry.faces[3 * hit.face + k];
    const p = vertexPosition(v);
    const d = Math.hypot(p[0] - hit.point[0], p[1] - hit.point[1], p[2] - hit.point[2]);
    if (d < best) [vertex, best] = [v, d];
  }
  return vertex;
}

function syncSelection() {
  const c = made().constraints.get(studio.selected);
  $("constraint").disabled = c === undefined;
  if (c === undefined) {
    $("constraint-info").textContent = "none: click a marker";
    return;
  }
  $("constraint-info").textContent = c.tool === "stroke"
    ? `#${studio.selected}: stroke of ${c.points.length} points`
    : c.tool === "singularity"
    ? `#${studio.selected}: singularity ${turns(c.index)} at vertex ${c.vertex}`
    : c.tool !== undefined ? `#${studio.selected}: ${TOOL_NAMES[c.tool]}`
    : `#${studio.selected} on face ${c.face}`;
  $("hard").checked = c.hard;
  // Not while the user types a weight: an update arriving meanwhile must not undo the typing.
  if (document.activeElement !== $("weight")) $("weight").value = String(c.weight);
  $("weight").disabled = c.hard;
}

// Kind and weight: the constraint is removed and added again with the same id.
function replaceSelected(change) {
  const id = studio.selected;
  const c = made().constraints.get(id);
  if (c === undefined) return;
  const next = { ...c, ...change };
  perform([{ kind: "remove", id }, { kind: "add", id, constraint: next }], {
    do: [{ kind: "remove", id }, { kind: "add", id, constraint: next }],
    undo: [{ kind: "remove", id }, { kind: "add", id, constraint: { ...c } }] });
}

$("hard").addEventListener("change", () => replaceSelected({ hard: $("hard").checked }));
$("weight").addEventListener("change", () => {
  const w = Number($("weight").value);
  if (Number.isFinite(w) && w > 0) replaceSelected({ weight: w });
  else showMessage("A soft constraint's weight must be a number > 0.", { error: true });
});

function deleteSelected() {
  const id = studio.selected;
  const c = made().constraints.get(id);
  if (c === undefined) return;
  studio.selected = null;
  perform([{ kind: "remove", id }], { do: [{ kind: "remove", id }],
    undo: [{ kind: "add", id, constraint: { ...c } }] });
}
$("delete").addEventListener("click", deleteSelected);

// ---------------------------------------------------------------------------------------------
// Tools: the singularity index, boundary and feature alignment, curvature alignment.

// The toolbar for the chosen basis: singularity indices k/n turns (k = -n..n, not 0; vectors
// +-1), singularities and curvature only where the daemon takes them.
function syncTools() {
  const { kind, n } = studio.field;
  const select = $("sing-index");
  select.replaceChildren(...Array.from({ length: 2 * n }, (_, i) => (i < n ? i - n : i - n + 1))
    .map((k) => new Option(turns(k / n), String(k / n))));
  select.value = String(1 / n);
  const singularity = document.querySelector("input[name=tool][value=singularity]");
  singularity.disabled = kind === "tensor";
  if (singularity.disabled && singularity.checked) {
    document.querySelector("input[name=tool][value=constraint]").checked = true;
  }
  $("curvature").disabled = !curvatureAllowed();
  $("curvature").checked = studio.curvature;
  $("mu-a-row").hidden = !studio.curvature;
  syncAlignment();
}

// An index in whole turns as the toolbar writes it: +1, -1/4, +3/4.
function turns(index) {
  const n = studio.field.n;
  const k = Math.round(index * n);
  return `${k > 0 ? "+" : ""}${k}${n === 1 ? "" : `/${n}`}`;
}

function curvatureAllowed() {
  return studio.field?.kind === "nfield" && (studio.field.n === 2 || studio.field.n === 4);
}

// The tool of kind `tool` the user made (boundary, features: at most one each): [id, tool].
function madeTool(tool) {
  return [...made().constraints].find(([, c]) => c.tool === tool) ?? [null, null];
}

function syncAlignment() {
  const [, boundary] = madeTool("boundary");
  const [, features] = madeTool("features");
  $("boundary").value = boundary?.mode ?? "";
  $("features").checked = features !== null;
  if (features !== null && document.activeElement !== $("feature-angle")) {
    $("feature-angle").value = String(features.angle);
  }
}

// Switches an alignment tool on (with `spec`), changes it, or off (spec null): one undoable action.
function setAlignment(tool, spec) {
  const [oldId, old] = madeTool(tool);
  const id = oldId ?? studio.nextId++;
  const next = spec === null ? null : { tool, ...spec, ...newKind() };
  const forward = [...(old ? [{ kind: "remove", id }] : []),
    ...(next ? [{ kind: "add", id, constraint: next }] : [])];
  const back = [...(next ? [{ kind: "remove", id }] : []),
    ...(old ? [{ kind: "add", id, constraint: { ...old } }] : [])];
  if (forward.length) perform(forward, { do: forward, undo: back });
}

$("boundary").addEventListener("change", () => setAlignment("boundary",
  $("boundary").value ? { mode: $("boundary").value } : null));
const featureChange = () => {
  const angle = Number($("feature-angle").value);
  if (!(angle > 0 && angle < 180)) {
    showMessage("The feature angle is in degrees, between 0 and 180.", { error: true });
    return;
  }
  setAlignment("features", $("features").checked ? { angle } : null);
};
$("features").addEventListener("change", featureChange);
$("feature-angle").addEventListener("change", () => {
  if ($("features").checked) featureChange();
});

// The curvature term is part of the session's energy (OpenDesign.data): switching it reopens
// the session with the same constraints. A switch is one undoable action (the history's
// `curvature` entries, which perform() turns into this instead of a session edit).
function setCurvature(on) {
  if (!studio.session || !curvatureAllowed() || studio.curvature === on) return;
  studio.curvature = on;
  $("curvature").checked = on;
  $("mu-a-row").hidden = !on;
  persist();
  studio.session.close();
  openSession();
}

$("curvature").addEventListener("change", () => {
  const on = $("curvature").checked;
  if (!studio.session || !curvatureAllowed() || studio.curvature === on) return;
  perform([{ kind: "curvature", on }], { do: [{ kind: "curvature", on }],
    undo: [{ kind: "curvature", on: !on }] });
});

// ---------------------------------------------------------------------------------------------
// Weights: log-scale sliders that re-solve while dragged.

const SLIDERS = [["muS", "mu-s", false], ["muB", "mu-b", true], ["muC", "mu-c", false],
  ["muA", "mu-a", false]];
let sliderStart = null;  // the weights when a slider drag began

function sliderWeight(input, zeroAtMin) {
  const s = Number(input.value);
  return zeroAtMin && s <= Number(input.min) ? 0 : 10 ** s;
}

function syncWeightSliders() {
  for (const [name, id, zeroAtMin] of SLIDERS) {
    const input = $(id);
    const w = made().weights[name] ?? DEFAULT_WEIGHTS[name] ?? DEFAULT_MU_A;
    if (document.activeElement !== input || sliderStart === null) {
      input.value = String(w > 0 ? Math.log10(w) : zeroAtMin ? input.min : input.min);
    }
    $(`${id}-out`).textContent = w === 0 ? "0" : w.toPrecision(3);
  }
}

for (const [name, id, zeroAtMin] of SLIDERS) {
  const input = $(id);
  input.addEventListener("input", () => {
    sliderStart ??= { ...made().weights };
    const w = sliderWeight(input, zeroAtMin);
    $(`${id}-out`).textContent = w === 0 ? "0" : w.toPrecision(3);
    edit({ kind: "weights", weights: { [name]: w } });
  });
  input.addEventListener("change", () => {
    const before = sliderStart ?? { ...made().weights };
    sliderStart = null;
    const w = sliderWeight(input, zeroAtMin);
    studio.history.push({ do: [{ kind: "weights", weights: { [name]: w } }],
      undo: [{ kind: "weights", weights: { [name]: before[name] } }] });
    persist();
  });
}

// ---------------------------------------------------------------------------------------------
// Undo, redo, PNG, keys.

function undo() {
  const edits = studio.history.undo();
  if (edits) perform(edits, null);
  persist();
}

function redo() {
  const edits = studio.history.redo();
  if (edits) perform(edits, null);
  persist();
}

$("undo").addEventListener("click", undo);
$("redo").addEventListener("click", redo);
function download(blob, name) {
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = name;
  link.click();
  setTimeout(() => URL.revokeObjectURL(link.href), 10000);
}

$("png").addEventListener("click", async () => {
  download(await view.png(), `fieldspace-${studio.basis?.id ?? "studio"}.png`);
});

// The whole field: the session's coefficients lifted on every face by the daemon (Lift,
// ambient), written here (export.js).
async function downloadField(format) {
  const coefficients = studio.session?.last?.coefficients;
  if (!coefficients || !studio.geometry) {
    showMessage("There is no field to download yet: choose a basis.", { error: true });
    return;
  }
  const { basis, field, geometry } = studio;
  const per = field.kind === "tensor" ? 6 : 3;
  const values = new Float64Array(per * (geometry.faces.length / 3));
  showMessage(`Lifting the field for the .${format} file...`);
  try {
    for await (const chunk of api.lift({ basisId: basis.id, coefficients: [...coefficients],
      encoding: FieldEncoding.AMBIENT })) {
      values.set(chunk.field.values, per * chunk.startFace);
    }
  } catch (e) {
    showMessage(describe("Lifting the field", e), { error: true });
    return;
  }
  const blob = format === "vtu"
    ? vtuBlob(field, geometry.positions, geometry.faces, geometry.frames, values)
    : rawfieldBlob(field, geometry.frames, values);
  showMessage("");
  download(blob, `fieldspace-${basis.id}.${format}`);
}
$("vtu").addEventListener("click", () => downloadField("vtu"));
$("rawfield").addEventListener("click", () => downloadField("rawfield"));

window.addEventListener("keydown", (event) => {
  if (event.target instanceof HTMLInputElement && event.target.type !== "range") return;
  if ((event.ctrlKey || event.metaKey) && event.key.toLowerCase() === "z") {
    event.preventDefault();
    if (event.shiftKey) redo();
    else undo();
  } else if (event.key === "Delete" || event.key === "Backspace") {
    deleteSelected();
  }
});

// ---------------------------------------------------------------------------------------------
// What tests read (tests/studio): the session's state and the camera.

window.__studio = {
  state: () => ({
    basisId: studio.basis?.id ?? null,
    ready: Boolean(studio.session?.ready),
    // No edit waiting or in flight, and the latest update drawn.
    idle: Boolean(studio.session?.idle) && !syncPending,
    coefficients: studio.session?.last ? [...studio.session.last.coefficients] : null,
    constraints: [...studio.constraints].map(([id, c]) => ({ id, ...c })),
    weights: { ...studio.weights },
    singularities: studio.singularities.size,
    sampleFaces: studio.sample?.faces.length ?? 0,
    spacing: studio.sample?.spacing ?? 0,
    curvature: studio.curvature,
    edits: studio.edits,
    timings: studio.lastTimings,
    error: studio.error,
    message: $("message").hidden ? "" : $("message").textContent,
  }),
  camera: () => view.cameraState(),
  // The watched sample and the last update's watched faces and values.
  sample: () => ({ faces: [...(studio.sample?.faces ?? [])], spacing: studio.sample?.spacing ?? 0,
    watchedFaces: [...(studio.session?.last?.watched?.faces ?? [])],
    watchedValues: [...(studio.session?.last?.watched?.values ?? [])] }),
  frameTimes: () => [...view.frameTimes],
  gestureEvent: GESTURE_MOVE,  // the pointer event gestures follow
  updateLog: () => studio.session?.updateLog ?? [],
  showGlyphs: (on) => view.setGlyphsVisible(on),
  edit,  // an edit as the gestures send them, for tests of refused edits
};

try {
  config = await (await fetch("config.json")).json();
} catch {
  // The gateway answers it; without it the page still works, with less specific messages.
}
if (config.tokenRequired && !token) {
  showMessage("This studio needs a token.", { error: true });
  askToken();
} else {
  refreshBases();
}
