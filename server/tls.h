#ifndef FIELDSPACE_SERVER_TLS_H_
#define FIELDSPACE_SERVER_TLS_H_

#include <memory>
#include <string>

#include "absl/status/statusor.h"

namespace grpc {
class ServerCredentials;
}  // namespace grpc

namespace fieldspace::server {

// The daemon's TLS: PEM files named by --tls-cert, --tls-key and --tls-client-ca. All empty:
// plaintext.
struct TlsFiles {
  std::string cert_file;       // the server's certificate (chain: leaf first)
  std::string key_file;        // its private key (unencrypted)
  std::string client_ca_file;  // when set: mutual TLS, clients need a certificate signed by it

  bool enabled() const { return !cert_file.empty() || !key_file.empty(); }
  // Whether clients must present a certificate (which authenticates them).
  bool verifies_clients() const { return !client_ca_file.empty(); }
};

// The credentials of the listening port: PlaintextServerCredentials (auth.h) without TLS, otherwise
// SslServerCredentials of the files, read and checked first. InvalidArgument, naming the flag
// and the file, for a certificate without a key or the other way round, a client CA without a
// certificate, a file that cannot be read or holds no PEM certificate (key), and a key that does
// not belong to the certificate.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const TlsFiles& files);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_TLS_H_
