#ifndef FIELDSPACE_SERVER_HASH_H_
#define FIELDSPACE_SERVER_HASH_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

namespace fieldspace::server {

// Streaming XXH64 (Yann Collet's xxHash, 64-bit variant): a fast non-cryptographic hash, stable
// across platforms, versions and runs. Used for content-derived ids and for store checksums, both
// of which must never change meaning once written, so the algorithm is fixed here rather than
// borrowed from a library whose hash may change (absl::Hash is salted per process).
class Hasher {
 public:
  explicit Hasher(uint64_t seed = 0);

  void Update(const void* data, size_t size);
  void Update(std::string_view bytes) { Update(bytes.data(), bytes.size()); }
  // Hashes the little-endian bytes of a trivially copyable value (the store and ids are defined
  // on little-endian hosts only; see store.cc).
  template <typename T>
  void UpdateValue(const T& value) {
    Update(&value, sizeof(T));
  }
  // Length-prefixed, so that ("ab", "c") and ("a", "bc") differ.
  void UpdateString(std::string_view s);

  // The hash of everything passed so far (does not reset the state).
  uint64_t Digest() const;

 private:
  uint64_t v_[4];
  uint64_t seed_;
  uint64_t total_ = 0;
  unsigned char buffer_[32];
  size_t buffered_ = 0;
};

// One-shot XXH64.
uint64_t Hash64(const void* data, size_t size, uint64_t seed = 0);

// 16 lowercase hex digits.
std::string Hex64(uint64_t value);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_HASH_H_
