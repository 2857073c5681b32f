#include "core/common/file_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace fieldspace {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

class FileUtilTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           absl::StrCat("file_util_test_", ::getpid(), "_",
                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Names of the files in the test directory.
  std::vector<std::string> Listing() const {
    std::vector<std::string> names;
    for (const auto& entry : fs::directory_iterator(dir_)) {
      names.push_back(entry.path().filename().string());
    }
    return names;
  }

  fs::path dir_;
};

std::string MustRead(const std::string& path) {
  absl::StatusOr<std::string> data = ReadFileToString(path);
  EXPECT_TRUE(data.ok()) << data.status();
  return data.ok() ? *std::move(data) : std::string();
}

// A descriptor is open iff fcntl can query it.
bool IsOpen(int fd) { return ::fcntl(fd, F_GETFD) != -1; }

TEST_F(FileUtilTest, MultiPieceWriteRoundTrips) {
  const std::string path = Path("out.bin");
  std::string big(3 << 20, '\0');
  for (size_t i = 0; i < big.size(); ++i) big[i] = static_cast<char>(i * 131 + 7);
  const std::string with_nul("a\0b", 3);
  const std::vector<std::string_view> pieces = {"header\n", "", big, with_nul, "end"};
  ASSERT_TRUE(WriteFileAtomically(path, pieces).ok());
  EXPECT_EQ(MustRead(path), absl::StrCat("header\n", big, with_nul, "end"));
  EXPECT_EQ(Listing(), std::vector<std::string>{"out.bin"});

  ASSERT_TRUE(WriteFileAtomically(Path("empty"), {}).ok());
  EXPECT_EQ(MustRead(Path("empty")), "");
}

TEST_F(FileUtilTest, WriterAppendsAndCommitsOnce) {
  const std::string path = Path("streamed");
  absl::StatusOr<AtomicFileWriter> out = AtomicFileWriter::Create(path);
  ASSERT_TRUE(out.ok()) << out.status();
  EXPECT_EQ(fs::path(out->temp_path()).parent_path(), dir_);
  EXPECT_TRUE(IsTemporaryFileName(fs::path(out->temp_path()).filename().string()));
  ASSERT_TRUE(out->Append("one ").ok());
  ASSERT_TRUE(out->Append("two").ok());
  EXPECT_EQ(out->bytes_written(), 7u);
  // Nothing under the final name before the commit.
  EXPECT_FALSE(fs::exists(path));
  ASSERT_TRUE(out->Commit().ok());
  EXPECT_EQ(MustRead(path), "one two");
  EXPECT_EQ(out->Commit().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(out->Append("x").code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(Listing(), std::vector<std::string>{"streamed"});
}

TEST_F(FileUtilTest, ReplacesAnExistingFile) {
  const std::string path = Path("replace.txt");
  std::ofstream(path) << "old contents that are longer than the new ones";
  ASSERT_TRUE(WriteFileAtomically(path, {"new"}).ok());
  EXPECT_EQ(MustRead(path), "new");
  EXPECT_EQ(Listing(), std::vector<std::string>{"replace.txt"});
}

TEST_F(FileUtilTest, AbandonedWriterLeavesNothingAndKeepsTheOldFile) {
  const std::string path = Path("kept");
  std::ofstream(path) << "old";
  {
    absl::StatusOr<AtomicFileWriter> out = AtomicFileWriter::Create(path);
    ASSERT_TRUE(out.ok());
    ASSERT_TRUE(out->Append("partial").ok());
    EXPECT_TRUE(fs::exists(out->temp_path()));
    // Moving keeps one owner of the temporary file.
    AtomicFileWriter moved = *std::move(out);
    EXPECT_TRUE(fs::exists(moved.temp_path()));
  }
  EXPECT_EQ(MustRead(path), "old");
  EXPECT_EQ(Listing(), std::vector<std::string>{"kept"});
}

TEST_F(FileUtilTest, MissingDirectoryFailsNamingThePathAndLeavesNoTemporary) {
  const std::string path = Path("no_such_dir/x.bin");
  const absl::Status status = WriteFileAtomically(path, {"abc", "def"});
  EXPECT_EQ(status.code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(status.message(), HasSubstr(path));
  EXPECT_THAT(status.message(), HasSubstr("No such file or directory"));
  EXPECT_TRUE(Listing().empty());
}

TEST_F(FileUtilTest, FailedRenameRemovesTheTemporary) {
  // A non-empty directory under the final name: rename(2) fails after the data is written.
  const std::string path = Path("occupied");
  fs::create_directories(dir_ / "occupied" / "inside");
  const absl::Status status = WriteFileAtomically(path, {"data"});
  EXPECT_FALSE(status.ok());
  EXPECT_THAT(status.message(), HasSubstr(path));
  EXPECT_THAT(status.message(), HasSubstr("renaming"));
  EXPECT_EQ(Listing(), std::vector<std::string>{"occupied"});
}

TEST_F(FileUtilTest, CustomErrnoMapping) {
  AtomicWriteOptions options;
  options.errno_status = [](int err, std::string_view what) {
    return absl::InternalError(
        absl::StrCat("mapped ", err, " ", absl::string_view(what.data(), what.size())));
  };
  const absl::Status status = WriteFileAtomically(Path("missing/x"), {"x"}, options);
  EXPECT_EQ(status.code(), absl::StatusCode::kInternal);
  EXPECT_THAT(status.message(), HasSubstr("mapped"));
}

TEST_F(FileUtilTest, MidwayHookRunsOnceWithOnlyTheTemporaryPresent) {
  const std::string path = Path("hooked");
  int calls = 0;
  AtomicWriteOptions options;
  options.midway_hook_at_byte = 5;
  options.midway_hook = [&] {
    ++calls;
    // Exactly the first five bytes are in the temporary file; the final name does not exist.
    EXPECT_FALSE(fs::exists(path));
    const std::vector<std::string> names = Listing();
    ASSERT_EQ(names.size(), 1u);
    EXPECT_TRUE(IsTemporaryFileName(names[0]));
    EXPECT_EQ(MustRead(Path(names[0])), "01234");
  };
  ASSERT_TRUE(WriteFileAtomically(path, {"012", "3456789"}, options).ok());
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(MustRead(path), "0123456789");

  // A hook beyond the end still runs, before the commit.
  calls = 0;
  options.midway_hook_at_byte = 1000;
  options.midway_hook = [&] {
    ++calls;
    EXPECT_FALSE(fs::exists(Path("short")));
  };
  ASSERT_TRUE(WriteFileAtomically(Path("short"), {"ab"}, options).ok());
  EXPECT_EQ(calls, 1);
}

TEST_F(FileUtilTest, TemporaryFileNames) {
  EXPECT_TRUE(IsTemporaryFileName(".b-00ff.fsbasis.tmp-123-0"));
  EXPECT_FALSE(IsTemporaryFileName("b-00ff.fsbasis"));
  EXPECT_FALSE(IsTemporaryFileName("x.tmp-1-2"));
  EXPECT_FALSE(IsTemporaryFileName(".hidden"));
}

TEST_F(FileUtilTest, ReadHonoursTheSizeCap) {
  const std::string path = Path("capped");
  const std::string data(1000, 'z');
  ASSERT_TRUE(WriteFileAtomically(path, {data}).ok());
  absl::StatusOr<std::string> exact = ReadFileToString(path, 1000);
  ASSERT_TRUE(exact.ok()) << exact.status();
  EXPECT_EQ(*exact, data);
  absl::StatusOr<std::string> over = ReadFileToString(path, 999);
  EXPECT_EQ(over.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_THAT(over.status().message(), HasSubstr(path));
  EXPECT_THAT(over.status().message(), HasSubstr("999 bytes"));

  EXPECT_EQ(ReadFileToString(Path("absent")).status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(ReadFileToString(dir_.string()).status().code(), absl::StatusCode::kInvalidArgument);
}

TEST_F(FileUtilTest, ReadCapAppliesToPipes) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  ScopedFd read_end(fds[0]);
  ScopedFd write_end(fds[1]);
  ASSERT_TRUE(WriteAll(write_end.get(), std::string(100, 'p'), "pipe").ok());
  ASSERT_EQ(write_end.Close(), 0);
  const std::string path = absl::StrCat("/proc/self/fd/", read_end.get());
  EXPECT_EQ(ReadFileToString(path, 99).status().code(), absl::StatusCode::kResourceExhausted);
}

TEST_F(FileUtilTest, ReadExactlyAtAndOpenForReading) {
  const std::string path = Path("positioned");
  ASSERT_TRUE(WriteFileAtomically(path, {"0123456789"}).ok());
  absl::StatusOr<ReadableFile> file = OpenForReading(path);
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_TRUE(file->is_regular);
  EXPECT_FALSE(file->is_directory);
  EXPECT_EQ(file->size, 10);
  char buffer[4];
  ASSERT_TRUE(ReadExactlyAt(file->fd.get(), 3, buffer, 4, path).ok());
  EXPECT_EQ(std::string_view(buffer, 4), "3456");
  const absl::Status past_end = ReadExactlyAt(file->fd.get(), 8, buffer, 4, path);
  EXPECT_EQ(past_end.code(), absl::StatusCode::kDataLoss);
  EXPECT_THAT(past_end.message(), HasSubstr(path));

  absl::StatusOr<ReadableFile> missing = OpenForReading(Path("missing"));
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(missing.status().message(), HasSubstr(Path("missing")));
}

TEST(ScopedFdTest, MoveTransfersOwnership) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  ScopedFd a(fds[0]);
  ScopedFd other(fds[1]);
  EXPECT_TRUE(a.is_open());

  ScopedFd b(std::move(a));
  EXPECT_FALSE(a.is_open());  // NOLINT(bugprone-use-after-move): moved-from state is specified
  EXPECT_EQ(a.get(), -1);     // NOLINT(bugprone-use-after-move)
  EXPECT_EQ(b.get(), fds[0]);
  EXPECT_TRUE(IsOpen(fds[0]));

  // Move assignment closes what the target held.
  b = std::move(other);
  EXPECT_FALSE(IsOpen(fds[0]));
  EXPECT_EQ(b.get(), fds[1]);
  EXPECT_TRUE(IsOpen(fds[1]));

  // Self-move keeps the descriptor.
  ScopedFd& alias = b;
  b = std::move(alias);
  EXPECT_TRUE(IsOpen(fds[1]));

  { ScopedFd scoped(std::move(b)); }
  EXPECT_FALSE(IsOpen(fds[1]));
  EXPECT_FALSE(b.is_open());  // NOLINT(bugprone-use-after-move)
}

TEST(ScopedFdTest, ReleaseResetAndClose) {
  int fds[2];
  ASSERT_EQ(::pipe(fds), 0);
  ScopedFd a(fds[0]);
  const int raw = a.release();
  EXPECT_EQ(raw, fds[0]);
  EXPECT_FALSE(a.is_open());
  EXPECT_TRUE(IsOpen(raw));
  a.reset(raw);
  EXPECT_EQ(a.get(), raw);
  a.reset();
  EXPECT_FALSE(IsOpen(raw));

  ScopedFd b(fds[1]);
  EXPECT_EQ(b.Close(), 0);
  EXPECT_FALSE(b.is_open());
  EXPECT_FALSE(IsOpen(fds[1]));
  EXPECT_EQ(b.Close(), EBADF);  // nothing left to close
  ScopedFd empty;
  EXPECT_EQ(empty.get(), -1);
}

}  // namespace
}  // namespace fieldspace
