#ifndef FIELDSPACE_CORE_SUBSPACE_SPECTRAL_MIXED_H_
#define FIELDSPACE_CORE_SUBSPACE_SPECTRAL_MIXED_H_

// Internal to core/subspace: the mixed biharmonic (BiharmonicForm::kMixed) by simultaneous
// diagonalization of the reduced stiffness and mass (docs/design-notes.md, "Mixed biharmonic
// edits"). Not a public API.

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "Eigen/Core"
#include "absl/status/statusor.h"
#include "absl/types/span.h"
#include "core/common/cancel.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace {

// All d solutions of K v = lambda Mr v for K = U^T S U and Mr = U^T M U of one reduced system
// (dense generalized symmetric eigensolve, ReducedEigenpairs with the dense method): with
// V = [v_1 .. v_d], V^T Mr V = I and V^T K V = Lambda, so K = Mr V Lambda V^T Mr and
// K Mr^-1 K = Mr V Lambda^2 V^T Mr. O(d^3) once per system (6-25 s at d = 2000 on a shared
// 2-core machine).
struct MixedSpectrum {
  Eigen::VectorXd lambda;  // d, ascending (>= 0 up to rounding: K is PSD)
  // V^T (d x d, column-major): column i holds row i of V, so that V^T r for a sparse r (a row of
  // U: ~30 nonzeros) reads a few contiguous columns.
  Eigen::MatrixXd vt;
  int64_t memory_bytes() const { return 8 * (vt.size() + lambda.size()); }
};

// The spectrum of `system` (see above). Cancelled (*cancel); Internal when the eigensolver fails.
absl::StatusOr<std::shared_ptr<const MixedSpectrum>> ComputeMixedSpectrum(
    const ReducedSystem& system, const CancelFlag* cancel = nullptr);

// The bytes a MixedSpectrum of a d-dimensional system holds: 8 (d^2 + d).
int64_t MixedSpectrumBytes(int64_t d);

// Computes the spectrum of a reduced system once and keeps it for the system's lifetime (one per
// cache: DesignSessions of a server share one). Concurrent first requests for a system wait for
// one computation; a failed or cancelled one is not kept. Thread-safe. The key is the system's
// address together with a weak reference to it, so a new system at a reused address never sees
// an old spectrum.
class MixedSpectrumCache {
 public:
  absl::StatusOr<std::shared_ptr<const MixedSpectrum>> Get(
      const std::shared_ptr<const ReducedSystem>& system, const CancelFlag* cancel = nullptr);
  // The process-wide cache (sessions without an explicit one use it).
  static MixedSpectrumCache& Global();
  // Bytes held by live entries.
  int64_t memory_bytes() const;

 private:
  struct Entry {
    std::weak_ptr<const ReducedSystem> system;
    std::mutex mu;  // held while the spectrum is computed
    std::shared_ptr<const MixedSpectrum> value;
  };
  mutable std::mutex mu_;
  std::vector<std::shared_ptr<Entry>> entries_;
};

// The inverse of the mixed energy matrix A = mu_s K + mu_b K Mr^-1 K = Mr V D V^T Mr,
// D = mu_s Lambda + mu_b Lambda^2, as a square-root factor: A^-1 = V D^-1 V^T = G G^T with
// G = V D^-1/2 (d x d). It plays the role of P^T L^-T of a Cholesky factorization in the KKT
// solver: Forward = G^T = D^-1/2 V^T, Backward = G. Directions with lambda <= 1e-10 lambda_max
// (the kernel columns' harmonic fields, zero energy to rounding) get D = kKernelColumnShift times
// the smallest D of the others, as ShiftKernelColumns does for a factorization: solves refine
// against the true A (Multiply), so a well-posed problem gets the exact solution.
class MixedEnergyInverse {
 public:
  // mu_s >= 0, mu_b > 0 (effective weights). `system` must outlive this object.
  MixedEnergyInverse(const ReducedSystem* system, std::shared_ptr<const MixedSpectrum> spectrum,
                     double mu_s, double mu_b);

  int64_t dimension() const { return inv_sqrt_d_.size(); }
  // out = G^T r (d) for a sparse r (cols, vals): O(d nnz(r)).
  void ForwardSparse(absl::Span<const int32_t> cols, absl::Span<const double> vals,
                     Eigen::Ref<Eigen::VectorXd> out) const;
  // G^T v and G u (d each): one pass over V each.
  Eigen::VectorXd Forward(const Eigen::VectorXd& v) const;
  Eigen::VectorXd Backward(const Eigen::VectorXd& u) const;
  // A v with the system's sparse K and the factorization of Mr (exact, independent of V).
  Eigen::VectorXd Multiply(const Eigen::VectorXd& v) const;

 private:
  const ReducedSystem* system_;
  std::shared_ptr<const MixedSpectrum> spectrum_;
  double mu_s_, mu_b_;
  Eigen::VectorXd inv_sqrt_d_;  // D^-1/2
};

}  // namespace fieldspace

#endif  // FIELDSPACE_CORE_SUBSPACE_SPECTRAL_MIXED_H_
