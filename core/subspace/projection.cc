#include "core/subspace/projection.h"

#include <cmath>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/index_check.h"
#include "core/common/status_macros.h"
#include "core/subspace/subspace_util.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/combinable.h"
#include "oneapi/tbb/enumerable_thread_specific.h"
#include "oneapi/tbb/parallel_for.h"

namespace fieldspace {
namespace {

using RowMajorMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

absl::Status CheckCoefficients(const Basis& basis, const Eigen::Ref<const Eigen::VectorXd>& x,
                               const char* what) {
  if (x.size() != basis.U.cols()) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": expected ", basis.U.cols(), " coefficients, got ", x.size()));
  }
  if (!x.allFinite()) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": coefficients are not finite"));
  }
  return absl::OkStatus();
}

absl::Status CheckFields(const ReducedSystem& system,
                         const Eigen::Ref<const Eigen::MatrixXd>& fields, const char* what) {
  if (fields.rows() != system.dofs()) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": a field has ", system.dofs(), " values (DOFs), got ", fields.rows()));
  }
  if (!fields.allFinite()) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": field values are not finite"));
  }
  return absl::OkStatus();
}

// The lifts that read U itself (those taking a Basis): a served system's basis has no rows left
// (ReducedSystemOptions::release_basis_rows), and its lifts go through the system's LiftPlan.
absl::Status CheckRows(const Basis& basis, const char* what) {
  if (basis.U.nonZeros() == 0 && basis.U.rows() > 0) {
    return absl::FailedPreconditionError(
        absl::StrCat(what,
                     ": the basis has no rows in memory (its ReducedSystem released them); "
                     "lift through the ReducedSystem"));
  }
  return absl::OkStatus();
}

absl::Status CancelledError(absl::string_view what) {
  return absl::CancelledError(absl::StrCat(what, ": cancelled"));
}

// sum_j U_ij x_j for one row.
inline double RowDot(const BasisRow& row, const double* x) {
  double v = 0;
  for (int64_t q = 0; q < row.size; ++q) v += static_cast<double>(row.vals[q]) * x[row.cols[q]];
  return v;
}

}  // namespace

absl::StatusOr<Eigen::MatrixXd> MassWeightedProducts(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::MatrixXd>& fields,
    const CancelFlag* cancel) {
  RETURN_IF_ERROR(CheckFields(system, fields, "MassWeightedProducts"));
  const int64_t d = system.dimension();
  const int64_t m = fields.cols();
  const Eigen::VectorXd& mass = system.mass();
  tbb::enumerable_thread_specific<RowMajorMatrix> partial(
      [&] { return RowMajorMatrix::Zero(d, m).eval(); });
  if (system.basis_rows_released()) {
    // Face by face through the LiftPlan: each entry's p values against the face's p weighted rows.
    const LiftPlan& plan = system.lift_plan();
    const int64_t p = system.dofs_per_face();
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, system.num_faces(), 2048),
                      [&](const tbb::blocked_range<int64_t>& r) {
                        if (IsCancelled(cancel)) return;
                        RowMajorMatrix& acc = partial.local();
                        RowMajorMatrix w(p, m);  // the face's rows of M X
                        for (int64_t f = r.begin(); f < r.end(); ++f) {
                          for (int64_t c = 0; c < p; ++c) {
                            w.row(c) = mass[f * p + c] * fields.row(f * p + c);
                          }
                          // Plain sums: Eigen's row operations on p x m blocks cost 4x here.
                          plan.ForEachEntry(f, [&](int col, const float* v) {
                            double* a = acc.data() + static_cast<int64_t>(col) * m;
                            for (int64_t j = 0; j < m; ++j) {
                              double sum = 0;
                              for (int64_t c = 0; c < p; ++c) sum += v[c] * w(c, j);
                              a[j] += sum;
                            }
                          });
                        }
                      });
  } else {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, system.dofs(), 4096),
                      [&](const tbb::blocked_range<int64_t>& r) {
                        if (IsCancelled(cancel)) return;
                        RowMajorMatrix& acc = partial.local();
                        Eigen::RowVectorXd w(m);
                        for (int64_t i = r.begin(); i < r.end(); ++i) {
                          const BasisRow row = GetBasisRow(system.basis().U, i);
                          if (row.size == 0) continue;
                          w = mass[i] * fields.row(i);
                          for (int64_t q = 0; q < row.size; ++q) {
                            acc.row(row.cols[q]) += static_cast<double>(row.vals[q]) * w;
                          }
                        }
                      });
  }
  if (IsCancelled(cancel)) return CancelledError("MassWeightedProducts");
  Eigen::MatrixXd result = Eigen::MatrixXd::Zero(d, m);
  for (const RowMajorMatrix& acc : partial) result += acc;
  return result;
}

absl::StatusOr<Eigen::VectorXd> RelativeResiduals(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::MatrixXd>& fields,
    const Eigen::Ref<const Eigen::MatrixXd>& coefficients, const CancelFlag* cancel) {
  RETURN_IF_ERROR(CheckFields(system, fields, "RelativeResiduals"));
  if (coefficients.rows() != system.dimension() || coefficients.cols() != fields.cols()) {
    return absl::InvalidArgumentError(
        absl::StrCat("RelativeResiduals: coefficients must be ", system.dimension(), " x ",
                     fields.cols(), ", got ", coefficients.rows(), " x ", coefficients.cols()));
  }
  const int64_t m = fields.cols();
  // Row-major coefficients: U_i x for all m columns reads contiguous rows of x.
  const RowMajorMatrix x = coefficients;
  const Eigen::VectorXd& mass = system.mass();
  struct Sums {
    Eigen::VectorXd residual, norm;
  };
  tbb::combinable<Sums> sums([&] {
    return Sums{Eigen::VectorXd::Zero(m), Eigen::VectorXd::Zero(m)};
  });
  if (system.basis_rows_released()) {
    // Face by face through the LiftPlan's own lift of a face, one field after the other.
    const Eigen::MatrixXd columns = coefficients;  // each field's coefficients contiguous
    const LiftPlan& plan = system.lift_plan();
    const int64_t p = system.dofs_per_face();
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, system.num_faces(), 2048),
                      [&](const tbb::blocked_range<int64_t>& r) {
                        if (IsCancelled(cancel)) return;
                        Sums& s = sums.local();
                        double lifted[8];  // p <= 3
                        for (int64_t j = 0; j < m; ++j) {
                          double residual = 0, norm = 0;
                          for (int64_t f = r.begin(); f < r.end(); ++f) {
                            plan.LiftFace(columns.col(j).data(), f, lifted);
                            for (int64_t c = 0; c < p; ++c) {
                              const double mi = mass[f * p + c];
                              const double fi = fields(f * p + c, j);
                              residual += mi * (fi - lifted[c]) * (fi - lifted[c]);
                              norm += mi * fi * fi;
                            }
                          }
                          s.residual[j] += residual;
                          s.norm[j] += norm;
                        }
                      });
  } else {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, system.dofs(), 4096),
                      [&](const tbb::blocked_range<int64_t>& r) {
                        if (IsCancelled(cancel)) return;
                        Sums& s = sums.local();
                        Eigen::RowVectorXd v(m);
                        for (int64_t i = r.begin(); i < r.end(); ++i) {
                          const BasisRow row = GetBasisRow(system.basis().U, i);
                          v.setZero();
                          for (int64_t q = 0; q < row.size; ++q) {
                            v += static_cast<double>(row.vals[q]) * x.row(row.cols[q]);
                          }
                          const double mi = mass[i];
                          s.residual += mi * (fields.row(i) - v).cwiseAbs2().transpose();
                          s.norm += mi * fields.row(i).cwiseAbs2().transpose();
                        }
                      });
  }
  if (IsCancelled(cancel)) return CancelledError("RelativeResiduals");
  Sums total{Eigen::VectorXd::Zero(m), Eigen::VectorXd::Zero(m)};
  sums.combine_each([&](const Sums& s) {
    total.residual += s.residual;
    total.norm += s.norm;
  });
  Eigen::VectorXd result(m);
  for (int64_t c = 0; c < m; ++c) {
    result[c] = total.norm[c] > 0 ? std::sqrt(total.residual[c] / total.norm[c]) : 0.0;
  }
  return result;
}

absl::StatusOr<ProjectionBatch> ProjectMany(const ReducedSystem& system,
                                            const Eigen::Ref<const Eigen::MatrixXd>& fields,
                                            const CancelFlag* cancel) {
  ASSIGN_OR_RETURN(Eigen::MatrixXd rhs, MassWeightedProducts(system, fields, cancel));
  system.mass_factor().SolveInPlace(rhs);
  ProjectionBatch batch;
  ASSIGN_OR_RETURN(batch.relative_errors, RelativeResiduals(system, fields, rhs, cancel));
  batch.coefficients = std::move(rhs);
  return batch;
}

absl::StatusOr<ProjectionResult> Project(const ReducedSystem& system,
                                         const Eigen::Ref<const Eigen::VectorXd>& field,
                                         const CancelFlag* cancel) {
  ASSIGN_OR_RETURN(ProjectionBatch batch, ProjectMany(system, field, cancel));
  ProjectionResult result;
  result.coefficients = batch.coefficients.col(0);
  result.relative_error = batch.relative_errors[0];
  return result;
}

absl::Status LiftInto(const Basis& basis, const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                      absl::Span<double> out) {
  RETURN_IF_ERROR(CheckCoefficients(basis, coefficients, "Lift"));
  RETURN_IF_ERROR(CheckRows(basis, "Lift"));
  const BasisMatrix& U = basis.U;
  if (static_cast<int64_t>(out.size()) != U.rows()) {
    return absl::InvalidArgumentError(
        absl::StrCat("Lift: output has ", out.size(), " values, expected ", U.rows()));
  }
  const Eigen::VectorXd x = coefficients;  // contiguous copy (d values)
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, U.rows(), 8192),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      for (int64_t i = r.begin(); i < r.end(); ++i) {
                        out[i] = RowDot(GetBasisRow(U, i), x.data());
                      }
                    });
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> Lift(const Basis& basis,
                                     const Eigen::Ref<const Eigen::VectorXd>& coefficients) {
  Eigen::VectorXd out(basis.U.rows());
  RETURN_IF_ERROR(LiftInto(basis, coefficients, absl::MakeSpan(out.data(), out.size())));
  return out;
}

absl::Status LiftFacesInto(const Basis& basis,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<const int32_t> faces, absl::Span<double> out) {
  RETURN_IF_ERROR(CheckCoefficients(basis, coefficients, "LiftFaces"));
  RETURN_IF_ERROR(CheckRows(basis, "LiftFaces"));
  const BasisMatrix& U = basis.U;
  const int64_t p = basis.type.dofs_per_face();
  const int64_t num_faces = U.rows() / p;
  if (static_cast<int64_t>(out.size()) != static_cast<int64_t>(faces.size()) * p) {
    return absl::InvalidArgumentError(
        absl::StrCat("LiftFaces: output has ", out.size(), " values, expected ", faces.size() * p));
  }
  RETURN_IF_ERROR(CheckFaces(faces, num_faces, "LiftFaces"));
  const Eigen::VectorXd x = coefficients;
  tbb::parallel_for(tbb::blocked_range<size_t>(0, faces.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t t = r.begin(); t < r.end(); ++t) {
                        for (int64_t c = 0; c < p; ++c) {
                          out[t * p + c] = RowDot(GetBasisRow(U, faces[t] * p + c), x.data());
                        }
                      }
                    });
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> LiftFaces(const Basis& basis,
                                          const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                                          absl::Span<const int32_t> faces) {
  Eigen::VectorXd out(static_cast<int64_t>(faces.size()) * basis.type.dofs_per_face());
  RETURN_IF_ERROR(
      LiftFacesInto(basis, coefficients, faces, absl::MakeSpan(out.data(), out.size())));
  return out;
}

namespace {

// The checks of an all-faces lift into `out_size` values through the system's plan.
absl::Status CheckLiftAll(const ReducedSystem& system,
                          const Eigen::Ref<const Eigen::VectorXd>& coefficients, size_t out_size) {
  const Basis& basis = system.basis();
  RETURN_IF_ERROR(CheckCoefficients(basis, coefficients, "Lift"));
  if (static_cast<int64_t>(out_size) != basis.U.rows()) {
    return absl::InvalidArgumentError(
        absl::StrCat("Lift: output has ", out_size, " values, expected ", basis.U.rows()));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status LiftInto(const ReducedSystem& system,
                      const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                      absl::Span<double> out) {
  RETURN_IF_ERROR(CheckLiftAll(system, coefficients, out.size()));
  const Eigen::VectorXd x = coefficients;
  system.lift_plan().LiftAll(x.data(), out.data());
  return absl::OkStatus();
}

absl::Status LiftIntoFloat(const ReducedSystem& system,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<float> out) {
  RETURN_IF_ERROR(CheckLiftAll(system, coefficients, out.size()));
  const Eigen::VectorXd x = coefficients;
  if (!system.lift_plan().LiftAllToFloat(x.data(), out.data())) {
    return absl::InvalidArgumentError(kFloatOverflowMessage);
  }
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> Lift(const ReducedSystem& system,
                                     const Eigen::Ref<const Eigen::VectorXd>& coefficients) {
  Eigen::VectorXd out(system.dofs());
  RETURN_IF_ERROR(LiftInto(system, coefficients, absl::MakeSpan(out.data(), out.size())));
  return out;
}

absl::Status LiftFacesInto(const ReducedSystem& system,
                           const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                           absl::Span<const int32_t> faces, absl::Span<double> out) {
  const Basis& basis = system.basis();
  RETURN_IF_ERROR(CheckCoefficients(basis, coefficients, "LiftFaces"));
  const int64_t p = system.dofs_per_face();
  if (static_cast<int64_t>(out.size()) != static_cast<int64_t>(faces.size()) * p) {
    return absl::InvalidArgumentError(
        absl::StrCat("LiftFaces: output has ", out.size(), " values, expected ", faces.size() * p));
  }
  RETURN_IF_ERROR(CheckFaces(faces, system.num_faces(), "LiftFaces"));
  const Eigen::VectorXd x = coefficients;
  const LiftPlan& plan = system.lift_plan();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, faces.size(), 4096),
                    [&](const tbb::blocked_range<size_t>& r) {
                      for (size_t t = r.begin(); t < r.end(); ++t) {
                        plan.LiftFace(x.data(), faces[t], out.data() + t * p);
                      }
                    });
  return absl::OkStatus();
}

absl::StatusOr<Eigen::VectorXd> LiftFaces(const ReducedSystem& system,
                                          const Eigen::Ref<const Eigen::VectorXd>& coefficients,
                                          absl::Span<const int32_t> faces) {
  Eigen::VectorXd out(static_cast<int64_t>(faces.size()) * system.dofs_per_face());
  RETURN_IF_ERROR(
      LiftFacesInto(system, coefficients, faces, absl::MakeSpan(out.data(), out.size())));
  return out;
}

}  // namespace fieldspace
