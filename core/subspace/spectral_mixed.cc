#include "core/subspace/spectral_mixed.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/subspace/kkt_solver.h"
#include "core/subspace/spectrum.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {
namespace {

// Rows or columns of V^T per task of a product with it.
constexpr Eigen::Index kBand = 256;

}  // namespace

absl::StatusOr<std::shared_ptr<const MixedSpectrum>> ComputeMixedSpectrum(
    const ReducedSystem& system, const CancelFlag* cancel) {
  ReducedEigenOptions options;
  options.count = system.dimension();
  options.method = ReducedEigenMethod::kDense;
  options.compute_vectors = true;
  options.cancel = cancel;
  ASSIGN_OR_RETURN(ReducedEigenResult eig, ReducedEigenpairs(system, options));
  auto out = std::make_shared<MixedSpectrum>();
  out->lambda = std::move(eig.values);
  out->vt = eig.coefficients.transpose();
  return std::shared_ptr<const MixedSpectrum>(std::move(out));
}

int64_t MixedSpectrumBytes(int64_t d) { return 8 * (d * d + d); }

MixedSpectrumCache& MixedSpectrumCache::Global() {
  static MixedSpectrumCache* cache = new MixedSpectrumCache();
  return *cache;
}

absl::StatusOr<std::shared_ptr<const MixedSpectrum>> MixedSpectrumCache::Get(
    const std::shared_ptr<const ReducedSystem>& system, const CancelFlag* cancel) {
  if (system == nullptr) return absl::InvalidArgumentError("MixedSpectrumCache: no system");
  std::shared_ptr<Entry> entry;
  {
    std::lock_guard<std::mutex> lock(mu_);
    // Drop the entries of systems that are gone (nobody computing: referenced only here).
    std::erase_if(entries_, [](const std::shared_ptr<Entry>& e) {
      return e.use_count() == 1 && e->system.expired();
    });
    for (const std::shared_ptr<Entry>& e : entries_) {
      if (e->system.lock() == system) {
        entry = e;
        break;
      }
    }
    if (entry == nullptr) {
      entry = std::make_shared<Entry>();
      entry->system = system;
      entries_.push_back(entry);
    }
  }
  std::lock_guard<std::mutex> lock(entry->mu);
  if (entry->value != nullptr) return entry->value;
  ASSIGN_OR_RETURN(entry->value, ComputeMixedSpectrum(*system, cancel));
  return entry->value;
}

int64_t MixedSpectrumCache::memory_bytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  int64_t bytes = 0;
  for (const std::shared_ptr<Entry>& e : entries_) {
    // An entry being computed holds its lock; its size is not known yet.
    std::unique_lock<std::mutex> entry_lock(e->mu, std::try_to_lock);
    if (entry_lock.owns_lock() && e->value != nullptr && !e->system.expired()) {
      bytes += e->value->memory_bytes();
    }
  }
  return bytes;
}

MixedEnergyInverse::MixedEnergyInverse(const ReducedSystem* system,
                                       std::shared_ptr<const MixedSpectrum> spectrum, double mu_s,
                                       double mu_b)
    : system_(system), spectrum_(std::move(spectrum)), mu_s_(mu_s), mu_b_(mu_b) {
  const Eigen::VectorXd& lambda = spectrum_->lambda;
  const int64_t d = lambda.size();
  const double lambda_max = std::max(lambda.maxCoeff(), 0.0);
  // Zero energy to rounding: the harmonic fields of the kernel columns (or of a basis that holds
  // them without marking them).
  const double kernel = 1e-10 * lambda_max;
  Eigen::VectorXd D(d);
  double smallest = std::numeric_limits<double>::infinity();
  for (int64_t i = 0; i < d; ++i) {
    const double l = lambda[i];
    D[i] = l > kernel ? mu_s * l + mu_b * l * l : 0.0;
    if (D[i] > 0) smallest = std::min(smallest, D[i]);
  }
  // Every direction at zero energy (S = 0: nothing to measure against) gets D = 1.
  const double shift = std::isfinite(smallest) ? kKernelColumnShift * smallest : 1.0;
  inv_sqrt_d_.resize(d);
  for (int64_t i = 0; i < d; ++i) inv_sqrt_d_[i] = 1.0 / std::sqrt(D[i] > 0 ? D[i] : shift);
}

void MixedEnergyInverse::ForwardSparse(absl::Span<const int32_t> cols,
                                       absl::Span<const double> vals,
                                       Eigen::Ref<Eigen::VectorXd> out) const {
  // V^T r = sum_q r_q (row cols[q] of V) = sum_q r_q vt.col(cols[q]).
  out.setZero();
  for (size_t q = 0; q < cols.size(); ++q) out.noalias() += vals[q] * spectrum_->vt.col(cols[q]);
  out.array() *= inv_sqrt_d_.array();
}

Eigen::VectorXd MixedEnergyInverse::Forward(const Eigen::VectorXd& v) const {
  // V^T v = vt v, by bands of rows (bands of columns of V^T would race on the output).
  const Eigen::MatrixXd& vt = spectrum_->vt;
  Eigen::VectorXd out(vt.rows());
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, vt.rows(), kBand),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      out.segment(r.begin(), r.size()).noalias() =
                          vt.middleRows(r.begin(), r.size()) * v;
                    });
  out.array() *= inv_sqrt_d_.array();
  return out;
}

Eigen::VectorXd MixedEnergyInverse::Backward(const Eigen::VectorXd& u) const {
  // V (D^-1/2 u) = vt^T (D^-1/2 u): dot products with vt's contiguous columns, a band of them
  // per task (the product streams all of V from memory: two cores fetch it faster than one).
  const Eigen::MatrixXd& vt = spectrum_->vt;
  const Eigen::VectorXd scaled = inv_sqrt_d_.cwiseProduct(u);
  Eigen::VectorXd out(vt.cols());
  tbb::parallel_for(tbb::blocked_range<Eigen::Index>(0, vt.cols(), kBand),
                    [&](const tbb::blocked_range<Eigen::Index>& r) {
                      out.segment(r.begin(), r.size()).noalias() =
                          vt.middleCols(r.begin(), r.size()).transpose() * scaled;
                    });
  return out;
}

Eigen::VectorXd MixedEnergyInverse::Multiply(const Eigen::VectorXd& v) const {
  const Eigen::SparseMatrix<double>& K = system_->stiffness();
  const Eigen::VectorXd kv = K * v;
  Eigen::VectorXd out = mu_b_ * (K * system_->mass_factor().Solve(kv));
  out.noalias() += mu_s_ * kv;
  return out;
}

}  // namespace fieldspace
