// fieldspace studio: the page (docs/studio.md). Lists the daemon's bases, shows a basis's mesh
// and the designed field, and turns pointer gestures into design-session edits.
import { Code, ConnectError, createClient } from "@connectrpc/connect";
import { createConnectTransport } from "@connectrpc/connect-web";
import {
  BasisState, BuildPhase, FieldKind, FieldSpace,
} from "../gen/fieldspace/v1/fieldspace_pb.js";
import { constraintValue, faceFrames, fieldGlyphs, sampleFaces } from "./glyphs.js";
import { DesignSession, History } from "./session.js";
import { View } from "./view.js";

const GLYPH_TARGET = 2500;  // sampled faces that carry a glyph
// Singularities cost the daemon a lift of the whole field per edit: on by default up to this size.
const SINGULARITIES_MAX_FACES = 200000;
const DRAG_START_PX = 4;    // a press moving less than this is a click
const MARKER_PICK_PX = 12;  // a press this close to a constraint marker grabs it
const STORE_PREFIX = "fieldspace.studio.v1.";
const DEFAULT_WEIGHTS = { muS: 1, muB: 0, muC: 1 };
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
  sample: null,         // { faces, spacing }
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
    studio.sample = sampleFaces(studio.geometry.frames, GLYPH_TARGET);
    $("show-singularities").checked = studio.geometry.faces.length / 3 <= SINGULARITIES_MAX_FACES;
  }
  restore(basis.id);
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
  return { meshId, positions, faces, frames: faceFrames(positions, faces) };
}

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
  studio.selected = null;
  syncWeightSliders();
}

function persist() {
  localStorage.setItem(storageKey(), JSON.stringify({
    weights: studio.weights,
    constraints: [...studio.constraints],
    history: studio.history,
    nextId: studio.nextId,
  }));
}

// ---------------------------------------------------------------------------------------------
// The design session.

const designUrl = `${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/design`;

function openSession() {
  const session = new DesignSession({
    url: designUrl,
    token,
    open: { basisId: studio.basis.id, weights: studio.weights, watchFaces: studio.sample.faces,
      singularities: studio.field.kind !== "tensor" && $("show-singularities").checked },
    confirmed: { weights: studio.weights, constraints: studio.constraints },
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
  studio.singularities = new Map();
  view.setSingularities([]);
}

function onUpdate(session, update, edit, roundTripMs) {
  studio.edits += 1;
  studio.weights = { ...session.weights };
  studio.constraints = session.constraints;
  if (!made().constraints.has(studio.selected)) studio.selected = null;
  persist();
  const t = update.timings;
  studio.lastTimings = { edit: edit.kind, editMs: t?.editMs ?? 0, liftMs: t?.liftMs ?? 0,
    totalMs: t?.totalMs ?? 0, roundTripMs };
  $("timings").textContent = `${edit.kind}: edit ${fmt(t?.editMs)} ms · lift ${fmt(t?.liftMs)} ms` +
    ` · server ${fmt(t?.totalMs)} ms · round trip ${fmt(roundTripMs)} ms` +
    `${t?.refactorized ? " (refactorized)" : ""} · ${update.numConstraints} constraints`;
  const values = Float32Array.from(update.watched?.values ?? []);
  if (values.length) {
    const glyphs = fieldGlyphs(studio.field, studio.geometry.frames, studio.sample.faces, values,
      studio.sample.spacing);
    view.setGlyphs(glyphs.positions, glyphs.colors);
    // After the frame that draws them (view's render was requested first): the page's first field.
    if (!firstFieldDrawn) {
      firstFieldDrawn = true;
      requestAnimationFrame(() => performance.mark(FIRST_FIELD_MARK));
    }
  }
  const changes = update.singularities;
  if (changes) {
    studio.singularityN = changes.n || 1;
    for (const s of changes.appeared) {
      studio.singularities.set(s.vertex, { vertex: s.vertex, index: s.index, position: s.position });
    }
    for (const v of changes.vanished) studio.singularities.delete(v);
    view.setSingularities([...studio.singularities.values()].map((s) => ({ ...s,
      n: studio.singularityN })), 0.15 * studio.sample.spacing);
  }
  drawMarkers();
  syncWeightSliders();
  syncSelection();
}

function fmt(ms) {
  return ms === undefined ? "-" : ms < 10 ? ms.toFixed(2) : ms.toFixed(1);
}

// The daemon refused an edit (its answer carries the error) and the session goes on as it was.
function onEditRefused(session, code, message, edit) {
  studio.constraints = session.constraints;
  if (!made().constraints.has(studio.selected)) studio.selected = null;
  persist();
  showMessage(`The daemon refused the edit '${edit.kind}' (${codeName(code)}): ${message}. ` +
    "The session goes on without it.", { error: true });
  drawMarkers();
  syncWeightSliders();
  syncSelection();
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
  showMessage(`The daemon refused the edit '${edit.kind}' (${codeName(code)}): ${message}. ` +
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
  for (const e of edits) edit(e);
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

function drawMarkers() {
  if (!studio.geometry) return;
  view.setMarkers([...made().constraints].map(([id, c]) => ({
    id, position: faceCentroid(c.face), direction: valueDirection(c.value), hard: c.hard,
    selected: id === studio.selected })), studio.sample.spacing);
}

function markerNear(x, y) {
  let best = null;
  let bestDistance = MARKER_PICK_PX;
  for (const [id, c] of made().constraints) {
    const [sx, sy] = view.screenOf(faceCentroid(c.face));
    const d = Math.hypot(sx - x, sy - y);
    if (d <= bestDistance) [best, bestDistance] = [id, d];
  }
  return best;
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
  const marker = markerNear(x, y);
  const hit = marker === null ? view.pick(x, y) : null;
  if (marker === null && hit === null) return;
  event.stopPropagation();
  canvas.setPointerCapture(event.pointerId);
  if (marker !== null) {
    const c = made().constraints.get(marker);
    studio.selected = marker;
    drawMarkers();
    syncSelection();
    gesture = { kind: event.shiftKey ? "turn" : "move", id: marker, x, y, started: false,
      face0: c.face, value0: [...c.value], face: c.face, value: [...c.value] };
  } else {
    gesture = { kind: "add", id: studio.nextId, x, y, started: false, face: hit.face,
      point: hit.point, value: null };
  }
}, { capture: true });

canvas.addEventListener("pointermove", (event) => {
  if (gesture === null) return;
  const [x, y] = local(event);
  if (!gesture.started && Math.hypot(x - gesture.x, y - gesture.y) < DRAG_START_PX) return;
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
    gesture.constraint = { face: gesture.face, value: gesture.value, hard: false, weight: 1 };
    studio.nextId += 1;
    studio.selected = gesture.id;
    edit({ kind: "add", id: gesture.id, constraint: { ...gesture.constraint } });
  } else {
    gesture.started = true;
    edit({ kind: "move", id: gesture.id, face: gesture.face, value: gesture.value });
  }
});

function endGesture(event) {
  if (gesture === null) return;
  const g = gesture;
  gesture = null;
  if (canvas.hasPointerCapture(event.pointerId)) canvas.releasePointerCapture(event.pointerId);
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
  } else {
    studio.history.push({
      do: [{ kind: "move", id: g.id, face: g.face, value: g.value }],
      undo: [{ kind: "move", id: g.id, face: g.face0, value: g.value0 }] });
  }
  persist();
}
canvas.addEventListener("pointerup", endGesture);
canvas.addEventListener("pointercancel", endGesture);

function syncSelection() {
  const c = made().constraints.get(studio.selected);
  $("constraint").disabled = c === undefined;
  if (c === undefined) {
    $("constraint-info").textContent = "none: click a marker";
    return;
  }
  $("constraint-info").textContent = `#${studio.selected} on face ${c.face}`;
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
// Weights: log-scale sliders that re-solve while dragged.

const SLIDERS = [["muS", "mu-s", false], ["muB", "mu-b", true], ["muC", "mu-c", false]];
let sliderStart = null;  // the weights when a slider drag began

function sliderWeight(input, zeroAtMin) {
  const s = Number(input.value);
  return zeroAtMin && s <= Number(input.min) ? 0 : 10 ** s;
}

function syncWeightSliders() {
  for (const [name, id, zeroAtMin] of SLIDERS) {
    const input = $(id);
    const w = made().weights[name] ?? DEFAULT_WEIGHTS[name];
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
$("png").addEventListener("click", async () => {
  const blob = await view.png();
  const link = document.createElement("a");
  link.href = URL.createObjectURL(blob);
  link.download = `fieldspace-${studio.basis?.id ?? "studio"}.png`;
  link.click();
  setTimeout(() => URL.revokeObjectURL(link.href), 10000);
});

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
    idle: Boolean(studio.session?.idle),
    coefficients: studio.session?.last ? [...studio.session.last.coefficients] : null,
    constraints: [...studio.constraints].map(([id, c]) => ({ id, ...c })),
    weights: { ...studio.weights },
    singularities: studio.singularities.size,
    sampleFaces: studio.sample?.faces.length ?? 0,
    edits: studio.edits,
    timings: studio.lastTimings,
    error: studio.error,
    message: $("message").hidden ? "" : $("message").textContent,
  }),
  camera: () => view.cameraState(),
  frameTimes: () => [...view.frameTimes],
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
