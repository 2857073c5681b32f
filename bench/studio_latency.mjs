// The studio's latency on a large mesh (issue 19's bench; docs/studio.md, "Performance"): the page
// in a headless Chromium against fieldspaced through the gateway, one constraint added by a short
// drag, then that constraint's marker dragged through N scripted pointer moves: real mouse input,
// sent through the DevTools protocol (Input.dispatchMouseEvent) every --interval-ms without
// waiting for each to be acknowledged. Playwright's mouse.move waits for the acknowledgement, which
// Chromium sends after the next animation frame: the drag would advance one step per frame of the
// page (seconds under software GL on 1.4M faces), which no user's mouse does. Reports, per pointer
// event the page's gestures follow (pointerrawupdate in Chromium, dispatched as the input arrives;
// pointermove waits for the next frame), the time from the event to the new field values decoded
// in the page (the page's own update log: DesignSession.updateLog), and where it goes (pick, wait
// behind the edit in flight, the daemon's edit and lift, gateway and transport); bytes per update
// (the WebSocket frames, as Chromium saw them); the page's frame times; the time from opening the
// page to its first drawn field. At the end the session's coefficients must equal a one-shot Solve
// of the final constraints.
//
//   node bench/studio_latency.mjs --mesh ../shared/meshes/armadillo_loop2_1384k.ply
//       [--daemon-bin build/bin/fieldspaced | --daemon HOST:PORT] [--store DIR] [--dim 2000]
//       [--steps 300] [--interval-ms 16] [--radius-px 40] [--web-dir client/web] [--json FILE]
//
// Without --daemon it starts fieldspaced on a free port with --store DIR (default: a temporary
// one); the mesh (by file name and face count) and a vector basis of dimension --dim already in the
// store are reused, so reruns with the same --store skip the upload and the build.
import { readdirSync, readFileSync, writeFileSync } from "node:fs";
import { cpus, loadavg } from "node:os";
import { basename, dirname, extname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";
import {
  castRay, cameraRay, check, chooseBasis, cleanup, faceCentroid, launchChromium, pageProbe,
  parseArgs, project, startDaemon, startGateway, webModules,
} from "../tests/studio/studio_lib.mjs";

const root = resolve(dirname(fileURLToPath(import.meta.url)), "..");
const args = {
  "web-dir": join(root, "client", "web"),
  "daemon-bin": join(root, "build", "bin", "fieldspaced"),
  dim: "2000", steps: "300", "interval-ms": "16", "radius-px": "40",
  ...parseArgs(process.argv.slice(2)),
};
if (!args.mesh) {
  console.error("usage: node bench/studio_latency.mjs --mesh FILE [--daemon HOST:PORT | " +
    "--daemon-bin PATH] [--store DIR] [--dim D] [--steps N] [--interval-ms MS] [--radius-px R] " +
    "[--web-dir DIR] [--json FILE]");
  process.exit(2);
}
const dimension = Number(args.dim);
const steps = Number(args.steps);
const intervalMs = Number(args["interval-ms"]);
const radiusPx = Number(args["radius-px"]);
const log = (text) => console.error(`[bench] ${text}`);
const load = { start: loadavg() };

// CPU seconds (user + system) of this bench's process tree by role, from /proc (Linux): the
// daemon, the gateway, Chromium's GPU process (where SwiftShader draws), its renderers, the rest of
// Chromium, and this process (the synthetic mouse).
function cpuByRole() {
  const tick = 100;  // USER_HZ
  const procs = new Map();
  for (const entry of readdirSync("/proc")) {
    if (!/^\d+$/.test(entry)) continue;
    try {
      const stat = readFileSync(`/proc/${entry}/stat`, "utf8");
      const fields = stat.slice(stat.lastIndexOf(")") + 2).split(" ");
      procs.set(Number(entry), { ppid: Number(fields[1]),
        cpu: (Number(fields[11]) + Number(fields[12])) / tick,
        cmd: readFileSync(`/proc/${entry}/cmdline`, "utf8") });
    } catch {
      // gone meanwhile
    }
  }
  const ours = (pid) => {
    for (let p = pid; p > 1; p = procs.get(p)?.ppid ?? 0) if (p === process.pid) return true;
    return false;
  };
  const roles = { daemon: 0, gateway: 0, gpuProcess: 0, renderers: 0, otherChromium: 0, bench: 0 };
  for (const [pid, { cpu, cmd }] of procs) {
    if (pid === process.pid) roles.bench += cpu;
    else if (!ours(pid)) continue;
    else if (cmd.includes("fieldspaced")) roles.daemon += cpu;
    else if (cmd.includes("gateway")) roles.gateway += cpu;
    else if (cmd.includes("--type=gpu-process")) roles.gpuProcess += cpu;
    else if (cmd.includes("--type=renderer")) roles.renderers += cpu;
    else if (cmd.includes("chrom")) roles.otherChromium += cpu;
  }
  return roles;
}

const { chromium, daemonClient, pb } = await webModules(args["web-dir"]);
let address = args.daemon;
if (!address) {
  address = (await startDaemon(args["daemon-bin"], { store: args.store ?? null })).address;
}
const client = daemonClient(address);

// --- The mesh and the basis, reused when the store has them. ---------------------------------

async function uploadFile(path) {
  const data = readFileSync(path);
  const format = { ".obj": pb.MeshFormat.OBJ, ".off": pb.MeshFormat.OFF,
    ".ply": pb.MeshFormat.PLY }[extname(path).toLowerCase()] ?? pb.MeshFormat.UNSPECIFIED;
  const chunk = 1 << 20;
  return client.uploadMesh((async function* () {
    for (let offset = 0; offset < data.length || offset === 0; offset += chunk) {
      yield { ...(offset === 0 ? { header: { name: basename(path), format,
        totalBytes: BigInt(data.length) } } : {}),
      offset: BigInt(offset), data: data.subarray(offset, offset + chunk) };
    }
  })());
}

let mesh = (await client.listMeshes({})).meshes.find((m) => m.name === basename(args.mesh));
if (mesh === undefined) {
  log(`uploading ${args.mesh}`);
  mesh = await uploadFile(args.mesh);
}
log(`mesh ${mesh.id}: ${mesh.numFaces} faces`);
let basis = (await client.listBases({ meshId: mesh.id })).bases.find((b) =>
  b.field?.kind === pb.FieldKind.VECTOR && b.dimension === dimension &&
  b.state === pb.BasisState.READY);
let buildSeconds = null;
if (basis === undefined) {
  log(`building a vector basis, d = ${dimension}`);
  const t0 = performance.now();
  let reported = -1;
  for await (const progress of client.buildBasis({ meshId: mesh.id,
    field: { kind: pb.FieldKind.VECTOR }, dimension })) {
    const percent = Math.floor(100 * progress.overallFraction);
    if (percent >= reported + 10) {
      reported = percent;
      log(`build ${percent}%`);
    }
    if (progress.basis) basis = progress.basis;
  }
  buildSeconds = (performance.now() - t0) / 1000;
}
check(basis?.state === pb.BasisState.READY, `basis ${basis?.id} (d = ${dimension}) ready`);

// --- The page: first open, then a reload (the page reopens the remembered basis itself). ------

const gateway = await startGateway(args["web-dir"], ["--daemon", address]);
const browser = await launchChromium(chromium);
const page = await browser.newPage({ viewport: { width: 1100, height: 760 } });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
page.on("console", (m) => m.type() === "error" && console.error(`page console: ${m.text()}`));
// The design WebSocket's frames as Chromium received them (the gateway's DesignUpdates).
const frames = [];
page.on("websocket", (ws) => {
  if (!ws.url().endsWith("/design")) return;
  ws.on("framereceived", ({ payload }) => {
    if (typeof payload !== "string") frames.push(payload.length);
  });
});
const probe = pageProbe(page, client, pb);
const markTime = () => page.evaluate(() =>
  performance.getEntriesByName("studio:first-field-drawn")[0]?.startTime ?? null);

await page.goto(gateway.url);
await page.waitForFunction(() => window.__studio !== undefined);
const chosenAt = await page.evaluate(() => performance.now());
await chooseBasis(page, basis.id);
await probe.settled(300000);
await probe.until("the first field drawn", () =>
  performance.getEntriesByName("studio:first-field-drawn").length > 0, null, 60000);
const firstOpen = { fromChoiceMs: (await markTime()) - chosenAt };
log(`first open: the field drawn ${firstOpen.fromChoiceMs.toFixed(0)} ms after choosing the basis`);
await page.reload();
await probe.settled(300000);
await probe.until("the first field drawn", () =>
  performance.getEntriesByName("studio:first-field-drawn").length > 0, null, 60000);
// performance.now() counts from the navigation's start.
const reload = { fromNavigationMs: await markTime() };
log(`reload: the field drawn ${reload.fromNavigationMs.toFixed(0)} ms after navigation`);

// --- Add a constraint: press on the surface near the view's centre, drag 20 px, release. -------

const geometry = { vertices: [], faces: [] };
for await (const chunk of client.getMeshGeometry({ meshId: mesh.id })) {
  for (const v of chunk.vertices) geometry.vertices.push(v);
  for (const f of chunk.faces) geometry.faces.push(f);
}
const canvasBox = await page.locator("#stage canvas").boundingBox();
const camera = await page.evaluate(() => window.__studio.camera());
// A ray cast here over every face (not the page's BVH): slow on 1.38M faces, so a few only.
const hitAt = (x, y) => castRay(cameraRay(camera, x, y), geometry.vertices, geometry.faces);
let press = null;
for (let r = 0; press === null && r < 300; r += 10) {
  for (let a = 0; a < 8 && press === null; a++) {
    const x = camera.width / 2 + r * Math.cos((a * Math.PI) / 4);
    const y = camera.height / 2 + r * Math.sin((a * Math.PI) / 4);
    // The circle the marker is dragged around must lie on the mesh too.
    const onMesh = [0, 1, 2, 3].every((k) => hitAt(x - radiusPx + radiusPx * Math.cos(k * Math.PI / 2),
      y + radiusPx * Math.sin(k * Math.PI / 2)) !== null);
    const hit = onMesh ? hitAt(x, y) : null;
    if (hit !== null) press = { x, y, hit };
  }
}
check(press !== null, "a screen point on the mesh with the drag circle on the mesh");
const toPage = (x, y) => [canvasBox.x + x, canvasBox.y + y];
// Mouse input as the browser gets it from a device (see the top): `buttons` says the left button
// is held. The returned promise is the acknowledgement.
const cdp = await page.context().newCDPSession(page);
const mouse = (type, [x, y], held) => cdp.send("Input.dispatchMouseEvent", { type, x, y,
  button: type === "mouseMoved" ? "none" : "left", buttons: held ? 1 : 0,
  ...(type === "mouseMoved" ? {} : { clickCount: 1 }) });
{
  const [x, y] = toPage(press.x, press.y);
  await mouse("mouseMoved", [x, y], false);
  await mouse("mousePressed", [x, y], true);
  await Promise.all([5, 10, 15, 20].map((dx) => mouse("mouseMoved", [x + dx, y], true)));
  await mouse("mouseReleased", [x + 20, y], false);
}
let state = await probe.checkAgainstSolve("the constraint added by a drag");
// Faces are about a pixel wide here: the page's pick (float32) may take a neighbour of the face
// cast here; its centroid must be within 2 px of the press.
const pressed = project(camera, faceCentroid(geometry.vertices, geometry.faces,
  state.constraints[0]?.face ?? 0));
check(state.constraints.length === 1 &&
  Math.hypot(pressed[0] - press.x, pressed[1] - press.y) <= 2,
  `the constraint is on the pressed face (${state.constraints[0]?.face}, cast here ` +
  `${press.hit.face})`);

// --- The drag: press on the marker, move it around a circle through it, N steps. --------------

const marker = project(camera, faceCentroid(geometry.vertices, geometry.faces,
  state.constraints[0].face));
const center = [marker[0] - radiusPx, marker[1]];
const turns = 2;
const path = Array.from({ length: steps }, (_, i) => {
  const angle = (2 * Math.PI * turns * (i + 1)) / steps;
  return toPage(center[0] + radiusPx * Math.cos(angle), center[1] + radiusPx * Math.sin(angle));
});
const framesBefore = frames.length;
const cpuAtDrag = {};
const gestureEvent = await page.evaluate(() => window.__studio.gestureEvent);
await page.evaluate((gestureEvent) => {
  // The bench's own view of the input and of the frames: each pointer event's time, and
  // the timestamps of the frames the page asked for (its requestAnimationFrame callbacks; a
  // loop of our own would make Chromium produce frames the page does not need).
  const record = { moves: [], frames: [], on: true };
  window.__bench = record;
  window.addEventListener(gestureEvent, (e) => {
    if (record.on) record.moves.push({ timeStamp: e.timeStamp, dispatched: performance.now() });
  }, { capture: true });
  const raf = window.requestAnimationFrame.bind(window);
  window.requestAnimationFrame = (callback) => raf((t) => {
    if (record.on && record.frames.at(-1) !== t) record.frames.push(t);
    callback(t);
  });
}, gestureEvent);
{
  const start = toPage(...marker);
  await mouse("mouseMoved", start, false);
  await mouse("mousePressed", start, true);
  cpuAtDrag.start = cpuByRole();
  cpuAtDrag.pageStart = await page.evaluate(() => performance.now());
  const t0 = performance.now();
  const acknowledged = [];
  for (let i = 0; i < steps; i++) {
    const wait = t0 + i * intervalMs - performance.now();
    if (wait > 0) await new Promise((r) => setTimeout(r, wait));
    acknowledged.push(mouse("mouseMoved", path[i], true));
  }
  log(`${steps} moves sent in ${((performance.now() - t0) / 1000).toFixed(1)} s`);
  await Promise.all(acknowledged);
  log(`acknowledged after ${((performance.now() - t0) / 1000).toFixed(1)} s`);
  cpuAtDrag.end = cpuByRole();
  cpuAtDrag.seconds = (performance.now() - t0) / 1000;
  cpuAtDrag.pageEnd = await page.evaluate(() => performance.now());
  await mouse("mouseReleased", path.at(-1), false);
}
state = await probe.checkAgainstSolve(`after ${steps} drag steps`);
const record = await page.evaluate(() => {
  window.__bench.on = false;
  return { moves: window.__bench.moves, frames: window.__bench.frames,
    renderMs: window.__studio.frameTimes(), updates: window.__studio.updateLog() };
});
const dragFrames = frames.slice(framesBefore);
await browser.close();

// --- Figures. --------------------------------------------------------------------------------

function stats(values) {
  const v = [...values].sort((a, b) => a - b);
  const at = (q) => v.length ? v[Math.min(v.length - 1, Math.ceil(q * v.length) - 1)] : null;
  const mean = v.length ? v.reduce((s, x) => s + x, 0) / v.length : null;
  return { n: v.length, mean, p50: at(0.5), p90: at(0.9), p99: at(0.99), max: v.at(-1) ?? null };
}
const moves = record.moves;
const updates = record.updates.filter((u) => u.kind === "move" && moves.length &&
  u.sent >= moves[0].dispatched);
// The pointer event behind each edit: the last one dispatched before the edit was made.
function eventOf(made) {
  let lo = 0, hi = moves.length - 1, found = null;
  while (lo <= hi) {
    const mid = (lo + hi) >> 1;
    if (moves[mid].dispatched <= made) [found, lo] = [moves[mid], mid + 1];
    else hi = mid - 1;
  }
  return found;
}
const latency = [], fromDispatch = [], delivery = [], pick = [], queued = [];
for (const u of updates) {
  for (const made of u.made) {
    const event = eventOf(made);
    if (event === null) continue;
    latency.push(u.decoded - event.timeStamp);
    fromDispatch.push(u.decoded - event.dispatched);
    delivery.push(event.dispatched - event.timeStamp);
    pick.push(made - event.dispatched);
    queued.push(u.sent - made);
  }
}
const server = updates.filter((u) => u.timings);
const intervals = record.frames.slice(1).map((t, i) => t - record.frames[i]);
// CPU during the drag (press to the last move's acknowledgement), per role, as a share of one core.
const dragCpu = Object.fromEntries(Object.keys(cpuAtDrag.start).map((role) => [role,
  (cpuAtDrag.end[role] - cpuAtDrag.start[role]) / cpuAtDrag.seconds]));
const dragFrameCount = record.frames.filter((t) => t >= cpuAtDrag.pageStart &&
  t <= cpuAtDrag.pageEnd).length;
const result = {
  bench: "studio_latency",
  mesh: basename(args.mesh), faces: mesh.numFaces, basis: basis.id, dimension,
  columns: basis.columns, basisBuildSeconds: buildSeconds,
  steps, intervalMs, radiusPx, gestureEvent,
  pointerMoves: moves.length,
  editsMade: latency.length,
  updates: updates.length,
  // The pointer event (its timeStamp: when the browser took the input) -> the field values
  // decoded in the page.
  latencyMs: stats(latency),
  // The same from the moment the page's handlers got the event.
  latencyFromDispatchMs: stats(fromDispatch),
  breakdownMs: {
    // pointerrawupdate: as the input arrives (pointermove: with the next animation frame).
    delivery: stats(delivery),
    pick: stats(pick),                 // handlers: the page's pick, the edit made
    waitInPage: stats(queued),         // edit made -> sent (behind the edit in flight)
    roundTrip: stats(updates.map((u) => u.decoded - u.sent)),
    serverEdit: stats(server.map((u) => u.timings.editMs)),
    serverLift: stats(server.map((u) => u.timings.liftMs)),
    serverTotal: stats(server.map((u) => u.timings.totalMs)),
    gatewayAndTransport: stats(server.map((u) => u.decoded - u.sent - u.timings.totalMs)),
  },
  bytesPerUpdate: { page: stats(updates.map((u) => u.bytes)), websocket: stats(dragFrames) },
  // The page's handler of an update (glyphs, markers, panels; not the frame, which is requested).
  handleUpdateMs: stats(updates.filter((u) => u.handled !== null).map((u) => u.handled - u.decoded)),
  frameMs: { rafInterval: stats(intervals), render: stats(record.renderMs),
    // The GPU process's CPU over the drag divided by the page's frames in it: what a frame costs
    // under software GL (with a GPU the GPU does that work).
    gpuProcessCpuPerFrame: dragFrameCount > 0
      ? 1000 * dragCpu.gpuProcess * cpuAtDrag.seconds / dragFrameCount : null },
  // Cores busy during the drag, by process (Linux /proc; 2 cores here).
  dragCpuCores: dragCpu,
  firstFieldMs: { fromChoosingTheBasis: firstOpen.fromChoiceMs,
    fromNavigationOnReload: reload.fromNavigationMs },
  solveCheck: "coefficients equal a one-shot Solve to 1e-9 relative",
  machine: { cpus: cpus().length, model: cpus()[0]?.model ?? "", node: process.version },
  loadAverage: { start: load.start, end: loadavg() },
};
const ms = (x) => (x === null ? "-" : x.toFixed(x < 10 ? 2 : 1));
const line = (name, s) => `${name.padEnd(30)} p50 ${ms(s.p50)}  p90 ${ms(s.p90)}  p99 ${ms(s.p99)}` +
  `  max ${ms(s.max)}  (n ${s.n})`;
const b = result.breakdownMs;
console.log([
  `studio latency: ${result.mesh} (${result.faces} faces), vector d = ${dimension}, ` +
    `${steps} drag steps every ${intervalMs} ms`,
  `${moves.length} ${gestureEvent} events, ${latency.length} edits, ${updates.length} updates ` +
    "(moves made while an edit was in flight are coalesced)",
  line("pointer event -> decoded (ms)", result.latencyMs),
  line("  delivery to the page (ms)", b.delivery),
  line("  dispatched -> decoded (ms)", result.latencyFromDispatchMs),
  line("    pick (ms)", b.pick),
  line("    wait in the page (ms)", b.waitInPage),
  line("    round trip (ms)", b.roundTrip),
  line("      server edit (ms)", b.serverEdit),
  line("      server lift (ms)", b.serverLift),
  line("      server total (ms)", b.serverTotal),
  line("      gateway + transport (ms)", b.gatewayAndTransport),
  `bytes per update: ${Math.round(result.bytesPerUpdate.page.mean ?? 0)} (page), ` +
    `${Math.round(result.bytesPerUpdate.websocket.mean ?? 0)} (WebSocket frames, ` +
    `${result.bytesPerUpdate.websocket.n})`,
  line("frame interval (page, ms)", result.frameMs.rafInterval),
  line("render call (ms)", result.frameMs.render),
  `GPU process CPU per frame: ${ms(result.frameMs.gpuProcessCpuPerFrame)} ms ` +
    `(${dragFrameCount} frames in the drag)`,
  `cores busy during the drag: ${Object.entries(dragCpu).map(([role, cores]) =>
    `${role} ${cores.toFixed(2)}`).join(", ")}`,
  line("update handler (ms)", result.handleUpdateMs),
  `first field drawn: ${ms(result.firstFieldMs.fromChoosingTheBasis)} ms after choosing the ` +
    `basis; ${ms(result.firstFieldMs.fromNavigationOnReload)} ms from navigation on a reload`,
  ...[["pointer event", result.latencyMs], ["dispatched", result.latencyFromDispatchMs]].map(
    ([from, s]) => `targets from ${from}: p50 <= 10 ms ${s.p50 <= 10 ? "met" : "MISSED"}, ` +
      `p99 <= 30 ms ${s.p99 <= 30 ? "met" : "MISSED"}`),
  `load average ${load.start.map((x) => x.toFixed(2)).join(" ")} -> ` +
    `${result.loadAverage.end.map((x) => x.toFixed(2)).join(" ")}`,
].join("\n"));
if (args.json) writeFileSync(args.json, `${JSON.stringify(result, null, 2)}\n`);
else console.log(JSON.stringify(result));
cleanup();
process.exit(0);
