#include "server/tls.h"

#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <ctime>
#include <iostream>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/common/file_util.h"
#include "core/common/status_macros.h"
#include "grpcpp/security/server_credentials.h"
#include "server/auth.h"

namespace fieldspace::server {
namespace {

// TLS files are small; anything larger is not one.
constexpr int64_t kMaxPemBytes = int64_t{1} << 20;

struct BioFree {
  void operator()(BIO* bio) const { BIO_free(bio); }
};
struct X509Free {
  void operator()(X509* cert) const { X509_free(cert); }
};
struct KeyFree {
  void operator()(EVP_PKEY* key) const { EVP_PKEY_free(key); }
};
using Bio = std::unique_ptr<BIO, BioFree>;
using Certificate = std::unique_ptr<X509, X509Free>;
using PrivateKey = std::unique_ptr<EVP_PKEY, KeyFree>;

Bio MemoryBio(const std::string& pem) {
  return Bio(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
}

// Never asks for a passphrase (OpenSSL's default would prompt on the terminal): an encrypted key
// fails to load.
int NoPassphrase(char*, int, int, void*) { return 0; }

// The file of `flag`, read ("--tls-cert FILE: <why>" when it cannot be).
absl::StatusOr<std::string> ReadPem(const std::string& flag, const std::string& path) {
  absl::StatusOr<std::string> pem = ReadFileToString(path, kMaxPemBytes);
  if (!pem.ok()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", flag, " ", path, ": cannot read it: ", pem.status().message()));
  }
  return pem;
}

// The first certificate of `pem` (a chain may follow), or InvalidArgument naming the flag.
absl::StatusOr<Certificate> FirstCertificate(const std::string& flag, const std::string& path,
                                             const std::string& pem) {
  Bio bio = MemoryBio(pem);
  Certificate cert(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr));
  ERR_clear_error();
  if (cert == nullptr) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", flag, " ", path, ": no PEM certificate in it"));
  }
  return cert;
}

// An ASN1 time as OpenSSL prints it ("Jan  1 00:00:00 2020 GMT").
std::string TimeText(const ASN1_TIME* time) {
  Bio bio(BIO_new(BIO_s_mem()));
  if (bio == nullptr || ASN1_TIME_print(bio.get(), time) != 1) return "?";
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, static_cast<size_t>(size));
}

}  // namespace

std::string CertificateValidityProblem(const std::string& cert_pem, int64_t now) {
  Bio bio = MemoryBio(cert_pem);
  const Certificate cert(PEM_read_bio_X509(bio.get(), nullptr, NoPassphrase, nullptr));
  ERR_clear_error();
  if (cert == nullptr) return "no PEM certificate";
  time_t at = static_cast<time_t>(now);
  const ASN1_TIME* not_before = X509_get0_notBefore(cert.get());
  const ASN1_TIME* not_after = X509_get0_notAfter(cert.get());
  const std::string dates =
      absl::StrCat("(valid from ", TimeText(not_before), " until ", TimeText(not_after), ")");
  // X509_cmp_time: -1 if the time is before `at`, 1 if after, 0 on error.
  if (X509_cmp_time(not_after, &at) < 0) {
    return absl::StrCat("the certificate expired on ", TimeText(not_after), " ", dates);
  }
  if (X509_cmp_time(not_before, &at) > 0) {
    return absl::StrCat("the certificate is not valid before ", TimeText(not_before), " ", dates);
  }
  return "";
}

absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> MakeServerCredentials(
    const TlsFiles& files) {
  if (!files.enabled()) {
    if (files.verifies_clients()) {
      return absl::InvalidArgumentError(
          "--tls-client-ca needs --tls-cert and --tls-key (the server's own certificate)");
    }
    return PlaintextServerCredentials();
  }
  if (files.cert_file.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls-key ", files.key_file, " needs --tls-cert (its certificate)"));
  }
  if (files.key_file.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--tls-cert ", files.cert_file, " needs --tls-key (its private key)"));
  }
  ASSIGN_OR_RETURN(const std::string cert_pem, ReadPem("tls-cert", files.cert_file));
  ASSIGN_OR_RETURN(const std::string key_pem, ReadPem("tls-key", files.key_file));
  ASSIGN_OR_RETURN(const Certificate cert, FirstCertificate("tls-cert", files.cert_file, cert_pem));
  Bio key_bio = MemoryBio(key_pem);
  const PrivateKey key(PEM_read_bio_PrivateKey(key_bio.get(), nullptr, NoPassphrase, nullptr));
  ERR_clear_error();
  if (key == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tls-key ", files.key_file, ": no PEM private key in it (encrypted keys are not read)"));
  }
  const bool match = X509_check_private_key(cert.get(), key.get()) == 1;
  ERR_clear_error();
  if (!match) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--tls-key ", files.key_file, " is not the key of --tls-cert ", files.cert_file));
  }

  // Clients refuse such a certificate: say so at startup rather than leave them to find out.
  if (const std::string problem = CertificateValidityProblem(cert_pem, std::time(nullptr));
      !problem.empty()) {
    std::cerr << "fieldspaced: warning: --tls-cert " << files.cert_file << ": " << problem
              << "; TLS clients will refuse it\n";
  }

  grpc::SslServerCredentialsOptions options;
  options.pem_key_cert_pairs.push_back({key_pem, cert_pem});
  if (files.verifies_clients()) {
    ASSIGN_OR_RETURN(options.pem_root_certs, ReadPem("tls-client-ca", files.client_ca_file));
    RETURN_IF_ERROR(
        FirstCertificate("tls-client-ca", files.client_ca_file, options.pem_root_certs).status());
    options.client_certificate_request = GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
  }
  return grpc::SslServerCredentials(options);
}

}  // namespace fieldspace::server
