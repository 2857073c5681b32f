// The studio gateway (docs/studio.md): serves the page, relays the page's unary and
// server-streaming fieldspace.v1 calls (Connect protocol, binary) to the daemon over gRPC, and its
// design sessions (one WebSocket per session, see design_relay.mjs) to gRPC Design streams.
// Every call to the daemon carries the token and the routing key x-fieldspace-key (the basis
// id, else the mesh id of the request), as the other clients send them (docs/scale-out.md).
import { readFileSync } from "node:fs";
import { timingSafeEqual } from "node:crypto";
import http from "node:http";
import https from "node:https";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { toJson } from "@bufbuild/protobuf";
import { Code, ConnectError } from "@connectrpc/connect";
import { connectNodeAdapter } from "@connectrpc/connect-node";
import { codeToHttpStatus, errorToJson } from "@connectrpc/connect/protocol-connect";
import { WebSocketServer } from "ws";
import { FieldSpace, MeshInfoSchema } from "../gen/fieldspace/v1/fieldspace_pb.js";
import { RAW_FIELDSPACE, daemonClient } from "./daemon.mjs";
import { CLOSE_STATUS_BASE, DesignRelay } from "./design_relay.mjs";

const here = dirname(fileURLToPath(import.meta.url));
export const DESIGN_PATH = "/design";
// The WebSocket subprotocol of design sessions; a token travels as a second offered subprotocol
// "bearer.<base64url(token)>" (browsers cannot set headers on a WebSocket).
export const DESIGN_PROTOCOL = "fieldspace.design.v1";
// Mesh uploads from the page: POST UPLOAD_PATH?name=FILE with the file as the body, relayed to the
// client-streaming UploadMesh in messages of at most UPLOAD_CHUNK_BYTES (browsers cannot stream a
// request body to a Connect client-streaming call).
export const UPLOAD_PATH = "/upload";
export const UPLOAD_CHUNK_BYTES = 1 << 20;
const STATIC_FILES = {
  "/": ["index.html", "text/html; charset=utf-8"],
  "/index.html": ["index.html", "text/html; charset=utf-8"],
  "/studio.js": ["studio.js", "text/javascript; charset=utf-8"],
  "/studio.js.map": ["studio.js.map", "application/json"],
  "/studio.css": ["studio.css", "text/css; charset=utf-8"],
};

function tokenMatches(expected, header) {
  const m = /^Bearer\s+(.+)$/i.exec(header ?? "");
  if (!m) return false;
  const a = Buffer.from(m[1].trim());
  const b = Buffer.from(expected);
  return a.length === b.length && timingSafeEqual(a, b);
}

/** The daemon's error as code and message only: its gRPC metadata (content-type and the like)
 *  must not become headers of the page's Connect response. */
function statusOnly(error) {
  const e = ConnectError.from(error);
  return new ConnectError(e.rawMessage, e.code);
}

/** The routing key of a request: its basis id, else its mesh id (empty: none). */
function routingKey(request) {
  return request?.basisId || request?.meshId || "";
}

/**
 * Starts the gateway. `options` as parseOptions returns them (listen host/port, daemon, token,
 * tls, daemonCa); `staticDir` holds the built page (default ../dist). Resolves to
 * { url, port, close() } once listening.
 */
export async function startGateway(options, { staticDir = join(here, "..", "dist"),
  log = (line) => console.error(`fieldspace-studio: ${line}`) } = {}) {
  const daemon = daemonClient(options.daemon, { ca: options.daemonCa });
  // Binary calls and design sessions: the daemon's answers relayed as its bytes (daemon.mjs).
  const rawDaemon = daemonClient(options.daemon, { ca: options.daemonCa, service: RAW_FIELDSPACE });

  // The daemon's metadata for a browser request with `authorization` header `auth`.
  const daemonHeaders = (auth) => {
    const headers = new Headers();
    if (options.token) headers.set("authorization", `Bearer ${options.token}`);
    else if (auth) headers.set("authorization", auth);
    return headers;
  };
  const checkToken = (auth) => {
    if (options.token && !tokenMatches(options.token, auth)) {
      throw new ConnectError(auth ? "wrong token" : "this studio needs a token",
        Code.Unauthenticated);
    }
  };

  // Every method of the service, relayed as is (Design too, for HTTP/2 gRPC clients).
  const relayOf = (client) => {
    const relay = {};
    for (const method of FieldSpace.methods) {
      relay[method.localName] = relayMethod(method, client[method.localName]);
    }
    return relay;
  };
  const relayMethod = (method, call) => {
    const headersFor = (ctx, key) => {
      const auth = ctx.requestHeader.get("authorization");
      checkToken(auth);
      const headers = daemonHeaders(auth);
      if (key) headers.set("x-fieldspace-key", key);
      return { headers, signal: ctx.signal };
    };
    switch (method.methodKind) {
      case "unary":
        return async (request, ctx) => {
          try {
            return await call(request, headersFor(ctx, routingKey(request)));
          } catch (e) {
            throw statusOnly(e);
          }
        };
      case "server_streaming":
        return async function* (request, ctx) {
          try {
            yield* call(request, headersFor(ctx, routingKey(request)));
          } catch (e) {
            throw statusOnly(e);
          }
        };
      default:  // UploadMesh (no key: the server computes the mesh id) and Design, for gRPC clients
        return (requests, ctx) => call(requests, headersFor(ctx, ""));
    }
  };

  // A mesh file in the body of POST /upload?name=FILE (Content-Length required: it is the
  // header's total_bytes), relayed as UploadMesh messages of at most UPLOAD_CHUNK_BYTES, each read
  // from the socket only when the daemon takes the previous one (the body is never held whole).
  // Answers the MeshInfo as JSON, or a Connect error JSON with its HTTP status.
  const upload = async (req, res) => {
    const answerError = (error) => {
      const e = statusOnly(error);
      res.writeHead(codeToHttpStatus(e.code), { "content-type": "application/json" });
      res.end(JSON.stringify(errorToJson(e, undefined)));
      req.resume();  // drain what the browser still sends
    };
    const total = Number(req.headers["content-length"]);
    const name = new URL(req.url, "http://x").searchParams.get("name") ?? "";
    try {
      checkToken(req.headers.authorization);
      if (!Number.isSafeInteger(total) || total <= 0) {
        throw new ConnectError("an upload needs a non-empty body with Content-Length",
          Code.InvalidArgument);
      }
      if (!name) throw new ConnectError("an upload needs ?name=FILE", Code.InvalidArgument);
    } catch (e) {
      answerError(e);
      return;
    }
    async function* messages() {
      let offset = 0;
      let pending = [];
      let size = 0;
      const message = () => {
        const data = Buffer.concat(pending, size);
        const m = { offset: BigInt(offset), data,
          ...(offset === 0 ? { header: { name, totalBytes: BigInt(total) } } : {}) };
        offset += size;
        pending = [];
        size = 0;
        return m;
      };
      for await (let piece of req) {
        while (size + piece.length >= UPLOAD_CHUNK_BYTES) {
          const take = UPLOAD_CHUNK_BYTES - size;
          pending.push(piece.subarray(0, take));
          size += take;
          piece = piece.subarray(take);
          yield message();
        }
        if (piece.length) {
          pending.push(piece);
          size += piece.length;
        }
      }
      if (size > 0 || offset === 0) yield message();
    }
    try {
      const abort = new AbortController();
      req.once("close", () => {
        if (!req.complete) abort.abort();  // the browser went away: the daemon drops the upload
      });
      const info = await daemon.uploadMesh(messages(),
        { headers: daemonHeaders(req.headers.authorization), signal: abort.signal });
      res.writeHead(200, { "content-type": "application/json", "cache-control": "no-store" });
      res.end(JSON.stringify(toJson(MeshInfoSchema, info)));
    } catch (e) {
      answerError(e);
    }
  };

  const config = JSON.stringify({ tokenRequired: Boolean(options.token), daemon: options.daemon });
  const serveStatic = (req, res) => {
    const path = new URL(req.url, "http://x").pathname;
    if (req.method === "POST" && path === UPLOAD_PATH) {
      upload(req, res);
      return;
    }
    if (req.method === "GET" && path === "/config.json") {
      res.writeHead(200, { "content-type": "application/json", "cache-control": "no-store" });
      res.end(config);
      return;
    }
    const entry = STATIC_FILES[path];
    if (req.method !== "GET" || entry === undefined) {
      res.writeHead(404, { "content-type": "text/plain" });
      res.end("not found\n");
      return;
    }
    let body;
    try {
      body = readFileSync(join(staticDir, entry[0]));
    } catch {
      res.writeHead(500, { "content-type": "text/plain" });
      res.end(`the page is not built: run 'npm run build' in client/web\n`);
      return;
    }
    res.writeHead(200, { "content-type": entry[1], "cache-control": "no-cache" });
    res.end(body);
  };
  const adapter = (service, client) => connectNodeAdapter({
    routes: (router) => router.service(service, relayOf(client)),
    fallback: serveStatic,
    readMaxBytes: 64 << 20,
  });
  // JSON answers need the messages parsed; binary ones (the page's) are relayed as bytes.
  const jsonHandler = adapter(FieldSpace, daemon);
  const rawHandler = adapter(RAW_FIELDSPACE, rawDaemon);
  const handler = (req, res) =>
    (/json/i.test(req.headers["content-type"] ?? "") ? jsonHandler : rawHandler)(req, res);

  const server = options.tls
    ? https.createServer({ cert: options.tls.cert, key: options.tls.key,
      ...(options.tls.clientCa ? { ca: options.tls.clientCa, requestCert: true,
        rejectUnauthorized: true } : {}) }, handler)
    : http.createServer(handler);

  const sockets = new WebSocketServer({
    server,
    path: DESIGN_PATH,
    maxPayload: 64 << 20,
    handleProtocols: (protocols) => (protocols.has(DESIGN_PROTOCOL) ? DESIGN_PROTOCOL : false),
  });
  sockets.on("connection", (socket, req) => {
    let auth = "";
    for (const p of (req.headers["sec-websocket-protocol"] ?? "").split(",")) {
      const offered = p.trim();
      if (offered.startsWith("bearer.")) {
        auth = `Bearer ${Buffer.from(offered.slice(7), "base64url").toString("utf8")}`;
      }
    }
    try {
      checkToken(auth);
    } catch (e) {
      socket.close(CLOSE_STATUS_BASE + e.code, e.rawMessage);
      return;
    }
    new DesignRelay(socket, rawDaemon, daemonHeaders(auth), log);
  });

  await new Promise((resolve, reject) => {
    server.once("error", reject);
    server.listen(options.port, options.host, resolve);
  });
  const port = server.address().port;
  const host = options.host.includes(":") ? `[${options.host}]` : options.host;
  return {
    port,
    url: `${options.tls ? "https" : "http"}://${host}:${port}/`,
    close: () => new Promise((resolve) => {
      for (const client of sockets.clients) client.terminate();
      sockets.close();
      server.closeAllConnections?.();
      server.close(() => resolve());
    }),
  };
}
