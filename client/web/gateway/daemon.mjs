// A fieldspace.v1.FieldSpace client of a daemon over gRPC (HTTP/2): the gateway's way to the
// daemon, also used by the studio's tests to check the page against the daemon.
import { createClient } from "@connectrpc/connect";
import { createGrpcTransport } from "@connectrpc/connect-node";
import { FieldSpace } from "../gen/fieldspace/v1/fieldspace_pb.js";

/** address: HOST:PORT; ca: PEM text to call over TLS trusting it, or null for plaintext. */
export function daemonClient(address, { ca = null } = {}) {
  return createClient(FieldSpace, createGrpcTransport({
    baseUrl: `${ca ? "https" : "http"}://${address}`,
    nodeOptions: ca ? { ca } : {},
    // Meshes and fields travel in chunks well below this (fieldspaced's --max-message-mb: 64).
    readMaxBytes: 64 << 20,
  }));
}
