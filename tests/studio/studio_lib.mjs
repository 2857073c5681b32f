// Helpers of the studio's browser tests: a daemon with a temporary store, a mesh made here, the
// gateway, a headless Chromium, rays cast through the page's camera, and PNG pixels.
import { spawn } from "node:child_process";
import { existsSync, mkdtempSync, readFileSync, rmSync } from "node:fs";
import { createRequire } from "node:module";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import { pathToFileURL } from "node:url";
import { inflateSync } from "node:zlib";

/** Command-line arguments as { name: value } ("--name value"). */
export function parseArgs(argv) {
  const args = {};
  for (let i = 0; i < argv.length; i += 2) args[argv[i].replace(/^--/, "")] = argv[i + 1];
  return args;
}

/** Modules of client/web (its node_modules and generated code). */
export async function webModules(webDir) {
  webDir = resolve(webDir);
  const require = createRequire(join(webDir, "package.json"));
  const playwright = require("playwright-core");
  const { daemonClient } = await import(pathToFileURL(join(webDir, "gateway", "daemon.mjs")));
  const pb = await import(pathToFileURL(join(webDir, "gen", "fieldspace", "v1", "fieldspace_pb.js")));
  return { chromium: playwright.chromium, daemonClient, pb };
}

const children = [];
const temporary = [];
export function cleanup() {
  for (const child of children) if (child.exitCode === null) child.kill("SIGTERM");
  for (const dir of temporary) rmSync(dir, { recursive: true, force: true });
}
process.on("exit", cleanup);

export function tempDir(prefix) {
  const dir = mkdtempSync(join(tmpdir(), prefix));
  temporary.push(dir);
  return dir;
}

/** Starts a program and resolves to [child, first stdout line matching `pattern`'s group 1]. */
export function startProcess(command, args, pattern, { timeoutMs = 30000 } = {}) {
  const child = spawn(command, args, { stdio: ["ignore", "pipe", "pipe"] });
  children.push(child);
  let stderr = "";
  child.stderr.on("data", (d) => {
    stderr += d;
    process.stderr.write(`[${command.split("/").pop()}] ${d}`);
  });
  return new Promise((resolve, reject) => {
    let out = "";
    const timer = setTimeout(() => reject(new Error(`${command}: no '${pattern}' in time`)),
      timeoutMs);
    child.stdout.on("data", (d) => {
      out += d;
      const m = pattern.exec(out);
      if (m) {
        clearTimeout(timer);
        resolve([child, m[1]]);
      }
    });
    child.on("exit", (code) => {
      clearTimeout(timer);
      reject(new Error(`${command} exited (${code}): ${stderr}`));
    });
  });
}

/** fieldspaced (by default on 127.0.0.1:0 with a new temporary store); resolves to
 *  { child, address, store, stop() }. */
export async function startDaemon(bin, { listen = "127.0.0.1:0", store = null, extra = [] } = {}) {
  store ??= tempDir("studio-store-");
  const [child, address] = await startProcess(bin,
    ["--listen", listen, "--store", store, ...extra], /listening on (\S+)/);
  const stop = () => new Promise((resolve) => {
    if (child.exitCode !== null) resolve();
    child.once("exit", resolve);
    child.kill("SIGTERM");
  });
  return { child, address, store, stop };
}

/** The gateway (client/web/gateway/main.mjs), on 127.0.0.1:0 unless `args` has a --listen;
 *  resolves to its URL. */
export async function startGateway(webDir, args) {
  webDir = resolve(webDir);
  const listen = args.includes("--listen") ? [] : ["--listen", "127.0.0.1:0"];
  const [child, url] = await startProcess(process.execPath,
    [join(webDir, "gateway", "main.mjs"), ...listen, ...args], /studio: (\S+)/);
  return { child, url };
}

/** The gateway's arguments as README.md's studio block writes them (the ```sh block after the
 *  tested-by comment naming `testPath`), with its two addresses replaced: --listen by
 *  127.0.0.1:0 and --daemon by `daemonAddress`. Checks that the block's daemon listens where its
 *  gateway calls. */
export function readmeGatewayArgs(readmePath, testPath, daemonAddress) {
  const text = readFileSync(readmePath, "utf8");
  const marker = `<!-- tested-by: ${testPath} -->`;
  const at = text.indexOf(marker);
  check(at >= 0, `${readmePath} has a block tagged ${marker}`);
  const block = /^\s*```sh\n([\s\S]*?)\n```/.exec(text.slice(at + marker.length));
  check(block !== null, `a \`\`\`sh block follows ${marker}`);
  const lines = block[1].split("\n");
  const words = (start) => lines.find((l) => l.startsWith(start))?.slice(start.length).trim()
    .replace(/\s*&$/, "").split(/\s+/);
  const flag = (argv, name) => argv[argv.indexOf(name) + 1];
  const gateway = words("node client/web/gateway/main.mjs ");
  const daemon = words("build/bin/fieldspaced ");
  check(gateway && daemon, "the studio block starts fieldspaced and the gateway");
  check(gateway.includes("--listen") && gateway.includes("--daemon"),
    "the block's gateway names --listen and --daemon");
  check(flag(daemon, "--listen") === flag(gateway, "--daemon"),
    `the block's gateway calls ${flag(gateway, "--daemon")}, its daemon listens on ` +
    `${flag(daemon, "--listen")}`);
  const replaced = { "--listen": "127.0.0.1:0", "--daemon": daemonAddress };
  return gateway.map((w, i) => (i > 0 && gateway[i - 1] in replaced ? replaced[gateway[i - 1]] : w));
}

/** OBJ text of a closed torus (genus 1) with 2 * major * minor faces. */
export function torusObj(major = 48, minor = 24, R = 1.0, r = 0.4) {
  const lines = [];
  for (let i = 0; i < major; i++) {
    const u = (2 * Math.PI * i) / major;
    for (let j = 0; j < minor; j++) {
      const v = (2 * Math.PI * j) / minor;
      lines.push(`v ${(R + r * Math.cos(v)) * Math.cos(u)} ${(R + r * Math.cos(v)) * Math.sin(u)} ` +
        `${r * Math.sin(v)}`);
    }
  }
  const idx = (i, j) => (i % major) * minor + (j % minor) + 1;
  for (let i = 0; i < major; i++) {
    for (let j = 0; j < minor; j++) {
      lines.push(`f ${idx(i, j)} ${idx(i + 1, j)} ${idx(i + 1, j + 1)}`);
      lines.push(`f ${idx(i, j)} ${idx(i + 1, j + 1)} ${idx(i, j + 1)}`);
    }
  }
  return `${lines.join("\n")}\n`;
}

/** Uploads OBJ text; resolves to the MeshInfo. */
export function uploadMesh(client, pb, objText, name) {
  const data = new TextEncoder().encode(objText);
  return client.uploadMesh((async function* () {
    yield { header: { name, format: pb.MeshFormat.OBJ, totalBytes: BigInt(data.length) },
      offset: 0n, data };
  })());
}

/** Uploads OBJ text and builds a basis; resolves to { mesh, basis } (MeshInfo, BasisInfo). */
export async function uploadAndBuild(client, pb, objText, name, field, dimension) {
  const mesh = await uploadMesh(client, pb, objText, name);
  let basis = null;
  for await (const progress of client.buildBasis({ meshId: mesh.id, field, dimension })) {
    if (progress.basis) basis = progress.basis;
  }
  return { mesh, basis };
}

/** Chromium (Debian's) headless with software GL and no background networking. */
export function launchChromium(chromium) {
  const executablePath = process.env.CHROMIUM || "/usr/bin/chromium";
  if (!existsSync(executablePath)) {
    console.log(`SKIP: no Chromium at ${executablePath} (.ci/install-deps installs it)`);
    process.exit(77);
  }
  return chromium.launch({
    executablePath,
    headless: true,
    args: ["--headless=new", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
      "--enable-unsafe-swiftshader", "--disable-background-networking",
      "--disable-component-update", "--disable-default-apps", "--disable-sync",
      "--no-first-run", "--metrics-recording-only", "--disable-domain-reliability"],
  });
}

// --- rays through the page's camera, done here (not by the page) ---------------------------

function applyMatrix4(m, x, y, z, w = 1) {  // column-major 4x4
  const out = [0, 1, 2, 3].map((r) => m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r] * w);
  return [out[0] / out[3], out[1] / out[3], out[2] / out[3]];
}

/** The ray through canvas point (x, y) of a camera state (window.__studio.camera()). */
export function cameraRay(camera, x, y) {
  const ndcX = (x / camera.width) * 2 - 1;
  const ndcY = -(y / camera.height) * 2 + 1;
  const view = applyMatrix4(camera.projectionMatrixInverse, ndcX, ndcY, 0.5);
  const world = applyMatrix4(camera.matrixWorld, ...view);
  const o = camera.position;
  const d = [world[0] - o[0], world[1] - o[1], world[2] - o[2]];
  const l = Math.hypot(...d);
  return { origin: o, direction: d.map((c) => c / l) };
}

/** The nearest triangle a ray hits (Moeller-Trumbore over all faces): { face, t, point, bary }
 *  or null. vertices: 3 per vertex; faces: 3 per face. */
export function castRay(ray, vertices, faces) {
  let best = null;
  const { origin: o, direction: d } = ray;
  for (let f = 0; f < faces.length / 3; f++) {
    const a = 3 * faces[3 * f], b = 3 * faces[3 * f + 1], c = 3 * faces[3 * f + 2];
    const e1 = [vertices[b] - vertices[a], vertices[b + 1] - vertices[a + 1], vertices[b + 2] - vertices[a + 2]];
    const e2 = [vertices[c] - vertices[a], vertices[c + 1] - vertices[a + 1], vertices[c + 2] - vertices[a + 2]];
    const p = cross(d, e2);
    const det = dot(e1, p);
    if (Math.abs(det) < 1e-14) continue;
    const s = [o[0] - vertices[a], o[1] - vertices[a + 1], o[2] - vertices[a + 2]];
    const u = dot(s, p) / det;
    if (u < 0 || u > 1) continue;
    const q = cross(s, e1);
    const v = dot(d, q) / det;
    if (v < 0 || u + v > 1) continue;
    const t = dot(e2, q) / det;
    if (t > 0 && (best === null || t < best.t)) {
      best = { face: f, t, point: o.map((oc, k) => oc + t * d[k]), bary: [1 - u - v, u, v] };
    }
  }
  return best;
}

export function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}

export function dot(a, b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/** The unit normal of face f. */
export function faceNormal(vertices, faces, f) {
  const [a, b, c] = [0, 1, 2].map((k) => 3 * faces[3 * f + k]);
  const e1 = [0, 1, 2].map((k) => vertices[b + k] - vertices[a + k]);
  const e2 = [0, 1, 2].map((k) => vertices[c + k] - vertices[a + k]);
  const n = cross(e1, e2);
  const l = Math.hypot(...n);
  return n.map((x) => x / l);
}

/** The centroid of face f. */
export function faceCentroid(vertices, faces, f) {
  return [0, 1, 2].map((k) => (vertices[3 * faces[3 * f] + k] + vertices[3 * faces[3 * f + 1] + k] +
    vertices[3 * faces[3 * f + 2] + k]) / 3);
}

/** Canvas position of an ambient point (the inverse of cameraRay's mapping). */
export function project(camera, point) {
  const viewMatrix = invert4(camera.matrixWorld);
  const projection = invert4(camera.projectionMatrixInverse);
  const v = applyMatrix4(viewMatrix, ...point);
  const ndc = applyMatrix4(projection, ...v);
  return [(ndc[0] + 1) / 2 * camera.width, (1 - ndc[1]) / 2 * camera.height];
}

// Inverse of a column-major 4x4 matrix (Gauss-Jordan with partial pivoting).
function invert4(m) {
  const a = [0, 1, 2, 3].map((r) => [0, 1, 2, 3].map((c) => m[4 * c + r])
    .concat([0, 1, 2, 3].map((c) => (c === r ? 1 : 0))));
  for (let col = 0; col < 4; col++) {
    let pivot = col;
    for (let r = col + 1; r < 4; r++) if (Math.abs(a[r][col]) > Math.abs(a[pivot][col])) pivot = r;
    [a[col], a[pivot]] = [a[pivot], a[col]];
    const p = a[col][col];
    for (let c = 0; c < 8; c++) a[col][c] /= p;
    for (let r = 0; r < 4; r++) {
      if (r === col) continue;
      const f = a[r][col];
      for (let c = 0; c < 8; c++) a[r][c] -= f * a[col][c];
    }
  }
  const out = new Array(16);
  for (let r = 0; r < 4; r++) for (let c = 0; c < 4; c++) out[4 * c + r] = a[r][4 + c];
  return out;
}

// --- PNG ---------------------------------------------------------------------------------

/** Decodes an 8-bit RGB or RGBA PNG (what Chromium's screenshots are) to
 *  { width, height, rgba: Uint8Array }. */
export function decodePng(buffer) {
  let offset = 8;
  let width = 0, height = 0, colorType = 0;
  const idat = [];
  while (offset < buffer.length) {
    const length = buffer.readUInt32BE(offset);
    const type = buffer.toString("latin1", offset + 4, offset + 8);
    const data = buffer.subarray(offset + 8, offset + 8 + length);
    if (type === "IHDR") {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      if (data[8] !== 8 || data[12] !== 0) throw new Error("only 8-bit, non-interlaced PNGs");
      colorType = data[9];
    } else if (type === "IDAT") {
      idat.push(data);
    }
    offset += 12 + length;
  }
  const channels = { 2: 3, 6: 4 }[colorType];
  if (channels === undefined) throw new Error(`PNG colour type ${colorType} not handled`);
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const pixels = new Uint8Array(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const left = x >= channels ? pixels[y * stride + x - channels] : 0;
      const up = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const upLeft = y > 0 && x >= channels ? pixels[(y - 1) * stride + x - channels] : 0;
      let value = line[x];
      if (filter === 1) value += left;
      else if (filter === 2) value += up;
      else if (filter === 3) value += (left + up) >> 1;
      else if (filter === 4) {
        const p = left + up - upLeft;
        const pa = Math.abs(p - left), pb = Math.abs(p - up), pc = Math.abs(p - upLeft);
        value += pa <= pb && pa <= pc ? left : pb <= pc ? up : upLeft;
      }
      pixels[y * stride + x] = value & 0xff;
    }
  }
  const rgba = new Uint8Array(width * height * 4);
  for (let i = 0; i < width * height; i++) {
    for (let k = 0; k < 3; k++) rgba[4 * i + k] = pixels[channels * i + k];
    rgba[4 * i + 3] = channels === 4 ? pixels[4 * i + 3] : 255;
  }
  return { width, height, rgba };
}

// --- checks ------------------------------------------------------------------------------

export function check(condition, message) {
  if (!condition) throw new Error(`check failed: ${message}`);
  console.log(`ok: ${message}`);
}

/** ||a - b|| / ||b||. */
export function relativeError(a, b) {
  let num = 0, den = 0;
  for (let i = 0; i < b.length; i++) {
    num += (a[i] - b[i]) ** 2;
    den += b[i] ** 2;
  }
  return Math.sqrt(num / Math.max(den, 1e-300));
}

// --- the page -----------------------------------------------------------------------------

/** Reads and checks a studio page: its state, waiting until it settled, and its coefficients
 *  against a one-shot Solve over the wire of the page's constraints and weights. */
export function pageProbe(page, client, pb) {
  const state = () => page.evaluate(() => window.__studio.state());
  async function settled(timeout = 60000) {
    try {
      await page.waitForFunction(() => {
        const s = window.__studio?.state();
        return s && s.ready && s.idle;
      }, null, { timeout });
    } catch (e) {
      console.error(`the page did not settle: ${JSON.stringify(await state())}`);
      throw e;
    }
    return state();
  }
  async function checkAgainstSolve(step) {
    const s = await settled();
    const kind = (c) => ({ hard: c.hard, ...(c.hard ? {} : { weight: c.weight }) });
    const solved = await client.solve({
      basisId: s.basisId,
      weights: { muS: s.weights.muS, muB: s.weights.muB, muC: s.weights.muC },
      constraints: s.constraints.filter((c) => c.tool === undefined).map((c) => ({ face: c.face,
        value: c.value, encoding: pb.FieldEncoding.AMBIENT, ...kind(c) })),
      // The page's tools as the constraint groups of the same design tools.
      constraintGroups: s.constraints.filter((c) => c.tool !== undefined).map((c) => ({ tool:
        c.tool === "stroke" ? { case: "stroke", value: { ...kind(c), points: c.points.map((p) =>
          ({ at: { case: "facePoint", value: { face: p.face, barycentric: p.barycentric } } })) } }
        : c.tool === "singularity" ? { case: "singularity", value: { ...kind(c),
          at: { case: "vertex", value: c.vertex }, index: c.index } }
        : c.tool === "boundary" ? { case: "alignBoundary", value: { ...kind(c),
          mode: pb.BoundaryAlignMode[`BOUNDARY_ALIGN_${c.mode.toUpperCase()}`] } }
        : { case: "alignFeatures", value: { ...kind(c), angleDegrees: c.angle } } })),
    });
    const error = relativeError(s.coefficients, solved.coefficients);
    check(s.coefficients.length === solved.coefficients.length && error <= 1e-9,
      `${step}: session coefficients equal Solve (relative error ${error.toExponential(2)})`);
    return s;
  }
  async function waitForMessage(pattern, timeout = 30000) {
    try {
      await page.waitForFunction((source) => new RegExp(source).test(
        window.__studio?.state().message ?? ""), pattern.source, { timeout });
    } catch (e) {
      console.error(`no message /${pattern.source}/: ${JSON.stringify(await state())}`);
      throw e;
    }
    const message = (await state()).message;
    check(pattern.test(message), `the page says: ${message}`);
  }
  // page.waitForFunction that says what it waited for and the page's state when it times out.
  async function until(what, fn, arg = null, timeout = 60000) {
    try {
      await page.waitForFunction(fn, arg, { timeout });
    } catch (e) {
      console.error(`timed out waiting for ${what}: ${JSON.stringify(await state())}`);
      throw e;
    }
  }
  return { state, settled, checkAgainstSolve, waitForMessage, until };
}

/** Opens the studio at `url` and chooses `basisId` once the list has it. */
export async function chooseBasis(page, basisId) {
  await page.waitForFunction((id) => [...document.querySelectorAll("#basis option")]
    .some((o) => o.value === id), basisId, { timeout: 30000 });
  await page.selectOption("#basis", basisId);
}
