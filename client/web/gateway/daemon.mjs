// A fieldspace.v1.FieldSpace client of a daemon over gRPC (HTTP/2): the gateway's way to the
// daemon, also used by the studio's tests to check the page against the daemon.
import { EmptySchema } from "@bufbuild/protobuf/wkt";
import { createClient } from "@connectrpc/connect";
import { createGrpcTransport } from "@connectrpc/connect-node";
import { FieldSpace } from "../gen/fieldspace/v1/fieldspace_pb.js";

// FieldSpace with every answer kept as the bytes the daemon sent: read as a message without fields
// (google.protobuf.Empty), each field stays an unknown field and is written back unchanged. The
// gateway relays binary calls and design sessions with it: parsing a large answer and serializing
// it again with protobuf-es took ~6 ms per design update of 2000 coefficients and 2500 faces, and
// the geometry of a 1.4M-face mesh 11.9 s through the gateway instead of 5.2 s (bench/RESULTS.md,
// "Studio").
export const RAW_FIELDSPACE = (() => {
  const methods = FieldSpace.methods.map((m) => ({ ...m, output: EmptySchema }));
  return { ...FieldSpace, methods, method: Object.fromEntries(methods.map((m) => [m.localName, m])) };
})();

/** address: HOST:PORT; ca: PEM text to call over TLS trusting it, or null for plaintext;
 *  service: FieldSpace, or RAW_FIELDSPACE for answers as the daemon's bytes. */
export function daemonClient(address, { ca = null, service = FieldSpace } = {}) {
  return createClient(service, createGrpcTransport({
    baseUrl: `${ca ? "https" : "http"}://${address}`,
    nodeOptions: ca ? { ca } : {},
    // Meshes and fields travel in chunks well below this (fieldspaced's --max-message-mb: 64).
    readMaxBytes: 64 << 20,
  }));
}
