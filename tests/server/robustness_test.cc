// Issue 22's smaller holes, unit by unit: LoadMesh's open of a FIFO or a device node under the
// data root refuses at once instead of blocking, the TLS certificate's validity dates are checked
// at startup, and error messages never echo a client's id (or anything) of unbounded length.

#include <fcntl.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <future>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "server/data_root.h"
#include "server/shown_text.h"
#include "server/status_util.h"
#include "server/tls.h"
#include "tests/testing/matchers.h"

namespace fieldspace::server {
namespace {

namespace fs = std::filesystem;
using ::fieldspace::testing::StatusIs;
using ::testing::HasSubstr;

class DataRootTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("fs_data_root_test_" + std::to_string(::getpid()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(root_);
    fs::create_directories(root_ / "sub");
  }
  void TearDown() override { fs::remove_all(root_); }

  // OpenDataFile on another thread, with a bound on how long it may take: a blocking open fails
  // the test instead of hanging it (the FIFO gets a writer afterwards to free the thread).
  absl::StatusOr<ReadableFile> OpenWithin(const std::string& path, std::chrono::seconds bound) {
    auto opened =
        std::async(std::launch::async, [this, path] { return OpenDataFile(root_.string(), path); });
    if (opened.wait_for(bound) != std::future_status::ready) {
      ADD_FAILURE() << "OpenDataFile(" << path << ") blocked for " << bound.count() << " s";
      const int writer = ::open((root_ / path).c_str(), O_WRONLY | O_NONBLOCK);
      if (writer >= 0) ::close(writer);
    }
    return opened.get();
  }

  fs::path root_;
};

TEST_F(DataRootTest, FifoIsRefusedAtOnce) {
  ASSERT_EQ(::mkfifo((root_ / "sub" / "pipe.obj").c_str(), 0644), 0);
  const auto start = std::chrono::steady_clock::now();
  EXPECT_THAT(OpenWithin("sub/pipe.obj", std::chrono::seconds(5)).status(),
              StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("not a regular file")));
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(1));
}

TEST_F(DataRootTest, SymlinkToACharacterDeviceIsRefused) {
  // A relative symlink that stays below the root is followed; what it reaches here is a character
  // device (made with mknod where the test may, else a symlink that leads out is refused anyway).
  if (::mknod((root_ / "zero").c_str(), S_IFCHR | 0644, ::makedev(1, 5)) == 0) {
    fs::create_symlink("../zero", root_ / "sub" / "zero.obj");
    EXPECT_THAT(OpenWithin("sub/zero.obj", std::chrono::seconds(5)).status(),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("not a regular file")));
    EXPECT_THAT(OpenWithin("zero", std::chrono::seconds(5)).status(),
                StatusIs(absl::StatusCode::kInvalidArgument, HasSubstr("not a regular file")));
  } else {
    fs::create_symlink("/dev/zero", root_ / "sub" / "zero.obj");
    EXPECT_THAT(OpenWithin("sub/zero.obj", std::chrono::seconds(5)).status(),
                StatusIs(absl::StatusCode::kPermissionDenied));
  }
}

TEST_F(DataRootTest, RegularFileStillOpensAndReads) {
  {
    std::ofstream out(root_ / "sub" / "m.obj");
    out << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  }
  absl::StatusOr<ReadableFile> file = OpenWithin("sub/m.obj", std::chrono::seconds(5));
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_TRUE(file->is_regular);
  absl::StatusOr<std::string> text = ReadFileToString(std::move(*file), "sub/m.obj", 1 << 20);
  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(*text, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
}

// A self-signed EC certificate valid from now + from_days to now + until_days, as PEM.
std::string CertificatePem(long from_days, long until_days) {
  EVP_PKEY* key = EVP_EC_gen("P-256");
  X509* cert = X509_new();
  X509_set_version(cert, 2);
  ASN1_INTEGER_set(X509_get_serialNumber(cert), 1);
  X509_gmtime_adj(X509_getm_notBefore(cert), from_days * 86400);
  X509_gmtime_adj(X509_getm_notAfter(cert), until_days * 86400);
  X509_set_pubkey(cert, key);
  X509_NAME* name = X509_get_subject_name(cert);
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_ASC,
                             reinterpret_cast<const unsigned char*>("fieldspace"), -1, -1, 0);
  X509_set_issuer_name(cert, name);
  X509_sign(cert, key, EVP_sha256());
  BIO* bio = BIO_new(BIO_s_mem());
  PEM_write_bio_X509(bio, cert);
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio, &data);
  std::string pem(data, static_cast<size_t>(size));
  BIO_free(bio);
  X509_free(cert);
  EVP_PKEY_free(key);
  return pem;
}

TEST(TlsValidityTest, SaysWhenTheCertificateIsOutsideItsDates) {
  const int64_t now = std::time(nullptr);
  EXPECT_EQ(CertificateValidityProblem(CertificatePem(-1, 30), now), "");
  const std::string expired = CertificateValidityProblem(CertificatePem(-30, -2), now);
  EXPECT_THAT(expired, HasSubstr("the certificate expired on "));
  EXPECT_THAT(expired, HasSubstr("(valid from "));
  EXPECT_THAT(expired, HasSubstr(" GMT until "));
  const std::string early = CertificateValidityProblem(CertificatePem(2, 30), now);
  EXPECT_THAT(early, HasSubstr("the certificate is not valid before "));
  // The same certificate judged at another time: valid within its dates, expired after.
  const std::string pem = CertificatePem(-1, 1);
  EXPECT_EQ(CertificateValidityProblem(pem, now), "");
  EXPECT_THAT(CertificateValidityProblem(pem, now + 3 * 86400), HasSubstr("expired"));
  EXPECT_THAT(CertificateValidityProblem(pem, now - 3 * 86400), HasSubstr("not valid before"));
  EXPECT_EQ(CertificateValidityProblem("not a certificate", now), "no PEM certificate");
}

TEST(ShownIdTest, ShortIdsWholeLongOnesCut) {
  EXPECT_EQ(ShownId("m-0123456789abcdef"), "'m-0123456789abcdef'");
  EXPECT_EQ(ShownId(""), "''");
  const std::string sixty_four(64, 'x');
  EXPECT_EQ(ShownId(sixty_four), "'" + sixty_four + "'");
  const std::string huge(60 << 20, 'y');
  const std::string shown = ShownId(huge);
  EXPECT_EQ(shown, "'" + std::string(64, 'y') + "\u2026' (62914560 bytes)");
  // Never cut inside a UTF-8 sequence: 63 ASCII bytes, then 2-byte characters.
  std::string utf8(63, 'a');
  for (int i = 0; i < 10; ++i) utf8 += "\u00e9";
  EXPECT_EQ(ShownId(utf8), "'" + std::string(63, 'a') + "\u2026' (83 bytes)");
}

TEST(ShownIdTest, StatusMessagesOnTheWireAreBounded) {
  const std::string huge(10 << 20, 'z');
  const grpc::Status status = ToGrpcStatus(absl::NotFoundError("no mesh with id '" + huge + "'"));
  EXPECT_EQ(status.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_LE(status.error_message().size(), 4096u + 64u);
  EXPECT_THAT(status.error_message(), HasSubstr("no mesh with id 'zzz"));
  EXPECT_THAT(status.error_message(), HasSubstr("(10485778 bytes)"));
  EXPECT_EQ(ToGrpcStatus(absl::NotFoundError("short")).error_message(), "short");
}

}  // namespace
}  // namespace fieldspace::server
