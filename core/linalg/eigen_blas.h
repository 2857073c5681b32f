#ifndef FIELDSPACE_CORE_LINALG_EIGEN_BLAS_H_
#define FIELDSPACE_CORE_LINALG_EIGEN_BLAS_H_

// Internal to core/linalg: Eigen implementations of the BLAS/LAPACK routines CHOLMOD calls, which
// replace the system's reference BLAS for CHOLMOD (see eigen_blas.cc). Declared here for tests.

extern "C" {
void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
            const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
            const double* beta, double* c, const int* ldc);
void dgemv_(const char* trans, const int* m, const int* n, const double* alpha, const double* a,
            const int* lda, const double* x, const int* incx, const double* beta, double* y,
            const int* incy);
void dtrsv_(const char* uplo, const char* trans, const char* diag, const int* n, const double* a,
            const int* lda, double* x, const int* incx);
void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
            const int* n, const double* alpha, const double* a, const int* lda, double* b,
            const int* ldb);
void dsyrk_(const char* uplo, const char* trans, const int* n, const int* k, const double* alpha,
            const double* a, const int* lda, const double* beta, double* c, const int* ldc);
void dpotrf_(const char* uplo, const int* n, double* a, const int* lda, int* info);
}

namespace fieldspace::linalg_internal {

// Referenced by the Cholesky wrapper so the linker keeps eigen_blas.o (and with it the symbols
// CHOLMOD binds to) in every program that factorizes.
bool EigenBlasLinked();

}  // namespace fieldspace::linalg_internal

#endif  // FIELDSPACE_CORE_LINALG_EIGEN_BLAS_H_
