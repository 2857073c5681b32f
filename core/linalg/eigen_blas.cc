// The six BLAS/LAPACK routines CHOLMOD calls (dgemm, dgemv, dsyrk, dtrsm, dtrsv, dpotrf),
// implemented with Eigen's blocked, vectorized kernels.
//
// Why: Debian's CHOLMOD links the system libblas, and the only one installed on the target
// (bookworm, no OpenBLAS/MKL) is the unblocked Fortran reference BLAS, which makes supernodal
// factorizations and solves several times slower. Defining these symbols in the program makes the
// dynamic linker bind CHOLMOD's calls to them (an executable's definitions come first in symbol
// lookup). Semantics follow the reference BLAS for every flag combination; CHOLMOD calls them from
// C without the Fortran hidden string-length arguments, which are therefore not declared.
// Single-threaded (Eigen's threading is disabled project-wide) and reentrant.

#include "core/linalg/eigen_blas.h"

#include <algorithm>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/Core"

namespace fieldspace::linalg_internal {

bool EigenBlasLinked() { return true; }

}  // namespace fieldspace::linalg_internal

namespace {

using Stride = Eigen::OuterStride<>;
using MatMap = Eigen::Map<Eigen::MatrixXd, 0, Stride>;
using ConstMatMap = Eigen::Map<const Eigen::MatrixXd, 0, Stride>;

bool Is(const char* flag, char c) { return (*flag | 0x20) == (c | 0x20); }
bool Transposed(const char* flag) { return !Is(flag, 'N'); }  // 'T' or 'C' (real data)

// A strided BLAS vector (inc may be negative: element i is at x[(n-1-i)*|inc|]) copied into a
// contiguous one, and back.
Eigen::VectorXd Gather(const double* x, int n, int inc) {
  Eigen::VectorXd v(n);
  const int step = std::abs(inc);
  for (int i = 0; i < n; ++i) v[i] = x[static_cast<int64_t>(inc > 0 ? i : n - 1 - i) * step];
  return v;
}
void Scatter(const Eigen::VectorXd& v, double* x, int inc) {
  const int n = static_cast<int>(v.size());
  const int step = std::abs(inc);
  for (int i = 0; i < n; ++i) x[static_cast<int64_t>(inc > 0 ? i : n - 1 - i) * step] = v[i];
}

template <int Mode, typename Tri, typename Rhs>
void SolveTriangular(const Tri& A, bool unit, Rhs&& x) {
  if (unit) {
    A.template triangularView<Mode | Eigen::UnitDiag>().solveInPlace(x);
  } else {
    A.template triangularView<Mode>().solveInPlace(x);
  }
}

}  // namespace

extern "C" {

// C = alpha op(A) op(B) + beta C, C m x n.
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc) {
  if (*m <= 0 || *n <= 0) return;
  MatMap C(c, *m, *n, Stride(*ldc));
  if (*beta == 0.0) {
    C.setZero();
  } else if (*beta != 1.0) {
    C *= *beta;
  }
  if (*k <= 0 || *alpha == 0.0) return;
  const bool ta = Transposed(transa), tb = Transposed(transb);
  ConstMatMap A(a, ta ? *k : *m, ta ? *m : *k, Stride(*lda));
  ConstMatMap B(b, tb ? *n : *k, tb ? *k : *n, Stride(*ldb));
  if (!ta && !tb) {
    C.noalias() += *alpha * A * B;
  } else if (ta && !tb) {
    C.noalias() += *alpha * A.transpose() * B;
  } else if (!ta && tb) {
    C.noalias() += *alpha * A * B.transpose();
  } else {
    C.noalias() += *alpha * A.transpose() * B.transpose();
  }
}

// y = alpha op(A) x + beta y, A m x n.
void dgemv_(const char* trans, const int* m, const int* n, const double* alpha, const double* a,
            const int* lda, const double* x, const int* incx, const double* beta, double* y,
            const int* incy) {
  if (*m <= 0 || *n <= 0) return;
  const bool t = Transposed(trans);
  const int lx = t ? *m : *n, ly = t ? *n : *m;
  ConstMatMap A(a, *m, *n, Stride(*lda));
  Eigen::VectorXd Y = *beta == 0.0 ? Eigen::VectorXd::Zero(ly) : Gather(y, ly, *incy);
  if (*beta != 0.0 && *beta != 1.0) Y *= *beta;
  if (*alpha != 0.0) {
    const Eigen::VectorXd X = Gather(x, lx, *incx);
    if (t) {
      Y.noalias() += *alpha * A.transpose() * X;
    } else {
      Y.noalias() += *alpha * A * X;
    }
  }
  Scatter(Y, y, *incy);
}

// Solves op(A) x = b in place, A n x n triangular.
void dtrsv_(const char* uplo, const char* trans, const char* diag, const int* n, const double* a,
            const int* lda, double* x, const int* incx) {
  if (*n <= 0) return;
  ConstMatMap A(a, *n, *n, Stride(*lda));
  Eigen::VectorXd X = Gather(x, *n, *incx);
  const bool lower = Is(uplo, 'L'), t = Transposed(trans), unit = Is(diag, 'U');
  // op(A) lower <=> (lower and not transposed) or (upper and transposed).
  if (lower && !t) {
    SolveTriangular<Eigen::Lower>(A, unit, X);
  } else if (lower && t) {
    SolveTriangular<Eigen::Upper>(A.transpose(), unit, X);
  } else if (!lower && !t) {
    SolveTriangular<Eigen::Upper>(A, unit, X);
  } else {
    SolveTriangular<Eigen::Lower>(A.transpose(), unit, X);
  }
  Scatter(X, x, *incx);
}

// Solves op(A) X = alpha B (side L) or X op(A) = alpha B (side R) in place; B m x n.
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb) {
  if (*m <= 0 || *n <= 0) return;
  MatMap B(b, *m, *n, Stride(*ldb));
  if (*alpha == 0.0) {
    B.setZero();
    return;
  }
  if (*alpha != 1.0) B *= *alpha;
  const bool left = Is(side, 'L');
  const int na = left ? *m : *n;
  ConstMatMap A(a, na, na, Stride(*lda));
  const bool lower = Is(uplo, 'L'), t = Transposed(transa), unit = Is(diag, 'U');
  auto solve = [&](auto&& T, auto mode) {
    constexpr int kMode = decltype(mode)::value;
    if (left) {
      if (unit) {
        T.template triangularView<kMode | Eigen::UnitDiag>()
            .template solveInPlace<Eigen::OnTheLeft>(B);
      } else {
        T.template triangularView<kMode>().template solveInPlace<Eigen::OnTheLeft>(B);
      }
    } else {
      if (unit) {
        T.template triangularView<kMode | Eigen::UnitDiag>()
            .template solveInPlace<Eigen::OnTheRight>(B);
      } else {
        T.template triangularView<kMode>().template solveInPlace<Eigen::OnTheRight>(B);
      }
    }
  };
  using LowerMode = std::integral_constant<int, Eigen::Lower>;
  using UpperMode = std::integral_constant<int, Eigen::Upper>;
  if (lower && !t) {
    solve(A, LowerMode());
  } else if (lower && t) {
    solve(A.transpose(), UpperMode());
  } else if (!lower && !t) {
    solve(A, UpperMode());
  } else {
    solve(A.transpose(), LowerMode());
  }
}

// C = alpha A A^T + beta C (trans N, A n x k) or alpha A^T A + beta C (trans T, A k x n), only the
// `uplo` triangle of C (n x n) referenced.
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* beta, double* c, const int* ldc) {
  if (*n <= 0) return;
  MatMap C(c, *n, *n, Stride(*ldc));
  const bool lower = Is(uplo, 'L'), t = Transposed(trans);
  if (lower) {
    if (*beta == 0.0) {
      C.triangularView<Eigen::Lower>().setZero();
    } else if (*beta != 1.0) {
      C.triangularView<Eigen::Lower>() *= *beta;
    }
  } else {
    if (*beta == 0.0) {
      C.triangularView<Eigen::Upper>().setZero();
    } else if (*beta != 1.0) {
      C.triangularView<Eigen::Upper>() *= *beta;
    }
  }
  if (*k <= 0 || *alpha == 0.0) return;
  ConstMatMap A(a, t ? *k : *n, t ? *n : *k, Stride(*lda));
  if (lower && !t) {
    C.selfadjointView<Eigen::Lower>().rankUpdate(A, *alpha);
  } else if (lower && t) {
    C.selfadjointView<Eigen::Lower>().rankUpdate(A.transpose(), *alpha);
  } else if (!lower && !t) {
    C.selfadjointView<Eigen::Upper>().rankUpdate(A, *alpha);
  } else {
    C.selfadjointView<Eigen::Upper>().rankUpdate(A.transpose(), *alpha);
  }
}

// In-place Cholesky of the `uplo` triangle of A (n x n): A = L L^T or U^T U. info = 0 on success,
// j > 0 when the leading minor of order j is not positive definite.
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info) {
  *info = 0;
  if (*n <= 0) return;
  MatMap A(a, *n, *n, Stride(*lda));
  const Eigen::Index failed = Is(uplo, 'L')
                                  ? Eigen::internal::llt_inplace<double, Eigen::Lower>::blocked(A)
                                  : Eigen::internal::llt_inplace<double, Eigen::Upper>::blocked(A);
  if (failed >= 0) *info = static_cast<int>(failed) + 1;
}

}  // extern "C"
