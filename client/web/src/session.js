// The page's design session: one WebSocket to the gateway, one binary frame per
// fieldspace.v1.DesignRequest / DesignUpdate (docs/studio.md, "Design sessions").
//
// At most one edit is in flight. Edits made meanwhile wait in a short queue where a move of the
// constraint that the last queued edit moves, or new weights after queued weights, replace that
// entry: a drag never builds a backlog of stale positions, and the last state sent is the last
// state the user made. The session keeps what the server confirmed (weights, constraints in the
// order added): the page stores it, and a new session (after a reload, or after the connection
// was lost) replays it. An edit the daemon refuses is answered with its error and costs only
// that edit.
import { create, fromBinary, toBinary } from "@bufbuild/protobuf";
import {
  BoundaryAlignMode, DesignRequestSchema, DesignUpdateSchema, FieldEncoding,
} from "../gen/fieldspace/v1/fieldspace_pb.js";

// Close codes 4000 + gRPC code carry the error that ended a session (gateway/design_relay.mjs).
const CLOSE_STATUS_BASE = 4000;
export const DESIGN_PROTOCOL = "fieldspace.design.v1";
// Answered edits kept in DesignSession.updateLog (the latest ones; docs/studio.md, "Performance").
const UPDATE_LOG_LENGTH = 2000;

/** The Constraint message of a page constraint { face, value (ambient), hard, weight }. */
export function constraintMessage(c) {
  return {
    face: c.face,
    value: c.value,
    encoding: FieldEncoding.AMBIENT,
    hard: c.hard,
    ...(c.hard ? {} : { weight: c.weight }),
  };
}

/**
 * The ConstraintGroup oneof ({ case, value }) of a page tool (a constraint with `tool`): a stroke
 * { points: [{ face, barycentric }] }, a placed singularity { vertex, index (whole turns) }, a
 * boundary alignment { mode: "tangent" | "normal" } or a feature alignment { angle (degrees) };
 * each with hard and weight. The daemon turns it into constraints (docs/api.md, Design sessions).
 */
export function groupMessage(id, c) {
  const common = { id, hard: c.hard, ...(c.hard ? {} : { weight: c.weight }) };
  switch (c.tool) {
    case "stroke":
      return { case: "stroke", value: { ...common, points: c.points.map((p) => ({
        at: { case: "facePoint", value: { face: p.face, barycentric: p.barycentric } } })) } };
    case "singularity":
      return { case: "singularity", value: { ...common, at: { case: "vertex", value: c.vertex },
        index: c.index } };
    case "boundary":
      return { case: "alignBoundary", value: { ...common, mode: c.mode === "normal"
        ? BoundaryAlignMode.BOUNDARY_ALIGN_NORMAL : BoundaryAlignMode.BOUNDARY_ALIGN_TANGENT } };
    case "features":
      return { case: "alignFeatures", value: { ...common, angleDegrees: c.angle } };
    default:
      throw new Error(`unknown tool ${c.tool}`);
  }
}

// The DesignRequest edit that adds a tool, by the ConstraintGroup case.
const ADD_TOOL = { stroke: "addStroke", singularity: "placeSingularity",
  alignBoundary: "alignBoundary", alignFeatures: "alignFeatures" };

function editMessage(edit) {
  switch (edit.kind) {
    case "add":
      if (edit.constraint.tool !== undefined) {
        const group = groupMessage(edit.id, edit.constraint);
        return { case: ADD_TOOL[group.case], value: group.value };
      }
      return { case: "add", value: { id: edit.id, constraint: constraintMessage(edit.constraint) } };
    case "move":
      return { case: "move", value: { id: edit.id, face: edit.face, value: edit.value,
        encoding: FieldEncoding.AMBIENT } };
    case "replace":  // a tool's group by a new one under the same id
      return { case: "move", value: { id: edit.id,
        group: { tool: groupMessage(edit.id, edit.constraint) } } };
    case "remove":
      return { case: "remove", value: { id: edit.id } };
    case "weights":
      return { case: "setWeights", value: { ...edit.weights } };
    case "watch":
      return { case: "watch", value: { faces: Array.from(edit.faces),
        encoding: FieldEncoding.AMBIENT } };
    default:
      throw new Error(`unknown edit ${edit.kind}`);
  }
}

export class DesignSession {
  /**
   * url: the gateway's ws(s) URL of design sessions; token: "" or the studio's token;
   * open: { basisId, weights {muS, muB, muC[, muA]}, watchFaces, singularities, curvature }
   * (curvature: the session's energy has the curvature-alignment data term, weight muA);
   * confirmed: { weights, constraints: Map id -> constraint } to replay after the open;
   * handlers: onUpdate(update, edit, roundTripMs), onRefused(code, message, edit) (the daemon
   * refused that edit; the session goes on without it), onReady(), onClosed(code, message, edit),
   * onEvent(object).
   */
  constructor({ url, token, open, confirmed, handlers }) {
    this.handlers = handlers;
    this.weights = { ...confirmed.weights };
    this.constraints = new Map([...confirmed.constraints].map(([id, c]) => [id, { ...c }]));
    // What the user made: the confirmed state with the edits in flight and queued applied.
    this.desired = { weights: { ...this.weights },
      constraints: new Map([...this.constraints].map(([id, c]) => [id, { ...c }])) };
    this.queue = [];
    this.inFlight = null;
    this.ready = false;
    this.closed = false;
    this.seq = 0;
    this.last = null;
    // Per answered edit: { kind, made: [when each edit it carries was made], sent, decoded,
    // handled (the page's handler returned), bytes, timings } (performance.now() ms; `made` has
    // several times when moves were coalesced).
    this.updateLog = [];
    this.made = new Map();  // queued edit -> the times its coalesced edits were made
    const protocols = [DESIGN_PROTOCOL];
    if (token) protocols.push(`bearer.${base64url(token)}`);
    this.socket = new WebSocket(url, protocols);
    this.socket.binaryType = "arraybuffer";
    this.socket.onopen = () => {
      this.send({ kind: "open", replay: true }, {
        case: "open",
        value: { basisId: open.basisId, weights: { ...this.weights },
          watchFaces: Array.from(open.watchFaces), watchEncoding: FieldEncoding.AMBIENT,
          singularities: open.singularities,
          ...(open.curvature ? { data: { target: { case: "curvature", value: {} } } } : {}) },
      });
      for (const [id, constraint] of this.constraints) {
        this.queue.push({ kind: "add", id, constraint, replay: true });
      }
    };
    this.socket.onmessage = (event) => this.onFrame(event.data);
    this.socket.onclose = (event) => this.onClose(event);
  }

  /** No edit in flight or waiting, and the session is open. */
  get idle() {
    return this.ready && this.inFlight === null && this.queue.length === 0;
  }

  /** Queues an edit ({kind: add|move|replace|remove|weights|watch, ...}); see the coalescing rule
   *  above (a replace of the tool that the last waiting edit replaces, and new watched faces after
   *  waiting ones, replace that entry too). */
  edit(edit) {
    if (this.closed) return;
    const made = performance.now();
    applyEdit(this.desired, edit);
    const last = this.queue[this.queue.length - 1];
    if (last !== undefined && !last.replay && last.kind === edit.kind &&
        (((edit.kind === "move" || edit.kind === "replace") && last.id === edit.id) ||
         edit.kind === "weights" || edit.kind === "watch")) {
      if (edit.kind === "weights") Object.assign(last.weights, edit.weights);
      else Object.assign(last, edit);
      this.made.get(last)?.push(made);
    } else {
      this.queue.push(edit);
      this.made.set(edit, [made]);
    }
    this.pump();
  }

  pump() {
    if (this.inFlight !== null || this.closed || this.socket.readyState !== WebSocket.OPEN) return;
    const edit = this.queue.shift();
    if (edit !== undefined) this.send(edit, editMessage(edit));
  }

  send(edit, message) {
    const request = create(DesignRequestSchema, { seq: BigInt(this.seq++), edit: message });
    const made = this.made.get(edit) ?? [];
    this.made.delete(edit);
    this.inFlight = { edit, sent: performance.now(), made };
    this.socket.send(toBinary(DesignRequestSchema, request));
  }

  onFrame(data) {
    if (typeof data === "string") {
      this.handlers.onEvent?.(JSON.parse(data));
      return;
    }
    const update = fromBinary(DesignUpdateSchema, new Uint8Array(data));
    const { edit, sent, made } = this.inFlight;
    const decoded = performance.now();
    const roundTripMs = decoded - sent;
    this.inFlight = null;
    const entry = { kind: edit.kind, made, sent, decoded, handled: null, bytes: data.byteLength,
      timings: update.timings ? { editMs: update.timings.editMs, liftMs: update.timings.liftMs,
        totalMs: update.timings.totalMs } : null };
    this.updateLog.push(entry);
    if (this.updateLog.length > UPDATE_LOG_LENGTH) this.updateLog.shift();
    if (update.error !== undefined) {
      // The daemon refused this edit and the session goes on as it was: what the user made is
      // the confirmed state with the edits still queued.
      this.desired = { weights: { ...this.weights },
        constraints: new Map([...this.constraints].map(([id, c]) => [id, { ...c }])) };
      for (const queued of this.queue) applyEdit(this.desired, queued);
      this.handlers.onRefused?.(update.error.code, update.error.message, edit);
      this.pump();
      return;
    }
    this.confirm(edit);
    this.last = update;
    if (!this.ready && this.queue.every((e) => !e.replay)) {
      this.ready = true;
      this.handlers.onReady?.();
    }
    // The next edit goes out before the page draws this update, so that the daemon works on it
    // meanwhile.
    this.pump();
    this.handlers.onUpdate(update, edit, roundTripMs);
    entry.handled = performance.now();
  }

  confirm(edit) {
    applyEdit(this, edit);
  }

  onClose(event) {
    if (this.closed) return;
    this.closed = true;
    const edit = this.inFlight?.edit ?? null;
    const code = event.code >= CLOSE_STATUS_BASE ? event.code - CLOSE_STATUS_BASE : null;
    this.handlers.onClosed(code, event.reason || `connection closed (${event.code})`, edit);
  }

  close() {
    if (this.closed) return;
    this.closed = true;
    this.socket.close(1000);
  }
}

/** Applies an edit to a state { weights, constraints: Map id -> constraint }. */
function applyEdit(state, edit) {
  if (edit.kind === "add" || edit.kind === "replace") {
    state.constraints.set(edit.id, { ...edit.constraint });
  } else if (edit.kind === "remove") {
    state.constraints.delete(edit.id);
  } else if (edit.kind === "move") {
    const c = state.constraints.get(edit.id);
    if (c !== undefined) Object.assign(c, { face: edit.face, value: [...edit.value] });
  } else if (edit.kind === "weights") Object.assign(state.weights, edit.weights);
}

function base64url(text) {
  const bytes = new TextEncoder().encode(text);
  let binary = "";
  for (const b of bytes) binary += String.fromCharCode(b);
  return btoa(binary).replace(/\+/g, "-").replace(/\//g, "_").replace(/=+$/, "");
}

/** Undo / redo of user actions; an action is { do: [edits], undo: [edits] }. */
export class History {
  constructor(saved) {
    this.undoStack = saved?.undo ?? [];
    this.redoStack = saved?.redo ?? [];
  }
  push(action) {
    this.undoStack.push(action);
    this.redoStack = [];
  }
  undo() {
    const action = this.undoStack.pop();
    if (action !== undefined) this.redoStack.push(action);
    return action?.undo ?? null;
  }
  redo() {
    const action = this.redoStack.pop();
    if (action !== undefined) this.undoStack.push(action);
    return action?.do ?? null;
  }
  toJSON() {
    return { undo: this.undoStack, redo: this.redoStack };
  }
}
