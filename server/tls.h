#ifndef FIELDSPACE_SERVER_TLS_H_
#define FIELDSPACE_SERVER_TLS_H_

#include <cstdint>
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

// Whether the certificate (the first of `cert_pem`) is valid at `now` (seconds since the epoch):
// empty if so, otherwise a sentence saying it has expired or is not yet valid, with its validity
// dates ("... expired on Jan  1 00:00:00 2020 GMT (valid from ... until ...)"). The daemon still
// starts with such a certificate (a clock may be wrong; clients refuse it anyway) but warns.
std::string CertificateValidityProblem(const std::string& cert_pem, int64_t now);

// The credentials of the listening port: PlaintextServerCredentials (auth.h) without TLS, otherwise
// SslServerCredentials of the files, read and checked first. InvalidArgument, naming the flag
// and the file, for a certificate without a key or the other way round, a client CA without a
// certificate, a file that cannot be read or holds no PEM certificate (key), and a key that does
// not belong to the certificate. A certificate outside its validity dates is accepted with a
// warning on stderr (CertificateValidityProblem).
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const TlsFiles& files);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_TLS_H_
