// The studio's designer tools in a real headless Chromium against a real daemon: a mesh uploaded by
// dropping its file on the page and its basis built from the page (and a file that is not a mesh
// refused with the daemon's message); boundary and feature alignment toggles on that open box (and
// a refused one on a closed torus); curvature alignment of a 4-field; a singularity placed by
// clicking near a vertex and dragged to another; a stroke drawn by pointer events, selected,
// deleted and undone, and back after a reload; the glyph sample following the zoom; the field
// downloaded as .rawfield and .vtu. After each edit the page's coefficients equal a Solve over
// the wire with the same constraints and constraint groups (1e-9 relative); the faces, vertices
// and points the page used are the ones this test finds by casting the same screen rays itself.
//   node studio_tools_test.mjs --web-dir client/web --daemon build/bin/fieldspaced --out DIR
import { readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import {
  castRay, cameraRay, check, chooseBasis, cleanup, launchChromium, pageProbe, parseArgs, project,
  relativeError, startDaemon, startGateway, torusObj, uploadAndBuild, webModules,
} from "./studio_lib.mjs";

const args = parseArgs(process.argv.slice(2));
const { chromium, daemonClient, pb } = await webModules(args["web-dir"]);
const daemon = await startDaemon(args.daemon);
const client = daemonClient(daemon.address);
const { mesh: torus, basis: vectorBasis } = await uploadAndBuild(client, pb, torusObj(),
  "torus.obj", { kind: pb.FieldKind.VECTOR }, 40);
let fourBasis = null;
for await (const progress of client.buildBasis({ meshId: torus.id,
  field: { kind: pb.FieldKind.NFIELD, n: 4 }, dimension: 60 })) {
  if (progress.basis) fourBasis = progress.basis;
}
// A finer torus for the zoom (the coarse one has a glyph on every face at the first view).
const { mesh: fineTorus, basis: fineBasis } = await uploadAndBuild(client, pb, torusObj(160, 80),
  "fine-torus.obj", { kind: pb.FieldKind.VECTOR }, 30);
check(vectorBasis?.state === pb.BasisState.READY && fourBasis?.state === pb.BasisState.READY &&
  fineBasis?.state === pb.BasisState.READY, "a vector and a 4-field basis of a torus, a vector " +
  `basis of a finer torus (${fineTorus.numFaces} faces)`);
const geometry = { vertices: [], faces: [] };
for await (const chunk of client.getMeshGeometry({ meshId: torus.id })) {
  geometry.vertices.push(...chunk.vertices);
  geometry.faces.push(...chunk.faces);
}
const gateway = await startGateway(args["web-dir"], ["--daemon", daemon.address]);
const browser = await launchChromium(chromium);
const page = await browser.newPage({ viewport: { width: 1100, height: 760 }, acceptDownloads: true });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
page.on("console", (m) => m.type() === "error" && console.error(`page console: ${m.text()}`));
const { state, settled, checkAgainstSolve, waitForMessage, until } = pageProbe(page, client, pb);

// An open box: the unit cube without its top, k x k quads per side, outward normals. Its rim is
// a boundary loop and its 8 lower edges are sharp (90 degrees).
function openBoxObj(k = 8) {
  const sides = [  // origin, u, v with u x v outward
    [[0, 0, 0], [0, 1, 0], [1, 0, 0]], [[0, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 0, 0], [1, 0, 0], [0, 0, 1]],
    [[0, 1, 0], [0, 0, 1], [1, 0, 0]]];
  const index = new Map();
  const vertices = [];
  const faces = [];
  const vertex = (p) => {
    const key = p.map((x) => Math.round(x * k)).join();
    if (!index.has(key)) {
      index.set(key, vertices.length + 1);
      vertices.push(p);
    }
    return index.get(key);
  };
  for (const [o, u, v] of sides) {
    const at = (i, j) => vertex([0, 1, 2].map((c) => o[c] + (i / k) * u[c] + (j / k) * v[c]));
    for (let i = 0; i < k; i++) {
      for (let j = 0; j < k; j++) {
        const [a, b, c, d] = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
        faces.push([a, b, c], [a, c, d]);
      }
    }
  }
  return `${vertices.map((p) => `v ${p.join(" ")}`).join("\n")}\n` +
    `${faces.map((f) => `f ${f.join(" ")}`).join("\n")}\n`;
}

await page.goto(gateway.url);
await until("the list of bases", () => document.querySelectorAll("#basis option").length > 2);

// 1. Upload by dropping a file on the view, then a vector basis of d = 40 built from the page.
await page.selectOption("#build-field", "vector");
await page.fill("#build-d", "40");
const dropped = await page.evaluateHandle((text) => {
  const transfer = new DataTransfer();
  transfer.items.add(new File([text], "box.obj", { type: "text/plain" }));
  return transfer;
}, openBoxObj());
await page.dispatchEvent("#stage", "drop", { dataTransfer: dropped });
await until("the uploaded mesh's basis", (ids) => {
  const s = window.__studio.state();
  return s.basisId !== null && !ids.includes(s.basisId) && s.ready;
}, [vectorBasis.id, fourBasis.id], 120000);
let s = await checkAgainstSolve("the dropped mesh's basis");
const boxBasis = await client.getBasis({ basisId: s.basisId });
const boxMesh = (await client.listMeshes({})).meshes.find((m) => m.id === boxBasis.meshId);
check(boxMesh?.name === "box.obj" && boxMesh.numFaces === 5 * 2 * 64 &&
  boxBasis.field.kind === pb.FieldKind.VECTOR && boxBasis.dimension === 40,
  `the dropped box.obj was stored (${boxMesh?.numFaces} faces) and a vector basis of d = 40 built`);

// A file that is not a mesh: the page shows the daemon's refusal and stays on the box.
const bad = await page.evaluateHandle(() => {
  const transfer = new DataTransfer();
  transfer.items.add(new File(["this is not a mesh\n"], "bad.obj", { type: "text/plain" }));
  return transfer;
}, null);
await page.dispatchEvent("#stage", "drop", { dataTransfer: bad });
await waitForMessage(/Uploading bad\.obj refused \(invalid argument\): \S/);
check((await state()).basisId === boxBasis.id, "the refused upload leaves the session as it was");

// 2. Boundary alignment (tangent, then normal) and feature alignment: session edits, one
// constraint group each, undoable.
await page.selectOption("#boundary", "tangent");
await until("boundary alignment", () => window.__studio.state().constraints
  .some((c) => c.tool === "boundary" && c.mode === "tangent"));
s = await checkAgainstSolve("boundary alignment, tangent");
const tangentCoefficients = s.coefficients;
await page.selectOption("#boundary", "normal");
await until("normal alignment", () => window.__studio.state().constraints
  .some((c) => c.tool === "boundary" && c.mode === "normal"));
s = await checkAgainstSolve("boundary alignment, normal");
check(s.constraints.filter((c) => c.tool === "boundary").length === 1 &&
  relativeError(s.coefficients, tangentCoefficients) > 1e-3,
  "one boundary group, replaced: the normal alignment gives another field");
await page.check("#features");
await until("feature alignment", () => window.__studio.state().constraints
  .some((c) => c.tool === "features" && c.angle === 60));
s = await checkAgainstSolve("feature alignment over 60 degrees");
await page.click("#undo");
await until("the undone feature alignment", () => !window.__studio.state().constraints
  .some((c) => c.tool === "features"));
s = await checkAgainstSolve("undo the feature alignment");
check(!(await page.isChecked("#features")), "undo unticks the feature box");
await page.selectOption("#boundary", "");
await until("no boundary alignment", () => window.__studio.state().constraints.length === 0);
await checkAgainstSolve("boundary alignment off");

// 3. On the closed torus the daemon refuses boundary alignment: the page says so and goes on.
await chooseBasis(page, fourBasis.id);
await checkAgainstSolve("the torus's 4-field");
await page.selectOption("#boundary", "tangent");
await waitForMessage(/refused the edit 'add boundary alignment' \(failed precondition\)/);
s = await settled();
check(s.constraints.length === 0 && (await page.inputValue("#boundary")) === "",
  "the refused alignment is not kept and the box shows it off");

// 4. Curvature alignment of the 4-field (a data term of the session): as Align with mu_c = mu_a
// when there are no constraints.
await page.check("#curvature");
await until("the curvature session", () => {
  const s = window.__studio.state();
  return s.curvature && s.ready && s.idle && s.weights.muA !== undefined;
});
s = await settled();
const aligned = await client.align({ basisId: fourBasis.id,
  weights: { muS: s.weights.muS, muB: s.weights.muB, muC: s.weights.muA } });
const alignError = relativeError(s.coefficients, aligned.coefficients);
check(alignError <= 1e-9, `curvature alignment equals Align (relative error ${alignError.toExponential(2)})`);
await page.uncheck("#curvature");
await until("the session without curvature", () => {
  const s = window.__studio.state();
  return !s.curvature && s.ready && s.idle && s.weights.muA === undefined;
});
await checkAgainstSolve("curvature off");
// The switch is one undo step each way.
await page.click("#undo");
await until("curvature back on by undo", () => {
  const s = window.__studio.state();
  return s.curvature && s.ready && s.idle && s.weights.muA !== undefined;
});
s = await settled();
check(relativeError(s.coefficients, aligned.coefficients) <= 1e-9 &&
  (await page.isChecked("#curvature")), "undo: curvature alignment again, the box checked");
await page.click("#redo");
await until("curvature off by redo", () => {
  const s = window.__studio.state();
  return !s.curvature && s.ready && s.idle && s.weights.muA === undefined;
});
await checkAgainstSolve("redo: curvature off");
check(!(await page.isChecked("#curvature")), "redo: the box unchecked");

// Screen points whose rays hit a face well inside, cast here.
const canvasBox = await page.locator("#stage canvas").boundingBox();
let camera = await page.evaluate(() => window.__studio.camera());
const toPage = (x, y) => [canvasBox.x + x, canvasBox.y + y];
function findPoint(x0, y0) {
  for (let r = 0; r < 200; r += 3) {
    for (let a = 0; a < 16; a++) {
      const x = x0 + r * Math.cos((a * Math.PI) / 8), y = y0 + r * Math.sin((a * Math.PI) / 8);
      const hit = castRay(cameraRay(camera, x, y), geometry.vertices, geometry.faces);
      if (hit && Math.min(...hit.bary) > 0.1) return { x, y, hit };
    }
  }
  throw new Error(`no face near (${x0}, ${y0})`);
}
const vertexAt = (v) => geometry.vertices.slice(3 * v, 3 * v + 3);

// 5. A singularity of index +1/4, hard, placed by clicking: at the vertex of the clicked face
// nearest the click, found there by Singularities.
await page.check("input[name=tool][value=singularity]");
await page.selectOption("#sing-index", "0.25");
await page.check("#new-hard");
const click = findPoint(camera.width * 0.5, camera.height * 0.45);
const corners = [0, 1, 2].map((k) => geometry.faces[3 * click.hit.face + k]);
const distances = corners.map((v) => Math.hypot(...vertexAt(v).map((p, k) => p - click.hit.point[k])));
const vertex = corners[distances.indexOf(Math.min(...distances))];
await page.mouse.click(...toPage(click.x, click.y));
await until("the placed singularity", () => window.__studio.state().constraints
  .some((c) => c.tool === "singularity"));
s = await checkAgainstSolve("a placed singularity");
const placed = s.constraints.find((c) => c.tool === "singularity");
check(placed.vertex === vertex && placed.index === 0.25 && placed.hard,
  `the singularity is at the vertex nearest the click (${vertex}, page: ${placed.vertex}), ` +
  "index 1/4, hard");
let sing = await client.singularities({ basisId: fourBasis.id, coefficients: s.coefficients });
const found = sing.singularities.find((x) => x.vertex === vertex);
check(sing.n === 4 && found?.index === 1, `Singularities finds index ${found?.index}/4 at vertex ${vertex}`);
check(s.singularities === sing.singularities.length,
  `the page marks ${s.singularities} singularities, the daemon counts ${sing.singularities.length}`);
await page.waitForTimeout(300);
writeFileSync(join(args.out, "studio-singularity.png"), await page.screenshot());

// Dragged by its marker to another vertex (one `move {id, group}` per vertex passed): there it is.
const markerAt = project(camera, vertexAt(vertex));
const away = findPoint(markerAt[0] + 70, markerAt[1] + 40);
const awayCorners = [0, 1, 2].map((k) => geometry.faces[3 * away.hit.face + k]);
const awayDistances = awayCorners.map((v) => Math.hypot(...vertexAt(v).map((p, k) =>
  p - away.hit.point[k])));
const target = awayCorners[awayDistances.indexOf(Math.min(...awayDistances))];
await page.mouse.move(...toPage(markerAt[0], markerAt[1]));
await page.mouse.down();
await page.mouse.move(...toPage(away.x, away.y), { steps: 10 });
await page.mouse.up();
await until("the moved singularity", (v) => window.__studio.state().constraints
  .some((c) => c.tool === "singularity" && c.vertex === v), target);
s = await checkAgainstSolve("the singularity dragged to another vertex");
sing = await client.singularities({ basisId: fourBasis.id, coefficients: s.coefficients });
check(s.constraints.length === 1 && target !== vertex &&
  sing.singularities.find((x) => x.vertex === target)?.index === 1,
  `the singularity moved from vertex ${vertex} to vertex ${target}, where Singularities finds it`);
await page.click("#undo");
await until("the undone move", (v) => window.__studio.state().constraints
  .some((c) => c.tool === "singularity" && c.vertex === v), vertex);
s = await checkAgainstSolve("undo the move (one step)");
await page.click("#undo");
await until("the undone singularity", () => window.__studio.state().constraints.length === 0);
await checkAgainstSolve("undo the singularity");
await page.click("#redo");
await until("the redone singularity", () => window.__studio.state().constraints.length === 1);
s = await checkAgainstSolve("redo the singularity");

// 6. Downloads of the whole field: .rawfield (N = 4 directions per face) and .vtu, against a Lift
// of the session's coefficients done here.
const lifted = [];
for await (const chunk of client.lift({ basisId: fourBasis.id, coefficients: s.coefficients,
  encoding: pb.FieldEncoding.AMBIENT })) lifted.push(...chunk.field.values);
const F = geometry.faces.length / 3;
const normalOf = (f) => {
  const [a, b, c] = [0, 1, 2].map((k) => vertexAt(geometry.faces[3 * f + k]));
  const e1 = b.map((x, k) => x - a[k]), e2 = c.map((x, k) => x - a[k]);
  const n = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]];
  const l = Math.hypot(...n);
  return n.map((x) => x / l);
};
async function downloadText(button) {
  const [download] = await Promise.all([page.waitForEvent("download"), page.click(button)]);
  return [download.suggestedFilename(), readFileSync(await download.path(), "utf8")];
}
const [rawName, raw] = await downloadText("#rawfield");
const rawLines = raw.trimEnd().split("\n");
let worst = 0;
for (let f = 0; f < F; f++) {
  const d = rawLines[1 + f].split(" ").map(Number);
  const u = lifted.slice(3 * f, 3 * f + 3);
  const n = normalOf(f);
  const turned = [n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]];
  const want = [...u, ...turned, ...u.map((x) => -x), ...turned.map((x) => -x)];
  for (let k = 0; k < 12; k++) worst = Math.max(worst, Math.abs(d[k] - want[k]));
}
check(rawName.endsWith(".rawfield") && rawLines[0] === `4 ${F}` && rawLines.length === F + 1 &&
  worst < 1e-6, `${rawName}: "4 ${F}" and per face the lifted direction and its quarter turns ` +
  `(largest difference ${worst.toExponential(2)})`);
const [vtuName, vtu] = await downloadText("#vtu");
const array = (name) => {
  const m = new RegExp(`Name="${name}"[^>]*>\\n([\\s\\S]*?)</DataArray>`).exec(vtu);
  return m ? m[1].trim().split(/\s+/).map(Number) : null;
};
const dir0 = array("field_dir0");
const connectivity = array("connectivity");
check(vtuName.endsWith(".vtu") && vtu.includes(`NumberOfPoints="${geometry.vertices.length / 3}" ` +
  `NumberOfCells="${F}"`) && connectivity.every((v, i) => v === geometry.faces[i]) &&
  dir0?.length === 3 * F && dir0.every((x, i) => Math.abs(x - lifted[i]) < 1e-12) &&
  array("field_dir3")?.length === 3 * F,
  `${vtuName}: the mesh's triangles and the field's 4 directions as cell arrays`);

// 7. A stroke drawn with the stroke tool (soft): picked points every 8 px on screen, sent as one
// add_stroke; selected by clicking it, deleted, and the delete undone.
await chooseBasis(page, vectorBasis.id);
await checkAgainstSolve("the vector basis");
await page.check("input[name=tool][value=stroke]");
await page.uncheck("#new-hard");
camera = await page.evaluate(() => window.__studio.camera());
// A screen segment of ~220 px whose every point is on the surface (the torus has a hole).
let from = null, to = null;
for (let y = 0.2; y < 0.85 && to === null; y += 0.05) {
  for (let x = 0.2; x < 0.6 && to === null; x += 0.05) {
    const a = findPoint(camera.width * x, camera.height * y);
    const b = { x: a.x + 200, y: a.y - 80 };
    const onSurface = Array.from({ length: 41 }, (_, i) => castRay(cameraRay(camera,
      a.x + (i / 40) * (b.x - a.x), a.y + (i / 40) * (b.y - a.y)), geometry.vertices, geometry.faces))
      .every((hit) => hit !== null);
    const end = castRay(cameraRay(camera, b.x, b.y), geometry.vertices, geometry.faces);
    if (onSurface && Math.min(...end.bary) > 0.1) [from, to] = [a, { ...b, hit: end }];
  }
}
check(to !== null, `a stroke path on the surface from (${from?.x}, ${from?.y}) to (${to?.x}, ${to?.y})`);
await page.mouse.move(...toPage(from.x, from.y));
await page.mouse.down();
await page.mouse.move(...toPage(to.x, to.y), { steps: 40 });
await page.mouse.up();
await until("the stroke", () => window.__studio.state().constraints.some((c) => c.tool === "stroke"));
s = await checkAgainstSolve("a stroke");
const stroke = s.constraints.find((c) => c.tool === "stroke");
const pointAt = (p) => [0, 1, 2].map((k) => p.barycentric.reduce((acc, b, c) =>
  acc + b * geometry.vertices[3 * geometry.faces[3 * p.face + c] + k], 0));
const screen = stroke.points.map((p) => project(camera, pointAt(p)));
const gaps = screen.slice(1).map((q, i) => Math.hypot(q[0] - screen[i][0], q[1] - screen[i][1]));
check(stroke.points[0].face === from.hit.face && stroke.points.at(-1).face === to.hit.face &&
  Math.hypot(...stroke.points[0].barycentric.map((b, k) => b - from.hit.bary[k])) < 1e-3,
  `the stroke runs from face ${from.hit.face} to face ${to.hit.face}, where the drag began and ended`);
check(stroke.points.length >= 5 && gaps.slice(0, -1).every((g) => g >= 7.5) && !stroke.hard &&
  stroke.weight === 1, `${stroke.points.length} points, at least 8 px apart on screen, soft`);
await page.waitForTimeout(300);
writeFileSync(join(args.out, "studio-stroke.png"), await page.screenshot());
await page.check("input[name=tool][value=constraint]");
const middle = screen[Math.floor(screen.length / 2)];
await page.mouse.click(...toPage(middle[0], middle[1]));
await until("the selected stroke", () => /stroke of/.test(document.querySelector("#constraint-info")
  .textContent));
await page.keyboard.press("Delete");
await until("the deleted stroke", () => window.__studio.state().constraints.length === 0);
await checkAgainstSolve("delete the stroke");
await page.click("#undo");
await until("the undone delete", () => window.__studio.state().constraints.length === 1);
s = await checkAgainstSolve("undo the delete");
check(JSON.stringify(s.constraints[0]) === JSON.stringify(stroke), "the stroke is back as it was");
await page.click("#undo");
await until("the undone stroke", () => window.__studio.state().constraints.length === 0);
await checkAgainstSolve("undo the stroke (one step)");
await page.click("#redo");
await until("the redone stroke", () => window.__studio.state().constraints.length === 1);
s = await checkAgainstSolve("redo the stroke");

// Dragging the stroke moves it as a whole: each point goes to the surface under its screen
// position plus the drag (one move of the group), and one undo puts it back.
let shift = null;
for (const [dx, dy] of [[24, 16], [-24, 16], [24, -16], [-24, -16], [12, 0], [0, 12], [-12, 0],
  [0, -12], [6, 6], [-6, -6]]) {
  const hits = screen.map(([x, y]) => castRay(cameraRay(camera, x + dx, y + dy), geometry.vertices,
    geometry.faces));
  // Away from the faces' edges, where the page's pick and this ray cast could disagree.
  if (hits.every((h) => h !== null && Math.min(...h.bary) > 1e-3)) {
    shift = { dx, dy, faces: hits.map((h) => h.face) };
    break;
  }
}
check(shift !== null, "an offset that keeps the stroke on the surface");
await page.mouse.move(...toPage(middle[0], middle[1]));
await page.mouse.down();
await page.mouse.move(...toPage(middle[0] + shift.dx, middle[1] + shift.dy), { steps: 12 });
await page.mouse.up();
await until("the moved stroke", (faces) => {
  const c = window.__studio.state().constraints[0];
  return c?.tool === "stroke" && JSON.stringify(c.points.map((p) => p.face)) === faces;
}, JSON.stringify(shift.faces));
s = await checkAgainstSolve("move the stroke by a drag");
check(s.constraints.length === 1 && s.constraints[0].points.length === stroke.points.length,
  `the stroke moved by (${shift.dx}, ${shift.dy}) px: its ${stroke.points.length} points on the faces under them`);
await page.click("#undo");
await until("the undone move", (want) => JSON.stringify(window.__studio.state().constraints[0]) ===
  want, JSON.stringify(stroke));
await checkAgainstSolve("undo the move (one step)");

// A reload reopens the session with the stroke (replayed as add_stroke).
await page.reload();
s = await checkAgainstSolve("reload");
check(s.basisId === vectorBasis.id && s.constraints.length === 1 &&
  JSON.stringify(s.constraints[0]) === JSON.stringify(stroke), "the reload brought the stroke back");

// 8. The glyph sample follows the zoom: zooming in watches a denser sample of the faces in view,
// about as dense on screen as before, and the updates carry the values of those faces.
await chooseBasis(page, fineBasis.id);
await checkAgainstSolve("the finer torus");
const fine = { vertices: [], faces: [] };
for await (const chunk of client.getMeshGeometry({ meshId: fineTorus.id })) {
  fine.vertices.push(...chunk.vertices);
  fine.faces.push(...chunk.faces);
}
const sampleOf = () => page.evaluate(() => window.__studio.sample());
// The median distance on screen from each sampled face's centroid to the nearest other one, and
// whether all of them are in the view.
function screenSpacing(sample, cam) {
  const points = sample.faces.map((f) => project(cam, [0, 1, 2].map((k) =>
    [0, 1, 2].reduce((acc, c) => acc + fine.vertices[3 * fine.faces[3 * f + c] + k], 0) / 3)));
  const nearest = points.map((p, i) => Math.min(...points.map((q, j) => (i === j ? Infinity
    : Math.hypot(p[0] - q[0], p[1] - q[1])))));
  nearest.sort((a, b) => a - b);
  const inside = points.every(([x, y]) => x >= -1 && y >= -1 && x <= cam.width + 1 && y <= cam.height + 1);
  return { median: nearest[Math.floor(nearest.length / 2)], inside };
}
camera = await page.evaluate(() => window.__studio.camera());
const before = await sampleOf();
const spacingBefore = screenSpacing(before, camera);
await page.mouse.move(...toPage(camera.width / 2, camera.height / 2));
for (let i = 0; i < 4; i++) {
  await page.mouse.wheel(0, -250);
  await page.waitForTimeout(50);
}
// The page samples again 250 ms after the camera's last change: past that, the sample is the
// last view's (an earlier one may have been taken between two wheel steps).
await page.waitForTimeout(800);
await until("a denser sample", (h) => {
  const s = window.__studio.state();
  const sample = window.__studio.sample();
  return s.spacing < 0.7 * h && s.idle && sample.watchedFaces.join() === sample.faces.join();
}, before.spacing);
s = await settled();
const after = await sampleOf();
camera = await page.evaluate(() => window.__studio.camera());
const spacingAfter = screenSpacing(after, camera);
check(spacingAfter.inside && spacingAfter.median > 0.6 * spacingBefore.median &&
  spacingAfter.median < 1.6 * spacingBefore.median,
  `zoomed in: spacing ${before.spacing.toFixed(4)} -> ${after.spacing.toFixed(4)}, ` +
  `${after.faces.length} faces in view (before: ${before.faces.length}), ` +
  `${spacingAfter.median.toFixed(1)} px apart on screen (before: ${spacingBefore.median.toFixed(1)} px)`);
const watchedLift = [];
for await (const chunk of client.lift({ basisId: fineBasis.id, coefficients: s.coefficients,
  faces: after.watchedFaces, encoding: pb.FieldEncoding.AMBIENT })) watchedLift.push(...chunk.field.values);
const watchError = relativeError(after.watchedValues, watchedLift);
check(watchError < 1e-6, `the watched values are the field on the new sample (relative error ` +
  `${watchError.toExponential(2)})`);
await checkAgainstSolve("after the zoom");

await browser.close();
cleanup();
console.log("studio_tools: all checks passed");
