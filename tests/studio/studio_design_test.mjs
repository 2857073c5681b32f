// The studio in a real headless Chromium against a real daemon: choose a basis, add a constraint
// by dragging on the surface, drag it to another face, move a weight slider, undo, reload. After
// each step the page's coefficients equal a Solve over the wire with the page's constraints and
// weights (1e-9 relative), and the faces the page edited are the faces this test finds by casting
// the same screen rays itself. A screenshot shows the glyphs over the mesh.
//   node studio_design_test.mjs --web-dir client/web --daemon build/bin/fieldspaced --out DIR
import { writeFileSync } from "node:fs";
import { join } from "node:path";
import {
  castRay, cameraRay, check, chooseBasis, cleanup, decodePng, dot, faceCentroid, faceNormal,
  launchChromium, pageProbe, parseArgs, project, startDaemon, startGateway, torusObj,
  uploadAndBuild, webModules,
} from "./studio_lib.mjs";

const args = parseArgs(process.argv.slice(2));
const { chromium, daemonClient, pb } = await webModules(args["web-dir"]);
const daemon = await startDaemon(args.daemon);
const client = daemonClient(daemon.address);
const { mesh, basis } = await uploadAndBuild(client, pb, torusObj(), "torus.obj",
  { kind: pb.FieldKind.VECTOR }, 40);
check(basis?.state === pb.BasisState.READY, `basis ${basis?.id} built`);
const geometry = { vertices: [], faces: [] };
for await (const chunk of client.getMeshGeometry({ meshId: mesh.id })) {
  geometry.vertices.push(...chunk.vertices);
  geometry.faces.push(...chunk.faces);
}
const gateway = await startGateway(args["web-dir"], ["--daemon", daemon.address]);
const browser = await launchChromium(chromium);
const page = await browser.newPage({ viewport: { width: 1100, height: 760 } });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
page.on("console", (m) => m.type() === "error" && console.error(`page console: ${m.text()}`));

const { checkAgainstSolve } = pageProbe(page, client, pb);

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

// 3. A weight slider: five steps of mu_s by keyboard (each step re-solves; coalesced in flight).
await page.focus("#mu-s");
for (let i = 0; i < 5; i++) await page.keyboard.press("ArrowRight");
s = await checkAgainstSolve("mu_s slider");
check(Math.abs(s.weights.muS - 10 ** 0.5) < 1e-9, `mu_s = 10^0.5 (${s.weights.muS})`);

// 4. Undo: the last slider step.
await page.click("#undo");
await page.waitForFunction(() => Math.abs(window.__studio.state().weights.muS - 10 ** 0.4) < 1e-9);
s = await checkAgainstSolve("undo");
check(s.constraints.length === 1 && s.constraints[0].face === target.hit.face,
  "undo of a weight keeps the constraint");

// 5. Reload: the session comes back with its constraints and weights.
const before = s;
await page.reload();
s = await checkAgainstSolve("reload");
check(JSON.stringify(s.constraints) === JSON.stringify(before.constraints) &&
  Math.abs(s.weights.muS - before.weights.muS) < 1e-15, "the reload resumed the constraints and weights");

// Singularities as the daemon counts them for the same coefficients.
const sing = await client.singularities({ basisId: basis.id, coefficients: s.coefficients });
check(s.singularities === sing.singularities.length,
  `singularities shown: ${s.singularities}, the daemon's: ${sing.singularities.length}`);

// 6. The picture: glyphs drawn over the mesh. Pixels that change when the glyphs are hidden are
// glyph pixels; most of them must lie where the mesh is (not the background).
const clip = canvasBox;
const shot = await page.screenshot({ clip });
writeFileSync(join(args.out, "studio.png"), shot);
await page.evaluate(() => window.__studio.showGlyphs(false));
const bare = decodePng(await page.screenshot({ clip }));
await page.evaluate(() => window.__studio.showGlyphs(true));
const full = decodePng(shot);
const background = [0xf4, 0xf4, 0xf2];
let glyphPixels = 0, overMesh = 0, meshPixels = 0;
for (let i = 0; i < bare.width * bare.height; i++) {
  const isBackground = [0, 1, 2].every((k) => Math.abs(bare.rgba[4 * i + k] - background[k]) <= 2);
  if (!isBackground) meshPixels += 1;
  const diff = [0, 1, 2].reduce((m, k) => Math.max(m, Math.abs(full.rgba[4 * i + k] - bare.rgba[4 * i + k])), 0);
  if (diff > 40) {
    glyphPixels += 1;
    if (!isBackground) overMesh += 1;
  }
}
const area = bare.width * bare.height;
check(meshPixels > 0.1 * area, `the mesh covers ${(100 * meshPixels / area).toFixed(1)}% of the view`);
check(glyphPixels > 0.005 * area && overMesh > 0.9 * glyphPixels,
  `${glyphPixels} glyph pixels, ${(100 * overMesh / Math.max(1, glyphPixels)).toFixed(1)}% over the mesh`);

await browser.close();
cleanup();
console.log("studio_design: all checks passed");
