#ifndef FIELDSPACE_CORE_COMMON_RANDOM_H_
#define FIELDSPACE_CORE_COMMON_RANDOM_H_

#include <cstdint>

namespace fieldspace {

// SplitMix64 (Steele, Lea and Flood 2014): the project's one pseudo-random generator. Tiny, well
// mixed and fully specified, so that start vectors, samples and test data are the same on every
// platform (unlike std::hash or the <random> distributions).
class SplitMix64 {
 public:
  explicit SplitMix64(uint64_t seed) : state_(seed) {}

  // The next 64 random bits.
  uint64_t Next() { return Finalize(state_ += kGamma); }
  // Uniform in [-1, 1), on a grid of 2^-52.
  double NextSigned() { return static_cast<double>(Next() >> 11) * 0x1.0p-52 - 1.0; }

  // The generator's output for state x (a stateless, well-mixed hash of x).
  static uint64_t Hash(uint64_t x) { return Finalize(x + kGamma); }
  // A hash of the pair (a, b) (boost's hash_combine, then the finalizer).
  static uint64_t Combine(uint64_t a, uint64_t b) {
    return Finalize(a ^ (b + kGamma + (a << 6) + (a >> 2)));
  }

 private:
  static constexpr uint64_t kGamma = 0x9e3779b97f4a7c15ull;
  static uint64_t Finalize(uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }

  uint64_t state_;
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_COMMON_RANDOM_H_
