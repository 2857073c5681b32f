// The studio behind the scale-out router: deploy/local-fleet.sh starts 2 fieldspaced replicas on a
// shared store behind nginx (docs/scale-out.md, "A local fleet"), the gateway calls the router.
// The page opens a session and adds two constraints (and an add the daemon refuses); the replica
// that serves the session (the one nginx hashed the basis id to) is SIGKILLed; the next edit
// resumes the session on the other replica through the gateway's replay, and the page's
// coefficients equal a Solve of the same constraints. Exit 77 without nginx or Chromium.
//   node studio_fleet_test.mjs --web-dir client/web --daemon build/bin/fieldspaced
import { spawn } from "node:child_process";
import { existsSync, readFileSync } from "node:fs";
import { dirname, join, resolve } from "node:path";
import { fileURLToPath } from "node:url";
import {
  check, chooseBasis, cleanup, launchChromium, pageProbe, parseArgs, startGateway, tempDir,
  torusObj, uploadAndBuild, webModules,
} from "./studio_lib.mjs";

const args = parseArgs(process.argv.slice(2));
const script = resolve(dirname(fileURLToPath(import.meta.url)), "..", "..", "deploy",
  "local-fleet.sh");
const nginx = process.env.NGINX ?? ["/usr/sbin/nginx", "/usr/bin/nginx"].find(existsSync);
if (!nginx) {
  console.log("SKIP: no nginx (.ci/install-deps installs nginx-light)");
  process.exit(77);
}
const started = performance.now();
const { chromium, daemonClient, pb } = await webModules(args["web-dir"]);

// --- The fleet: its lines `replica: PID ADDRESS NAME`, `work: DIR`, then `router: ADDRESS`.
const fleet = spawn(script, ["-n", "2", "--port", "0", "--bin-dir", dirname(args.daemon), "--",
  "--threads", "1"], { stdio: ["ignore", "pipe", "inherit"],
  env: { ...process.env, NGINX: nginx, TMPDIR: tempDir("studio-fleet-") } });
const stopFleet = () => new Promise((done) => {
  if (fleet.exitCode !== null) done();
  fleet.once("exit", done);
  fleet.kill("SIGTERM");
});
process.on("exit", () => fleet.exitCode === null && fleet.kill("SIGTERM"));
const lines = await new Promise((done, fail) => {
  let out = "";
  const timer = setTimeout(() => fail(new Error(`no router line in 60 s:\n${out}`)), 60000);
  fleet.stdout.on("data", (d) => {
    out += d;
    if (/^router: \S+$/m.test(out)) {
      clearTimeout(timer);
      done(out.split("\n"));
    }
  });
  fleet.once("exit", (code) => fail(new Error(`local-fleet.sh exited (${code}):\n${out}`)));
});
const value = (key) => lines.filter((l) => l.startsWith(`${key}: `)).map((l) => l.slice(key.length + 2));
const replicas = new Map(value("replica").map((v) => v.split(" ")).map(([pid, address]) =>
  [address, Number(pid)]));
const [work] = value("work");
const [router] = value("router");
check(replicas.size === 2 && work && router, `2 replicas ${[...replicas.keys()]} behind ${router}`);

// Upstreams nginx logged for calls of `method` with routing key `key`, in order (its log format:
// $remote_addr $request_uri "$http_x_fieldspace_key" $upstream_addr $status $request_time).
function upstreams(method, key) {
  const log = readFileSync(join(work, "nginx-access.log"), "utf8");
  return log.split("\n").filter((l) => l.includes(` /fieldspace.v1.FieldSpace/${method} "${key}" `))
    .map((l) => l.split(" ").slice(3, -2).join(" "));
}

const client = daemonClient(router);
const { basis } = await uploadAndBuild(client, pb, torusObj(), "torus.obj",
  { kind: pb.FieldKind.VECTOR }, 40);
check(basis?.state === pb.BasisState.READY, `basis ${basis?.id} built through the router`);

const gateway = await startGateway(args["web-dir"], ["--daemon", router]);
const browser = await launchChromium(chromium);
const page = await browser.newPage({ viewport: { width: 900, height: 640 } });
page.on("pageerror", (e) => console.error(`page error: ${e.message}`));
const { checkAgainstSolve, waitForMessage } = pageProbe(page, client, pb);
await page.goto(gateway.url);
await chooseBasis(page, basis.id);
await checkAgainstSolve("the session opened through the router");
await page.evaluate(() => window.__studio.edit({ kind: "add", id: 1,
  constraint: { face: 10, value: [0, 0, 1], hard: false, weight: 2 } }));
await page.evaluate(() => window.__studio.edit({ kind: "add", id: 2,
  constraint: { face: 700, value: [1, 0, 0], hard: true, weight: 1 } }));
await checkAgainstSolve("two constraints through the router");
// An edit the daemon refuses (constraint id 2 exists) must not be replayed after the failover.
await page.evaluate(() => window.__studio.edit({ kind: "add", id: 2,
  constraint: { face: 5, value: [0, 0, 1], hard: false, weight: 7 } }));
await waitForMessage(/daemon refused the edit .add. \(already exists\)/);
const before = await checkAgainstSolve("after the refused edit");
check(before.constraints.length === 2 && before.constraints.find((c) => c.id === 2)?.hard,
  "the session has the two constraints, the second one hard as added");

// The page read the basis (GetBasis, keyed by its id) just before opening the session with the
// same key: nginx's consistent hash sent both to the replica that serves the session.
const [victim] = upstreams("GetBasis", basis.id).slice(-1);
check(replicas.has(victim), `the session's replica: ${victim}`);
process.kill(replicas.get(victim), "SIGKILL");
for (let i = 0; ; i++) {
  try {
    process.kill(replicas.get(victim), 0);
  } catch {
    break;
  }
  check(i < 100, `replica ${victim} died`);
  await new Promise((r) => setTimeout(r, 50));
}

// The next edit resumes the session on the other replica, which loads the basis from the store.
await page.evaluate(() => window.__studio.edit({ kind: "move", id: 1, face: 20,
  value: [0, 1, 0] }));
await waitForMessage(/replica was lost; the session was reopened/);
const after = await checkAgainstSolve("after the replica's loss, the session resumed");
check(after.constraints.length === 2 && after.constraints.find((c) => c.id === 1)?.face === 20 &&
  JSON.stringify(after.constraints.find((c) => c.id === 2)) ===
  JSON.stringify(before.constraints.find((c) => c.id === 2)),
  "the resumed session has the same constraints, with the edit made across the loss");
const lost = upstreams("Design", basis.id);
check(lost.length >= 1 && lost[0].startsWith(victim),
  `nginx logged the lost Design stream on ${victim} (${lost})`);

await browser.close();
await stopFleet();
cleanup();
console.log(`studio_fleet: all checks passed in ${((performance.now() - started) / 1000).toFixed(1)} s`);
