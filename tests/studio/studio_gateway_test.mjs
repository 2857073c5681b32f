// The gateway against a stand-in daemon (a gRPC server made here with connect-node) that records
// what arrives: every relayed call carries the token and the routing key the scale-out router
// hashes on (the basis id, else the mesh id; none for listings and uploads); a design session's
// frames are relayed in order; when the stand-in drops the Design stream with UNAVAILABLE (a
// draining replica), the gateway reopens it with the same key, replays the open (with the current
// weights and watch) and the constraints in the order added, and sends the unanswered edit again.
// Tool groups (strokes, placed singularities, alignments) are replayed as they were last made.
// A mesh POSTed to /upload reaches UploadMesh in bounded chunks with total_bytes. Also the listen
// rules of the flags.
//   node studio_gateway_test.mjs --web-dir client/web
import { spawnSync } from "node:child_process";
import { readFileSync, writeFileSync } from "node:fs";
import http2 from "node:http2";
import { createRequire } from "node:module";
import { join, resolve } from "node:path";
import { pathToFileURL } from "node:url";
import { check, cleanup, parseArgs, startGateway, tempDir } from "./studio_lib.mjs";

const args = parseArgs(process.argv.slice(2));
const webDir = resolve(args["web-dir"]);
const require = createRequire(join(webDir, "package.json"));
const load = (path) => import(pathToFileURL(require.resolve(path)));
const { Code, ConnectError, createClient } = await import(pathToFileURL(join(webDir, "node_modules",
  "@connectrpc", "connect", "dist", "esm", "index.js")));
const connectNode = await import(pathToFileURL(join(webDir, "node_modules", "@connectrpc",
  "connect-node", "dist", "esm", "index.js")));
const { create, fromBinary, toBinary } = await import(pathToFileURL(join(webDir, "node_modules",
  "@bufbuild", "protobuf", "dist", "esm", "index.js")));
const pb = await import(pathToFileURL(join(webDir, "gen", "fieldspace", "v1", "fieldspace_pb.js")));
const { replicaLost } = await import(pathToFileURL(join(webDir, "gateway", "design_relay.mjs")));
const { default: WebSocket } = await load("ws");

// The stand-in daemon.
const calls = [];      // { method, key, auth }
const streams = [];    // per Design stream: { key, requests: [DesignRequest] }
const uploads = [];    // per UploadMesh call: { messages: [{ header, offset, data }] }
let dropNext = false;  // fail the Design stream's next request with UNAVAILABLE
const meta = (method, ctx) => calls.push({ method, key: ctx.requestHeader.get("x-fieldspace-key"),
  auth: ctx.requestHeader.get("authorization") });
const standIn = http2.createServer(connectNode.connectNodeAdapter({
  routes: (router) => router.service(pb.FieldSpace, {
    listMeshes: (_, ctx) => (meta("ListMeshes", ctx), { meshes: [] }),
    getMesh: (req, ctx) => (meta("GetMesh", ctx), { id: req.meshId }),
    getBasis: (req, ctx) => (meta("GetBasis", ctx), { id: req.basisId }),
    async *getMeshGeometry(req, ctx) {
      meta("GetMeshGeometry", ctx);
      yield { numVertices: 3, numFaces: 1, vertices: [0, 0, 0, 1, 0, 0, 0, 1, 0], faces: [0, 1, 2] };
    },
    async uploadMesh(requests, ctx) {
      meta("UploadMesh", ctx);
      const upload = { messages: [] };
      uploads.push(upload);
      for await (const r of requests) {
        upload.messages.push({ header: r.header, offset: r.offset, data: Buffer.from(r.data) });
        if (r.header?.name === "refuse.obj") {
          throw new ConnectError("mesh: no faces", Code.InvalidArgument);
        }
      }
      return { id: "m-0000000000000001", name: upload.messages[0]?.header?.name ?? "",
        numFaces: 7 };
    },
    async *design(requests, ctx) {
      const stream = { key: ctx.requestHeader.get("x-fieldspace-key"),
        auth: ctx.requestHeader.get("authorization"), requests: [] };
      streams.push(stream);
      for await (const request of requests) {
        stream.requests.push(request);
        if (dropNext) {
          dropNext = false;
          throw new ConnectError("server is shutting down", Code.Unavailable);
        }
        yield { seq: request.seq, basisId: stream.key, numConstraints: stream.requests.length };
      }
    },
  }),
}));
await new Promise((done) => standIn.listen(0, "127.0.0.1", done));
const daemonAddress = `127.0.0.1:${standIn.address().port}`;

// 1. Unary and streaming calls: token and routing key.
const gateway = await startGateway(webDir, ["--daemon", daemonAddress]);
const api = createClient(pb.FieldSpace, connectNode.createConnectTransport({
  baseUrl: gateway.url.replace(/\/$/, ""), httpVersion: "1.1", useBinaryFormat: true,
  interceptors: [(next) => (req) => {
    req.header.set("authorization", "Bearer t0ken");
    return next(req);
  }],
}));
await api.listMeshes({});
await api.getMesh({ meshId: "m-00000000000000aa" });
await api.getBasis({ basisId: "b-00000000000000bb" });
for await (const _ of api.getMeshGeometry({ meshId: "m-00000000000000cc" })) { /* one chunk */ }
const byMethod = Object.fromEntries(calls.map((c) => [c.method, c]));
check(byMethod.ListMeshes.key === null, "ListMeshes carries no routing key");
check(byMethod.GetMesh.key === "m-00000000000000aa", "GetMesh: key = the mesh id");
check(byMethod.GetBasis.key === "b-00000000000000bb", "GetBasis: key = the basis id");
check(byMethod.GetMeshGeometry.key === "m-00000000000000cc", "GetMeshGeometry (streaming): key = the mesh id");
check(calls.every((c) => c.auth === "Bearer t0ken"), "every call passes the page's token on");

// 2. A design session over the WebSocket, then a replica loss under it.
const socket = new WebSocket(gateway.url.replace(/^http/, "ws") + "design",
  ["fieldspace.design.v1", `bearer.${Buffer.from("t0ken").toString("base64url")}`]);
const updates = [];
const events = [];
let closed = null;
socket.on("message", (data, binary) => (binary ? updates.push(fromBinary(pb.DesignUpdateSchema,
  new Uint8Array(data))) : events.push(JSON.parse(String(data)))));
socket.on("close", (code, reason) => (closed = { code, reason: String(reason) }));
await new Promise((done) => socket.once("open", done));
let seq = 0n;
async function send(edit) {
  const count = updates.length;
  socket.send(toBinary(pb.DesignRequestSchema, create(pb.DesignRequestSchema, { seq: seq++, edit })));
  const deadline = Date.now() + 10000;
  while (updates.length === count) {
    if (closed || Date.now() > deadline) throw new Error(`no update: ${JSON.stringify(closed)}`);
    await new Promise((done) => setTimeout(done, 10));
  }
  return updates[updates.length - 1];
}
const ambient = pb.FieldEncoding.AMBIENT;
const basisId = "b-00000000000000dd";
await send({ case: "open", value: { basisId, weights: { muS: 1, muC: 1 }, watchFaces: [1, 2] } });
await send({ case: "add", value: { id: 7, constraint: { face: 3, value: [1, 0, 0], encoding: ambient } } });
await send({ case: "add", value: { id: 4, constraint: { face: 5, value: [0, 1, 0], encoding: ambient, hard: true } } });
await send({ case: "move", value: { id: 7, face: 9, value: [0, 0, 1], encoding: ambient } });
await send({ case: "remove", value: { id: 4 } });
await send({ case: "setWeights", value: { muB: 0.5 } });
await send({ case: "watch", value: { faces: [8], encoding: ambient } });
const facePoint = (face) => ({ at: { case: "facePoint", value: { face, barycentric: [1, 0, 0] } } });
await send({ case: "addStroke", value: { id: 20, points: [facePoint(1), facePoint(2)] } });
await send({ case: "placeSingularity", value: { id: 21, at: { case: "vertex", value: 5 },
  index: 0.25, hard: true } });
await send({ case: "alignBoundary", value: { id: 22, mode: pb.BoundaryAlignMode.BOUNDARY_ALIGN_NORMAL } });
await send({ case: "alignFeatures", value: { id: 23, angleDegrees: 45 } });
await send({ case: "remove", value: { id: 22 } });
// The stroke replaced by a longer one (move with a group).
await send({ case: "move", value: { id: 20, group: { tool: { case: "stroke", value: {
  points: [facePoint(1), facePoint(2), facePoint(3)], weight: 2 } } } } });
check(streams.length === 1 && streams[0].key === basisId && streams[0].auth === "Bearer t0ken",
  "the Design stream carries the basis id as key and the token");
check(updates.map((u) => u.seq).join() === "0,1,2,3,4,5,6,7,8,9,10,11,12",
  "one update per frame, in order");

dropNext = true;  // the stream's next request fails: as a draining replica answers
const dropped = streams.length;
const answer = await send({ case: "add", value: { id: 12, constraint: { face: 11, value: [1, 1, 0], encoding: ambient } } });
check(answer.seq === 13n && events.some((e) => e.resumed === 1), "the failed edit is answered after a resume");
const replay = streams[streams.length - 1].requests;
const kinds = replay.map((r) => `${r.edit.case}:${r.edit.value.id ?? ""}`).join(" ");
check(streams.length === dropped + 1 && streams[streams.length - 1].key === basisId,
  "the session was reopened on a new stream with the same key");
check(kinds === "open: add:7 addStroke:20 placeSingularity:21 alignFeatures:23 add:12",
  `the new stream replays the open, the constraints and tools in order, then the edit (${kinds})`);
const open = replay[0].edit.value;
check(open.weights.muS === 1 && open.weights.muC === 1 && open.weights.muB === 0.5 &&
  open.watchFaces.join() === "8", "the replayed open has the current weights and watch");
const moved = replay[1].edit.value.constraint;
check(moved.face === 9 && moved.value.join() === "0,0,1", "the replayed constraint is where it was moved");
const stroke = replay[2].edit.value;
check(stroke.id === 20 && stroke.points.length === 3 && stroke.weight === 2,
  "the replayed stroke is the one that replaced it");
const singularity = replay[3].edit.value;
check(singularity.at.value === 5 && singularity.index === 0.25 && singularity.hard &&
  replay[4].edit.value.angleDegrees === 45, "the replayed singularity and feature alignment are as made");

// Uploads: POST /upload?name= with a body larger than two chunks; UploadMesh gets the header
// (name, total_bytes = the body's length) first, then chunks of at most 1 MiB at consecutive
// offsets that make up the body.
const { UPLOAD_CHUNK_BYTES } = await import(pathToFileURL(join(webDir, "gateway", "gateway.mjs")));
const body = Buffer.alloc(2 * UPLOAD_CHUNK_BYTES + 12345);
for (let i = 0; i < body.length; i++) body[i] = (i * 7919) & 0xff;
const uploaded = await fetch(`${gateway.url}upload?name=big.obj`, { method: "POST", body,
  headers: { authorization: "Bearer t0ken" } });
const info = await uploaded.json();
const received = uploads.at(-1).messages;
check(uploaded.status === 200 && info.id === "m-0000000000000001" && info.numFaces === 7,
  `the upload answers the MeshInfo as JSON (${JSON.stringify(info)})`);
check(received[0].header?.name === "big.obj" && received[0].header.totalBytes === BigInt(body.length) &&
  received.slice(1).every((m) => m.header === undefined), "the first message carries the name and total_bytes");
check(received.every((m) => m.data.length <= UPLOAD_CHUNK_BYTES) && received.length === 3 &&
  received.every((m, i) => m.offset === BigInt(i * UPLOAD_CHUNK_BYTES)) &&
  Buffer.concat(received.map((m) => m.data)).equals(body),
  `${received.length} chunks of at most ${UPLOAD_CHUNK_BYTES} bytes at consecutive offsets make up the body`);
check(calls.at(-1).method === "UploadMesh" && calls.at(-1).auth === "Bearer t0ken",
  "the upload passes the token on");
const refusedUpload = await fetch(`${gateway.url}upload?name=refuse.obj`, { method: "POST",
  body: "v 0 0 0\n" });
const refusal = await refusedUpload.json();
check(refusedUpload.status === 400 && refusal.code === "invalid_argument" &&
  refusal.message === "mesh: no faces", `a refused upload answers the daemon's error (${refusedUpload.status}, ` +
  `${JSON.stringify(refusal)})`);
const nameless = await fetch(`${gateway.url}upload`, { method: "POST", body: "x" });
check(nameless.status === 400 && /name=/.test((await nameless.json()).message),
  "an upload without ?name= is refused");

// 3. A lost replica by stream reset (the router's RST_STREAM) counts, a server's INTERNAL does not.
check(replicaLost(new ConnectError("http/2 stream closed with error code INTERNAL_ERROR (0x2)",
  Code.Internal)), "a reset stream is a lost replica");
check(!replicaLost(new ConnectError("bug", Code.Internal)), "a server's INTERNAL is not");

// 4. A refused first frame closes with 4000 + the gRPC code.
const bad = new WebSocket(gateway.url.replace(/^http/, "ws") + "design", ["fieldspace.design.v1"]);
await new Promise((done) => bad.once("open", done));
bad.send(toBinary(pb.DesignRequestSchema, create(pb.DesignRequestSchema,
  { edit: { case: "remove", value: { id: 1 } } })));
const [code, reason] = await new Promise((done) => bad.once("close", (c, r) => done([c, String(r)])));
check(code === 4000 + Code.FailedPrecondition && /first message/.test(reason),
  `a session not starting with open closes with ${code}: ${reason}`);
socket.close();

// 5. The gateway's own token: the WebSocket without it is refused with 4016.
const dir = tempDir("studio-gw-");
writeFileSync(join(dir, "token"), "abc\n");
const guarded = await startGateway(webDir, ["--daemon", daemonAddress, "--auth-token-file", join(dir, "token")]);
const refused = new WebSocket(guarded.url.replace(/^http/, "ws") + "design", ["fieldspace.design.v1"]);
const refusedCode = await new Promise((done) => refused.once("close", (c) => done(c)));
check(refusedCode === 4000 + Code.Unauthenticated, `a session without the token closes with ${refusedCode}`);

// 6. Listen rules: non-loopback needs a token, a client CA or --insecure.
const main = join(webDir, "gateway", "main.mjs");
const open0 = spawnSync(process.execPath, [main, "--listen", "0.0.0.0:0"], { encoding: "utf8" });
check(open0.status === 2 && /refusing to listen on non-loopback/.test(open0.stderr),
  "0.0.0.0 without a token is refused (exit 2)");
const badFlag = spawnSync(process.execPath, [main, "--listen", "nohostport"], { encoding: "utf8" });
check(badFlag.status === 2 && /--listen must be HOST:PORT/.test(badFlag.stderr), "a bad --listen is refused");
const tokenOpen = await startGateway(webDir, ["--listen", "0.0.0.0:0", "--daemon", daemonAddress,
  "--auth-token-file", join(dir, "token")]).catch((e) => e);
check(!(tokenOpen instanceof Error), "0.0.0.0 with a token starts");

// 7. TLS both ways: the gateway serves HTTPS (--tls-cert, --tls-key) and calls a daemon over TLS
// (--daemon-ca); the stand-in answers over TLS with the same self-signed certificate.
const cert = join(dir, "cert.pem"), key = join(dir, "key.pem");
const openssl = spawnSync("openssl", ["req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1",
  "-subj", "/CN=localhost", "-addext", "subjectAltName=DNS:localhost,IP:127.0.0.1",
  "-keyout", key, "-out", cert], { encoding: "utf8" });
check(openssl.status === 0, "a self-signed certificate for 127.0.0.1");
const pem = readFileSync(cert, "utf8");
const tlsStandIn = http2.createSecureServer({ cert: pem, key: readFileSync(key, "utf8") },
  connectNode.connectNodeAdapter({ routes: (router) => router.service(pb.FieldSpace, {
    getBasis: (req, ctx) => (meta("GetBasis over TLS", ctx), { id: req.basisId }),
  }) }));
await new Promise((done) => tlsStandIn.listen(0, "127.0.0.1", done));
const tlsGateway = await startGateway(webDir, ["--daemon", `127.0.0.1:${tlsStandIn.address().port}`,
  "--daemon-ca", cert, "--tls-cert", cert, "--tls-key", key]);
check(tlsGateway.url.startsWith("https://"), `the gateway serves ${tlsGateway.url}`);
const tlsApi = createClient(pb.FieldSpace, connectNode.createConnectTransport({
  baseUrl: tlsGateway.url.replace(/\/$/, ""), httpVersion: "1.1", useBinaryFormat: true,
  nodeOptions: { ca: pem } }));
const tlsBasis = await tlsApi.getBasis({ basisId: "b-00000000000000ee" });
check(tlsBasis.id === "b-00000000000000ee" && calls.at(-1).method === "GetBasis over TLS",
  "a call through HTTPS reaches the daemon over TLS");
const tlsOnly = spawnSync(process.execPath, [main, "--listen", "0.0.0.0:0", "--tls-cert", cert,
  "--tls-key", key], { encoding: "utf8" });
check(tlsOnly.status === 2, "0.0.0.0 with TLS but neither a token nor a client CA is refused");
tlsStandIn.close();

standIn.close();
cleanup();
console.log("studio_gateway: all checks passed");
process.exit(0);
