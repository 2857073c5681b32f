#include "core/linalg/lanczos.h"

#include <exception>
#include <utility>

#include "Spectra/SymEigsShiftSolver.h"
#include "Spectra/SymEigsSolver.h"
#include "Spectra/SymGEigsShiftSolver.h"
#include "absl/strings/str_format.h"

namespace fieldspace {
namespace {

// Carries an operator's Status out of Spectra's callback, which cannot return one.
class StatusException : public std::exception {
 public:
  explicit StatusException(absl::Status status) : status_(std::move(status)) {}
  const char* what() const noexcept override { return "status exception"; }
  const absl::Status& status() const { return status_; }

 private:
  absl::Status status_;
};

// A LanczosOperator in the shape Spectra's solvers expect (perform_op, and set_shift for the
// shift-invert modes, where the caller has already built the inverse for the one shift used).
class SpectraOp {
 public:
  using Scalar = double;
  SpectraOp(int64_t n, LanczosOperator op) : n_(n), op_(op) {}
  Eigen::Index rows() const { return n_; }
  Eigen::Index cols() const { return n_; }
  void set_shift(const Scalar&) {}
  void perform_op(const Scalar* x_in, Scalar* y_out) const {
    absl::Status status = op_(x_in, y_out);
    if (!status.ok()) throw StatusException(std::move(status));
  }

 private:
  int64_t n_;
  LanczosOperator op_;
};

// Runs `make_solver()`'s solver with the given selection rule and output order, translating
// everything Spectra can report or throw into a Status.
template <typename MakeSolver>
absl::StatusOr<LanczosResult> Run(MakeSolver make_solver, Spectra::SortRule selection,
                                  Spectra::SortRule order, const LanczosOptions& options) {
  try {
    auto solver = make_solver();
    solver.init();
    solver.compute(selection, options.max_iterations, options.tolerance, order);
    LanczosResult result;
    result.iterations = solver.num_iterations();
    result.operations = solver.num_operations();
    if (solver.info() == Spectra::CompInfo::NotConverging) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "%s: %d of %d eigenpairs not converged after %d Lanczos restarts (tolerance %g)",
          options.context, options.count - solver.eigenvalues().size(), options.count,
          options.max_iterations, options.tolerance));
    }
    if (solver.info() != Spectra::CompInfo::Successful) {
      return absl::InternalError(
          absl::StrFormat("%s: Spectra reported a numerical failure", options.context));
    }
    result.values = solver.eigenvalues();
    if (result.values.size() != options.count) {
      return absl::InternalError(absl::StrFormat("%s: Spectra returned %d eigenvalues, not %d",
                                                 options.context, result.values.size(),
                                                 options.count));
    }
    result.vectors = solver.eigenvectors();
    return result;
  } catch (const StatusException& e) {
    return e.status();
  } catch (const std::exception& e) {
    return absl::InternalError(
        absl::StrFormat("%s: Spectra failed: %s", options.context, e.what()));
  }
}

}  // namespace

absl::StatusOr<LanczosResult> LargestEigenpairs(int64_t n, LanczosOperator T,
                                                const LanczosOptions& options) {
  SpectraOp op(n, T);
  return Run(
      [&] { return Spectra::SymEigsSolver<SpectraOp>(op, options.count, options.subspace_size); },
      Spectra::SortRule::LargestAlge, Spectra::SortRule::LargestAlge, options);
}

absl::StatusOr<LanczosResult> ShiftInvertEigenpairs(int64_t n, LanczosOperator inverse,
                                                    double sigma, const LanczosOptions& options) {
  SpectraOp op(n, inverse);
  return Run(
      [&] {
        return Spectra::SymEigsShiftSolver<SpectraOp>(op, options.count, options.subspace_size,
                                                      sigma);
      },
      Spectra::SortRule::LargestMagn, Spectra::SortRule::SmallestAlge, options);
}

absl::StatusOr<LanczosResult> GeneralizedShiftInvertEigenpairs(int64_t n, LanczosOperator inverse,
                                                               LanczosOperator B, double sigma,
                                                               const LanczosOptions& options) {
  SpectraOp op(n, inverse);
  SpectraOp bop(n, B);
  return Run(
      [&] {
        return Spectra::SymGEigsShiftSolver<SpectraOp, SpectraOp, Spectra::GEigsMode::ShiftInvert>(
            op, bop, options.count, options.subspace_size, sigma);
      },
      Spectra::SortRule::LargestMagn, Spectra::SortRule::SmallestAlge, options);
}

}  // namespace fieldspace
