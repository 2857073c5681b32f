// The studio in a real headless Chromium against a real daemon: choose a basis, add a constraint
// by dragging on the surface, drag it to another face, move a weight slider, undo, reload. After
// each step the page's coefficients equal a Solve over the wire with the page's constraints and
// weights (1e-9 relative), and the faces the page edited are the faces this test finds by casting
// the same screen rays itself. A screenshot shows the glyphs over the mesh.
// The gateway is started with the command line of README.md's studio block (its addresses
// replaced), so that the README's way to start the studio by hand is run here.
//   node studio_design_test.mjs --web-dir client/web --daemon build/bin/fieldspaced --out DIR
//       --readme README.md
import { readFileSync, writeFileSync } from "node:fs";
import { join } from "node:path";
import {
  castRay, cameraRay, check, chooseBasis, cleanup, decodePng, dot, faceCentroid, faceNormal,
  launchChromium, pageProbe, parseArgs, project, readmeGatewayArgs, startDaemon, startGateway,
  torusObj,
  uploadAndBuild, webModules,
} from "./studio_lib.mjs";

const args = parseArgs(process.argv.slice(2));
const { chromium, daemonClient, pb } = await webModules(args["web-dir"]);
const daemon = await startDaemon(args.daemon);
const client = daemonClient(daemon.address);
const { mesh, basis } = await uploadAndBuild(client, pb, torusObj(), "torus.obj",
  { kind: pb.FieldKind.VECTOR }, 40);
check(basis?.state === pb.BasisState.READY, `basis ${basis?.id} built`);
// A 4-field and a tensor basis of the same mesh, for their glyphs and constraint values.
const others = [];
for (const [name, field] of [["4-field", { kind: pb.FieldKind.NFIELD, n: 4 }],
  ["tensor", { kind: pb.FieldKind.TENSOR }]]) {
  let built = null;
  for await (const progress of client.buildBasis({ meshId: mesh.id, field, dimension: 40 })) {
    if (progress.basis) built = progress.basis;
  }
  others.push({ name, basis: built });
}
const geometry = { vertices: [], faces: [] };
for await (const chunk of client.getMeshGeometry({ meshId: mesh.id })) {
  geometry.vertices.push(...chunk.vertices);
  geometry.faces.push(...chunk.faces);
}
const gateway = await startGateway(args["web-dir"],
  readmeGatewayArgs(args.readme, "tests/studio/studio_design_test.mjs", daemon.address));
const browser = await launchChromium(chromium);
const page = await browser.newPage({ viewport: { width: 1100, height: 760 } });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
page.on("console", (m) => m.type() === "error" && console.error(`page console: ${m.text()}`));

const { checkAgainstSolve, until } = pageProbe(page, client, pb);

await page.goto(gateway.url);
await chooseBasis(page, basis.id);
let s = await checkAgainstSolve("open");
check(s.constraints.length === 0 && s.sampleFaces > 100, `no constraints, ${s.sampleFaces} glyph faces`);

// Screen points, in page coordinates, whose rays hit a face well inside (not near an edge, so that
// float32 picking in the page and float64 here agree).
const canvasBox = await page.locator("#stage canvas").boundingBox();
const camera = await page.evaluate(() => window.__studio.camera());
function hitAt(x, y) {
  const hit = castRay(cameraRay(camera, x, y), geometry.vertices, geometry.faces);
  return hit && Math.min(...hit.bary) > 0.15 ? hit : null;
}
function findPoint(x0, y0, avoidFace) {
  for (let r = 0; r < 200; r += 3) {
    for (let a = 0; a < 16; a++) {
      const x = x0 + r * Math.cos((a * Math.PI) / 8), y = y0 + r * Math.sin((a * Math.PI) / 8);
      const hit = hitAt(x, y);
      if (hit && hit.face !== avoidFace) return { x, y, hit };
    }
  }
  throw new Error(`no face near (${x0}, ${y0})`);
}
const toPage = (p) => [canvasBox.x + p.x, canvasBox.y + p.y];

// Drags from the face near canvas point (x0, y0) by (dx, dy) pixels; resolves to the face hit
// (cast here) and the unit drag direction in its tangent plane.
async function dragOnSurface(x0, y0, dx, dy) {
  const start = findPoint(x0, y0);
  const [x, y] = toPage(start);
  await page.mouse.move(x, y);
  await page.mouse.down();
  await page.mouse.move(x + dx / 2, y + dy / 2, { steps: 4 });
  await page.mouse.move(x + dx, y + dy, { steps: 4 });
  await page.mouse.up();
  const normal = faceNormal(geometry.vertices, geometry.faces, start.hit.face);
  const ray = cameraRay(camera, start.x + dx, start.y + dy);
  const t = dot(normal, start.hit.point.map((p, k) => p - ray.origin[k])) /
    dot(normal, ray.direction);
  const end = ray.origin.map((o, k) => o + t * ray.direction[k]);
  const d = end.map((e, k) => e - start.hit.point[k]);
  const l = Math.hypot(...d);
  return { ...start, d: d.map((x) => x / l) };
}

// A screenshot must show glyphs over the mesh: pixels that change when the glyphs are hidden are
// glyph pixels, and most of them lie where the mesh is (not the background).
async function checkPicture(what, file) {
  await page.waitForTimeout(200);  // the last update's frame
  const shot = await page.screenshot({ clip: canvasBox });
  writeFileSync(join(args.out, file), shot);
  await page.evaluate(() => window.__studio.showGlyphs(false));
  const bare = decodePng(await page.screenshot({ clip: canvasBox }));
  await page.evaluate(() => window.__studio.showGlyphs(true));
  const full = decodePng(shot);
  const background = [0xf4, 0xf4, 0xf2];
  let glyphPixels = 0, overMesh = 0, meshPixels = 0;
  for (let i = 0; i < bare.width * bare.height; i++) {
    const isBackground = [0, 1, 2].every((k) => Math.abs(bare.rgba[4 * i + k] - background[k]) <= 2);
    if (!isBackground) meshPixels += 1;
    let diff = 0;
    for (let k = 0; k < 3; k++) diff = Math.max(diff, Math.abs(full.rgba[4 * i + k] - bare.rgba[4 * i + k]));
    if (diff > 40) {
      glyphPixels += 1;
      if (!isBackground) overMesh += 1;
    }
  }
  const area = bare.width * bare.height;
  check(meshPixels > 0.1 * area,
    `${what}: the mesh covers ${(100 * meshPixels / area).toFixed(1)}% of the view`);
  check(glyphPixels > 0.005 * area && overMesh > 0.9 * glyphPixels, `${what}: ${glyphPixels} ` +
    `glyph pixels, ${(100 * overMesh / Math.max(1, glyphPixels)).toFixed(1)}% over the mesh`);
}

// 1. Add: press on a face, drag 40 px to the right, release.
const start = findPoint(camera.width * 0.45, camera.height * 0.55);
const [px, py] = toPage(start);
await page.mouse.move(px, py);
await page.mouse.down();
await page.mouse.move(px + 20, py, { steps: 4 });
await page.mouse.move(px + 40, py, { steps: 4 });
await page.mouse.up();
s = await checkAgainstSolve("add by dragging");
check(s.constraints.length === 1 && s.constraints[0].face === start.hit.face,
  `the constraint is on the face under the press (${start.hit.face}, page: ${s.constraints[0]?.face})`);
// Its value: the drag's direction in the face's tangent plane, as cast here.
const n = faceNormal(geometry.vertices, geometry.faces, start.hit.face);
const endRay = cameraRay(camera, start.x + 40, start.y);
const t = dot(n, start.hit.point.map((p, k) => p - endRay.origin[k])) / dot(n, endRay.direction);
const end = endRay.origin.map((o, k) => o + t * endRay.direction[k]);
const want = end.map((e, k) => e - start.hit.point[k]);
const cosine = dot(want, s.constraints[0].value) / Math.hypot(...want) /
  Math.hypot(...s.constraints[0].value);
check(cosine > 0.999, `the value is the drag direction in the tangent plane (cos ${cosine.toFixed(5)})`);

// 2. Move: press on the marker (the face's centroid on screen) and drag it to another face.
const markerAt = project(camera, faceCentroid(geometry.vertices, geometry.faces, start.hit.face));
const target = findPoint(markerAt[0] + 90, markerAt[1] - 60, start.hit.face);
const [mx, my] = toPage({ x: markerAt[0], y: markerAt[1] });
const [tx, ty] = toPage(target);
const valueBefore = s.constraints[0].value;
await page.mouse.move(mx, my);
await page.mouse.down();
await page.mouse.move(tx, ty, { steps: 12 });
await page.mouse.up();
s = await checkAgainstSolve("drag to another face");
check(s.constraints.length === 1 && s.constraints[0].face === target.hit.face,
  `the constraint moved to the face under the release (${target.hit.face}, page: ${s.constraints[0].face})`);
check(s.constraints[0].value.every((v, k) => v === valueBefore[k]), "moving keeps its value");

// A second constraint against the first's direction (the field turns between them).
const second = await dragOnSurface(camera.width * 0.62, camera.height * 0.35, -40, 10);
s = await checkAgainstSolve("a second constraint");
check(s.constraints.length === 2 && s.constraints[1].face === second.hit.face,
  `the second constraint is on face ${second.hit.face}`);

// 3. A weight slider: five steps of mu_s by keyboard (each step re-solves; coalesced in flight).
await page.focus("#mu-s");
for (let i = 0; i < 5; i++) await page.keyboard.press("ArrowRight");
s = await checkAgainstSolve("mu_s slider");
check(Math.abs(s.weights.muS - 10 ** 0.5) < 1e-9, `mu_s = 10^0.5 (${s.weights.muS})`);

// 4. Undo: the last slider step.
await page.click("#undo");
await until("mu_s undone", () => Math.abs(window.__studio.state().weights.muS - 10 ** 0.4) < 1e-9);
s = await checkAgainstSolve("undo");
check(s.constraints.length === 2 && s.constraints[0].face === target.hit.face,
  "undo of a weight keeps the constraints");

// 5. Reload: the session comes back with its constraints and weights.
const before = s;
await page.reload();
s = await checkAgainstSolve("reload");
check(JSON.stringify(s.constraints) === JSON.stringify(before.constraints) &&
  Math.abs(s.weights.muS - before.weights.muS) < 1e-15, "the reload resumed the constraints and weights");

// Select the first constraint by clicking its marker, make it hard, then soft with weight 3,
// delete it, and undo the delete.
const first = s.constraints[0];
const firstAt = project(camera, faceCentroid(geometry.vertices, geometry.faces, first.face));
await page.mouse.click(...toPage({ x: firstAt[0], y: firstAt[1] }));
await until("the selection", () => !document.querySelector("#constraint").disabled);
await page.check("#hard");
s = await checkAgainstSolve("hard");
check(s.constraints.find((c) => c.id === first.id)?.hard === true, "the selected constraint is hard");
await page.uncheck("#hard");
await page.fill("#weight", "3");
await page.press("#weight", "Enter");
await until("weight 3", (id) => window.__studio.state().constraints
  .some((c) => c.id === id && c.weight === 3 && !c.hard), first.id);
s = await checkAgainstSolve("soft, weight 3");
await page.click("#delete");
await until("the delete", () => window.__studio.state().constraints.length === 1);
s = await checkAgainstSolve("delete");
await page.click("#undo");
await until("the undone delete", () => window.__studio.state().constraints.length === 2);
s = await checkAgainstSolve("undo the delete");
const restored = s.constraints.find((c) => c.id === first.id);
check(restored?.face === first.face && restored.weight === 3 && !restored.hard,
  "undo brought the deleted constraint back as it was");

// Singularities as the daemon counts them for the same coefficients.
const sing = await client.singularities({ basisId: basis.id, coefficients: s.coefficients });
check(s.singularities === sing.singularities.length,
  `singularities shown: ${s.singularities}, the daemon's: ${sing.singularities.length}`);

// 6. The picture: glyphs drawn over the mesh.
await checkPicture("vector field", "studio.png");

// The PNG button downloads the view: a PNG of the canvas's size.
const [download] = await Promise.all([page.waitForEvent("download"), page.click("#png")]);
const png = decodePng(readFileSync(await download.path()));
check(png.width === Math.round(canvasBox.width) && png.height === Math.round(canvasBox.height) &&
  /\.png$/.test(download.suggestedFilename()), `PNG download: ${download.suggestedFilename()}, ` +
  `${png.width}x${png.height}`);

// 7. A 4-field and a tensor field: a constraint by dragging (its value: the drag direction, or
// d d^T for the tensor), the coefficients against Solve, the picture.
for (const { name, basis: other } of others) {
  await chooseBasis(page, other.id);
  await checkAgainstSolve(`${name}: open`);
  const { hit, d } = await dragOnSurface(camera.width * 0.55, camera.height * 0.4, 0, 40);
  s = await checkAgainstSolve(`${name}: add by dragging`);
  const c = s.constraints[0];
  const want = name === "tensor" ? [d[0] * d[0], d[1] * d[1], d[2] * d[2], d[0] * d[1], d[1] * d[2],
    d[2] * d[0]] : d;
  const cos = want.reduce((acc, w, k) => acc + w * c.value[k], 0) /
    Math.hypot(...want) / Math.hypot(...c.value);
  check(s.constraints.length === 1 && c.face === hit.face && cos > 0.999,
    `${name}: the constraint is on face ${hit.face} with the drag's value (cos ${cos.toFixed(5)})`);
  if (name === "4-field") {
    // Two hard constraints at odds with each other: the 4-field gets singular vertices, which the
    // page marks as the daemon counts them.
    await page.evaluate(() => {
      window.__studio.edit({ kind: "add", id: 100,
        constraint: { face: 0, value: [0, 0, 1], hard: true, weight: 1 } });
      window.__studio.edit({ kind: "add", id: 101,
        constraint: { face: 1200, value: [1, 0, 0], hard: true, weight: 1 } });
    });
    s = await checkAgainstSolve(`${name}: two hard constraints`);
    const sing = await client.singularities({ basisId: other.id, coefficients: s.coefficients });
    const labels = await page.locator(".labels span").count();
    check(sing.singularities.length > 0 && s.singularities === sing.singularities.length &&
      labels === s.singularities, `${name}: ${labels} singularities marked, the daemon's: ` +
      `${sing.singularities.length}`);
    // The whole page, as docs/images/studio.png shows it (the panel from its top).
    await page.evaluate(() => document.querySelector("#panel").scrollTo(0, 0));
    await page.waitForTimeout(200);
    writeFileSync(join(args.out, "studio-page.png"), await page.screenshot());
  }
  await checkPicture(name, `studio-${name}.png`);
}

await browser.close();
cleanup();
console.log("studio_design: all checks passed");
