// One browser design session: a WebSocket whose binary frames are serialized
// fieldspace.v1.DesignRequest (page -> gateway) and DesignUpdate (gateway -> page), relayed to one
// gRPC Design stream on the daemon. Failover as in the other clients (docs/scale-out.md, Design
// failover; client/python/fieldspace/design.py): the relay keeps what the daemon confirmed (the
// open with its current weights and watch, the constraints and tool groups by id in the order they
// were added),
// and when the stream loses its replica it reopens the stream with the same routing key, replays
// the open and the constraints, and sends the unanswered edits again.
import { clone, create, fromBinary, toBinary } from "@bufbuild/protobuf";
import { EmptySchema } from "@bufbuild/protobuf/wkt";
import { Code, ConnectError } from "@connectrpc/connect";
import {
  DesignRequestSchema, DesignUpdateSchema, OpenDesignSchema, WeightsSchema,
} from "../gen/fieldspace/v1/fieldspace_pb.js";

// The edits that add something under an id (a constraint or a tool's group), and the add edit of
// each ConstraintGroup case (what `move {id, group}` replaces a group with).
const ADDS = new Set(["add", "addStroke", "placeSingularity", "alignBoundary", "alignFeatures"]);
const ADD_OF_GROUP = { stroke: "addStroke", singularity: "placeSingularity",
  alignBoundary: "alignBoundary", alignFeatures: "alignFeatures" };
// DesignUpdate.error's field number: updates arrive as raw bytes (RAW_FIELDSPACE), so a refused
// edit shows as this unknown field.
const UPDATE_ERROR = DesignUpdateSchema.field.error.number;

// Pauses (ms) before each reopening attempt; then the edit fails with the error that lost it.
const RESUME_PAUSES_MS = [0, 100, 300, 600, 1000, 2000];
// WebSocket close codes 4000 + gRPC status code carry the error that ended a session.
export const CLOSE_STATUS_BASE = 4000;

/** Whether a failed Design stream lost its replica, so that reopening may help: UNAVAILABLE (the
 *  replica drained or is unreachable) or the HTTP/2 stream reset under it (what a router does when
 *  the replica behind it dies). An INTERNAL status the server sent has its own message. */
export function replicaLost(error) {
  const e = ConnectError.from(error);
  if (e.code === Code.Unavailable) return true;
  return e.code === Code.Internal && /RST_STREAM|stream closed with error code/i.test(e.rawMessage);
}

// The requests of one gRPC stream: pushed by the relay, pulled by the client (an async generator,
// so that the client can also end or fail it).
class Queue {
  constructor() {
    this.items = [];
    this.wake = null;
    this.ended = false;
  }
  push(item) {
    this.items.push(item);
    this.wake?.();
  }
  end() {
    this.ended = true;
    this.wake?.();
  }
  async *[Symbol.asyncIterator]() {
    for (;;) {
      if (this.items.length) {
        yield this.items.shift();
      } else if (this.ended) {
        return;
      } else {
        await new Promise((resolve) => {
          this.wake = resolve;
        });
        this.wake = null;
      }
    }
  }
}

export class DesignRelay {
  /**
   * @param socket  an open `ws` WebSocket
   * @param client  a connect client of daemon.mjs's RAW_FIELDSPACE (gRPC to the daemon): the
   *                daemon's DesignUpdates go to the page as the bytes it sent
   * @param headers metadata for the daemon (authorization), without the routing key
   * @param log     function(string) for the gateway's log
   */
  constructor(socket, client, headers, log) {
    this.socket = socket;
    this.client = client;
    this.headers = headers;
    this.log = log;
    this.pending = [];  // requests sent on the current stream and not yet answered, in order
    this.open = null;   // the confirmed OpenDesign, kept up to date with weights and watch
    // id -> the confirmed edit that adds it now ({ case, value } of a DesignRequest), in the order
    // added: an add of a constraint (kept where moves took it) or of a tool's group.
    this.constraints = new Map();
    this.resumes = 0;
    this.resuming = false;
    this.lost = null;  // the error that lost the stream while no edit was open: resume on the next
    this.closed = false;
    this.call = null;
    socket.on("message", (data, isBinary) => this.onFrame(data, isBinary));
    socket.on("close", () => this.shutdown());
    socket.on("error", () => this.shutdown());
  }

  onFrame(data, isBinary) {
    if (this.closed) return;
    if (!isBinary) {
      this.fail(new ConnectError("frames must be binary DesignRequest messages",
        Code.InvalidArgument));
      return;
    }
    let request;
    try {
      request = fromBinary(DesignRequestSchema, new Uint8Array(data));
    } catch (e) {
      this.fail(new ConnectError(`not a DesignRequest: ${e.message}`, Code.InvalidArgument));
      return;
    }
    if (this.call === null) {
      if (request.edit.case !== "open") {
        this.fail(new ConnectError("the first message of a session must be 'open'",
          Code.FailedPrecondition));
        return;
      }
      this.key = request.edit.value.basisId;
      this.startCall(true);
    }
    this.pending.push(request);
    if (this.resuming) return;  // sent after the replay
    if (this.lost !== null) {
      const lost = this.lost;
      this.lost = null;
      this.resume(lost);
      return;
    }
    this.call.requests.push(request);
  }

  // A new gRPC Design stream; `pump`: forward its answers to the page now (not while replaying).
  startCall(pump) {
    const requests = new Queue();
    const abort = new AbortController();
    const headers = new Headers(this.headers);
    if (this.key) headers.set("x-fieldspace-key", this.key);
    const responses = this.client.design(requests, { headers, signal: abort.signal });
    this.call = { requests, abort, responses: responses[Symbol.asyncIterator]() };
    if (pump) this.pump(this.call);
  }

  // Forwards the answers of `call` to the page until it ends; on a lost replica, resumes.
  async pump(call) {
    try {
      for (;;) {
        const { value: update, done } = await call.responses.next();
        if (done) break;
        if (call !== this.call) return;
        this.answer(update);
      }
      if (call === this.call && !this.closed) {
        // The daemon ended the stream without an error while edits were open, or on its own.
        this.fail(new ConnectError("the server ended the session", Code.Unavailable));
      }
    } catch (error) {
      if (call !== this.call || this.closed) return;
      if (replicaLost(error) && this.open !== null) {
        // As the other clients: an edit in flight resumes now, else the next edit does.
        if (this.pending.length) this.resume(error);
        else this.lost = error;
      } else {
        this.fail(error);
      }
    }
  }

  answer(update) {
    const request = this.pending.shift();
    // A refused edit (DesignUpdate.error) left the session as it was: nothing to replay.
    const refused = update.$unknown?.some((field) => field.no === UPDATE_ERROR) ?? false;
    if (request !== undefined && !refused) this.remember(request);
    if (this.socket.readyState === this.socket.OPEN) {
      this.socket.send(toBinary(EmptySchema, update), { binary: true });
    }
  }

  // Keeps the state a reopened session replays once the daemon confirmed `request`.
  remember(request) {
    const { case: kind, value } = request.edit;
    if (kind === "open") {
      this.open = clone(OpenDesignSchema, value);
    } else if (ADDS.has(kind)) {
      this.constraints.set(value.id, clone(DesignRequestSchema, request).edit);
    } else if (kind === "move") {
      const added = this.constraints.get(value.id);
      if (added !== undefined && value.group?.tool.case !== undefined) {
        const tool = value.group.tool;
        const edit = clone(DesignRequestSchema, create(DesignRequestSchema,
          { edit: { case: ADD_OF_GROUP[tool.case], value: tool.value } })).edit;
        edit.value.id = value.id;
        this.constraints.set(value.id, edit);
      } else if (added?.case === "add") {
        const c = added.value.constraint;
        c.face = value.face;
        c.value = [...value.value];
        c.encoding = value.encoding;
      }
    } else if (kind === "remove") {
      this.constraints.delete(value.id);
    } else if (kind === "setWeights") {
      // Weights an edit leaves out keep the session's values.
      this.open.weights ??= create(WeightsSchema);
      for (const name of ["muS", "muB", "muC", "muA"]) {
        if (value[name] !== undefined) this.open.weights[name] = value[name];
      }
    } else if (kind === "watch") {
      this.open.watchFaces = [...value.faces];
      this.open.watchEncoding = value.encoding;
    }
  }

  // Reopens the stream after `lost`, replays the confirmed state and sends the unanswered edits
  // again; fails the session with `lost` when every attempt failed.
  async resume(lost) {
    this.resuming = true;
    this.log(`design session on ${this.key}: replica lost (${ConnectError.from(lost).message}), ` +
      "reopening");
    for (const pause of RESUME_PAUSES_MS) {
      await new Promise((resolve) => setTimeout(resolve, pause));
      if (this.closed) return;
      this.call.abort.abort();
      this.startCall(false);
      const call = this.call;
      try {
        const replay = [create(DesignRequestSchema, { edit: { case: "open", value: this.open } })];
        for (const edit of this.constraints.values()) {
          replay.push(create(DesignRequestSchema, { edit }));
        }
        for (const request of replay) {
          call.requests.push(request);
          const { done } = await call.responses.next();
          if (done) throw new ConnectError("the server ended the session", Code.Unavailable);
        }
      } catch (error) {
        if (!replicaLost(error)) {
          this.resuming = false;
          this.fail(error);
          return;
        }
        continue;
      }
      this.resuming = false;
      this.resumes += 1;
      this.sendEvent({ resumed: this.resumes });
      for (const request of this.pending) call.requests.push(request);
      this.pump(call);
      return;
    }
    this.resuming = false;
    this.fail(lost);
  }

  sendEvent(event) {
    if (this.socket.readyState === this.socket.OPEN) this.socket.send(JSON.stringify(event));
  }

  // Ends the session with `error`: the page gets close code 4000 + its gRPC code and its message.
  fail(error) {
    if (this.closed) return;
    const e = ConnectError.from(error);
    this.shutdown();
    if (this.socket.readyState === this.socket.OPEN) {
      this.socket.close(CLOSE_STATUS_BASE + e.code, truncateUtf8(e.rawMessage, 120));
    }
  }

  shutdown() {
    if (this.closed) return;
    this.closed = true;
    if (this.call !== null) {
      this.call.requests.end();  // half-close: the daemon ends the session with OK
      const call = this.call;
      setTimeout(() => call.abort.abort(), 5000).unref();
    }
  }
}

// A close frame's reason holds at most 123 bytes.
function truncateUtf8(text, maxBytes) {
  const bytes = new TextEncoder().encode(text);
  if (bytes.length <= maxBytes) return text;
  return new TextDecoder().decode(bytes.slice(0, maxBytes - 3)).replace(/\uFFFD$/, "") + "...";
}
