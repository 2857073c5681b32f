// Included by Eigen inside `class Eigen::SparseMatrix` (EIGEN_SPARSEMATRIX_PLUGIN, defined for
// every target that links fieldspace_core, core/CMakeLists.txt); never include it directly.
//
// Eigen 3.4's SparseMatrix has no move constructor and no move assignment (Eigen's later
// versions have both, as below), so moving one copied it: every `return basis;` into a
// StatusOr<Basis>, every FieldOperator moved into the daemon's cache. On a 1.38M-face vector
// basis that is a second U of 595 MB at the build's peak. A moved-from matrix is empty (0 x 0)
// or holds what the target held before (the assignment swaps).

#if !EIGEN_VERSION_AT_LEAST(3, 4, 90)
/** Takes over other's arrays; other is left 0 x 0. */
inline SparseMatrix(SparseMatrix&& other) noexcept : SparseMatrix() { this->swap(other); }

/** Swaps with other, which frees the arrays this held when it is destroyed. */
inline SparseMatrix& operator=(SparseMatrix&& other) noexcept {
  this->swap(other);
  return *this;
}
#endif
