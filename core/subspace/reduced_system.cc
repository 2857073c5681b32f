#include "core/subspace/reduced_system.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/common/timing.h"
#include "core/linalg/sparse_checks.h"
#include "core/operators/vector_laplacian.h"
#include "core/subspace/subspace_util.h"
#include "oneapi/tbb/blocked_range.h"
#include "oneapi/tbb/enumerable_thread_specific.h"
#include "oneapi/tbb/parallel_for.h"
#include "oneapi/tbb/task_arena.h"

namespace fieldspace {
namespace {

// Per-thread state of the product pass. Rows of U are processed in groups of spatially close
// faces (rows sharing their dominant column): a group touches only a few hundred columns, so its
// contributions are summed in small dense local matrices that stay in cache, then added once to
// the thread's dense accumulators of the current band of output columns (column c - band_begin
// holds rows a <= c: only the upper triangle is accumulated).
struct ProductWorkspace {
  std::vector<double> s, b, m;  // band accumulators, width x d each
  // Pattern mode (ProductPass::pattern): the mass product on the pattern's positions instead.
  std::vector<double> pattern_values;
  bool outside_pattern = false;
  // Sparse accumulator for one row of S U.
  std::vector<double> spa;
  std::vector<char> mark;
  std::vector<std::pair<int32_t, double>> su_row;
  // The group's rows: U and S U entries (global columns, ascending), flattened.
  std::vector<int64_t> u_begin, su_begin;
  std::vector<int32_t> u_cols, su_cols;
  std::vector<double> u_vals, su_vals, row_mass;
  // Local numbering of the group's columns (ascending global order) and local accumulators,
  // column-major L x L (entry (la, lb) at lb * L + la, la <= lb).
  std::vector<int32_t> local_of;
  std::vector<int32_t> local_cols;
  std::vector<double> ls, lb, lm;
  BasisRowScratch row_scratch;
};

struct Entry {
  int32_t row, col;
  double s, b, m;
};

// What one product pass computes: U^T diag(row_mass) U always; with `S`, also U^T S U and
// (S U)^T diag(row_mass)^-1 (S U) (then row_mass must be positive).
struct ProductPass {
  const BasisMatrix* U = nullptr;
  // Instead of U, for the mass product only (S null): the rows of this system's basis
  // (ReducedSystem::BasisRowOf), also once it released U.
  const ReducedSystem* rows_of = nullptr;
  // Symmetric k x k, or null: mass product only. The S products read U (never rows_of).
  const Eigen::SparseMatrix<double>* S = nullptr;
  // Instead of S, for vector fields: S's rows computed from the mesh (never assembled).
  const VectorHodgeRows* hodge_rows = nullptr;
  const double* row_mass = nullptr;  // k values, >= 0 (> 0 with S)
  int64_t accumulator_budget_bytes = 0;
  const CancelFlag* cancel = nullptr;
  const std::function<void(double fraction)>* progress = nullptr;  // may be null
  // Mass product only (S null): accumulate onto the upper-triangle positions of this known
  // symmetric pattern (column-major, sorted rows) instead of dense band accumulators, so that
  // memory and the final scan are O(nnz(pattern)) per thread instead of O(d^2).
  const Eigen::SparseMatrix<double>* pattern = nullptr;
};

struct ProductOutput {
  // Without a pattern: the upper-triangle entries (row <= col) with a nonzero value in any
  // product, ordered by column and then row.
  std::vector<Entry> entries;
  // With a pattern: U^T diag(row_mass) U at the pattern's upper-triangle positions (0 below the
  // diagonal), and whether a nonzero fell outside the pattern (then pattern_values is incomplete).
  std::vector<double> pattern_values;
  bool outside_pattern = false;
};

// One parallel pass over the rows of U per band of output columns (one band in pattern mode):
// the work is O(nnz(U) * row nnz) (plus the rows of S for the S products), the memory that of
// the band accumulators (pattern mode: of the pattern's values, per thread). Returns false when
// cancelled.
bool ComputeProducts(const ProductPass& pass, ProductOutput* out) {
  const ReducedSystem* source = pass.rows_of;
  const Eigen::SparseMatrix<double>* S = pass.S;
  const VectorHodgeRows* hodge_rows = pass.hodge_rows;
  const bool with_s = S != nullptr || hodge_rows != nullptr;
  const double* row_mass = pass.row_mass;
  const int64_t k = source != nullptr ? source->dofs() : pass.U->rows();
  const int64_t d = source != nullptr ? source->dimension() : pass.U->cols();
  const auto row_of = [&](int64_t i, BasisRowScratch* scratch) {
    return source != nullptr ? source->BasisRowOf(i, scratch) : GetBasisRow(*pass.U, i);
  };
  const int products = with_s ? 3 : 1;
  const Eigen::SparseMatrix<double>* pattern = with_s ? nullptr : pass.pattern;
  const int64_t pattern_nnz = pattern != nullptr ? pattern->nonZeros() : 0;
  std::atomic<bool> cancelled{false};
  std::atomic<int64_t> work_done{0};
  // Output columns per band: d x d accumulators for all threads when they fit the budget.
  const int64_t threads = std::max(1, tbb::this_task_arena::max_concurrency());
  const int64_t band_width =
      pattern != nullptr
          ? d
          : std::clamp<int64_t>(pass.accumulator_budget_bytes / (products * 8 * d * threads), 1, d);
  // Groups: rows ordered by their dominant column (counting sort), split into chunks of at
  // most kMaxGroupRows. Rows without entries (faces no basis field covers) still have S U
  // entries through their neighbors; they form their own groups.
  constexpr int64_t kMaxGroupRows = 4096;
  std::vector<int32_t> key(k);
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, k, 8192),
                    [&](const tbb::blocked_range<int64_t>& r) {
                      BasisRowScratch scratch;
                      for (int64_t i = r.begin(); i < r.end(); ++i) {
                        const BasisRow u = row_of(i, &scratch);
                        int32_t best = static_cast<int32_t>(d);  // "no entry" bucket
                        float best_abs = -1;
                        for (int64_t q = 0; q < u.size; ++q) {
                          if (std::abs(u.vals[q]) > best_abs) {
                            best_abs = std::abs(u.vals[q]);
                            best = u.cols[q];
                          }
                        }
                        key[i] = best;
                      }
                    });
  std::vector<int64_t> bucket(d + 2, 0);
  for (int64_t i = 0; i < k; ++i) ++bucket[key[i] + 1];
  for (int64_t c = 0; c <= d; ++c) bucket[c + 1] += bucket[c];
  std::vector<int32_t> order(k);
  {
    std::vector<int64_t> fill(bucket.begin(), bucket.end() - 1);
    for (int64_t i = 0; i < k; ++i) order[fill[key[i]]++] = static_cast<int32_t>(i);
  }
  std::vector<int64_t> group_begin;
  // Without S, rows without entries contribute nothing: skip their bucket.
  const int64_t last_bucket = with_s ? d : d - 1;
  for (int64_t c = 0; c <= last_bucket; ++c) {
    for (int64_t g = bucket[c]; g < bucket[c + 1]; g += kMaxGroupRows) group_begin.push_back(g);
  }
  group_begin.push_back(bucket[last_bucket + 1]);
  std::vector<int32_t>().swap(key);
  const int64_t num_groups = static_cast<int64_t>(group_begin.size()) - 1;
  const int64_t num_bands = (d + band_width - 1) / band_width;
  const int64_t total_work = std::max<int64_t>(1, num_groups * num_bands);
  const int64_t report_every = std::max<int64_t>(1, total_work / 100);

  tbb::enumerable_thread_specific<ProductWorkspace> workspaces;
  for (int64_t band_begin = 0; band_begin < d && !cancelled.load(); band_begin += band_width) {
    const int64_t band_end = std::min(d, band_begin + band_width);
    const int64_t width = band_end - band_begin;
    for (ProductWorkspace& w : workspaces) {
      std::fill(w.s.begin(), w.s.end(), 0.0);
      std::fill(w.b.begin(), w.b.end(), 0.0);
      std::fill(w.m.begin(), w.m.end(), 0.0);
    }
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, num_groups, 1),
        [&](const tbb::blocked_range<int64_t>& range) {
          ProductWorkspace& w = workspaces.local();
          if (pattern != nullptr) {
            if (w.pattern_values.empty()) w.pattern_values.assign(pattern_nnz, 0.0);
          } else if (w.m.size() != static_cast<size_t>(width * d)) {
            if (with_s) {
              w.s.assign(width * d, 0.0);
              w.b.assign(width * d, 0.0);
            }
            w.m.assign(width * d, 0.0);
          }
          if (w.local_of.empty()) {
            if (with_s) {
              w.spa.assign(d, 0.0);
              w.mark.assign(d, 0);
            }
            w.local_of.assign(d, -1);
          }
          for (int64_t g = range.begin(); g < range.end(); ++g) {
            if (cancelled.load(std::memory_order_relaxed)) return;
            if (IsCancelled(pass.cancel)) {
              cancelled.store(true);
              return;
            }
            if (const int64_t done = work_done.fetch_add(1) + 1;
                pass.progress != nullptr && *pass.progress && done % report_every == 0) {
              (*pass.progress)(static_cast<double>(done) / static_cast<double>(total_work));
            }
            // Pass 1: the group's rows of U and S U, and the columns they touch.
            w.u_begin.assign(1, 0);
            w.su_begin.assign(1, 0);
            w.u_cols.clear();
            w.u_vals.clear();
            w.su_cols.clear();
            w.su_vals.clear();
            w.row_mass.clear();
            w.local_cols.clear();
            const auto touch = [&](int32_t c) {
              if (w.local_of[c] < 0) {
                w.local_of[c] = 0;
                w.local_cols.push_back(c);
              }
            };
            for (int64_t t = group_begin[g]; t < group_begin[g + 1]; ++t) {
              const int64_t i = order[t];
              const BasisRow u = row_of(i, &w.row_scratch);
              for (int64_t q = 0; q < u.size; ++q) {
                w.u_cols.push_back(u.cols[q]);
                w.u_vals.push_back(static_cast<double>(u.vals[q]));
                touch(u.cols[q]);
              }
              w.u_begin.push_back(static_cast<int64_t>(w.u_cols.size()));
              w.row_mass.push_back(row_mass[i]);
              if (!with_s) continue;
              // Row i of S U (S symmetric: row i = column i), S's entries in ascending j.
              w.su_row.clear();
              const auto add_su = [&](int64_t j, double sij) {
                const BasisRow uj = GetBasisRow(*pass.U, j);
                for (int64_t q = 0; q < uj.size; ++q) {
                  const int32_t c = uj.cols[q];
                  if (!w.mark[c]) {
                    w.mark[c] = 1;
                    w.spa[c] = 0.0;
                    w.su_row.emplace_back(c, 0.0);
                  }
                  w.spa[c] += sij * static_cast<double>(uj.vals[q]);
                }
              };
              if (hodge_rows != nullptr) {
                const int64_t c = i % 2;
                hodge_rows->ForEachBlock(static_cast<int32_t>(i / 2),
                                         [&](int32_t g, const double* block) {
                                           add_su(2 * int64_t{g}, block[2 * c]);
                                           add_su(2 * int64_t{g} + 1, block[2 * c + 1]);
                                         });
              } else {
                for (Eigen::SparseMatrix<double>::InnerIterator it(*S, i); it; ++it) {
                  add_su(it.row(), it.value());
                }
              }
              for (auto& [c, v] : w.su_row) {
                v = w.spa[c];
                w.mark[c] = 0;
              }
              std::sort(w.su_row.begin(), w.su_row.end());
              for (const auto& [c, v] : w.su_row) {
                w.su_cols.push_back(c);
                w.su_vals.push_back(v);
                touch(c);
              }
              w.su_begin.push_back(static_cast<int64_t>(w.su_cols.size()));
            }
            // Local numbering in ascending global order, so that a <= b iff la <= lb.
            std::sort(w.local_cols.begin(), w.local_cols.end());
            const int64_t L = static_cast<int64_t>(w.local_cols.size());
            for (int64_t l = 0; l < L; ++l) w.local_of[w.local_cols[l]] = static_cast<int32_t>(l);
            for (int32_t& c : w.u_cols) c = w.local_of[c];
            for (int32_t& c : w.su_cols) c = w.local_of[c];
            if (with_s) {
              w.ls.assign(L * L, 0.0);
              w.lb.assign(L * L, 0.0);
            }
            w.lm.assign(L * L, 0.0);
            // Pass 2: U^T S U: sum_i U_ia (S U)_ib; U^T B U: (S U)_ia (S U)_ib / m_i;
            // U^T M U: U_ia U_ib m_i (a <= b).
            const int64_t rows = static_cast<int64_t>(w.row_mass.size());
            for (int64_t t = 0; t < rows; ++t) {
              const int32_t* uc = w.u_cols.data() + w.u_begin[t];
              const double* uv = w.u_vals.data() + w.u_begin[t];
              const int64_t nu = w.u_begin[t + 1] - w.u_begin[t];
              const double mi = w.row_mass[t];
              if (with_s) {
                const int32_t* sc = w.su_cols.data() + w.su_begin[t];
                const double* sv = w.su_vals.data() + w.su_begin[t];
                const int64_t ns = w.su_begin[t + 1] - w.su_begin[t];
                const double inv_mi = 1.0 / mi;
                for (int64_t q = 0; q < ns; ++q) {
                  const int64_t cb = sc[q];
                  double* col_s = w.ls.data() + cb * L;
                  double* col_b = w.lb.data() + cb * L;
                  const double svq = sv[q];
                  for (int64_t p = 0; p < nu && uc[p] <= cb; ++p) col_s[uc[p]] += uv[p] * svq;
                  const double bv = svq * inv_mi;
                  for (int64_t p = 0; p <= q; ++p) col_b[sc[p]] += sv[p] * bv;
                }
              }
              if (mi == 0.0) continue;
              for (int64_t q = 0; q < nu; ++q) {
                double* col_m = w.lm.data() + static_cast<int64_t>(uc[q]) * L;
                const double mv = uv[q] * mi;
                for (int64_t p = 0; p <= q; ++p) col_m[uc[p]] += uv[p] * mv;
              }
            }
            if (pattern != nullptr) {
              // Add the local sums at the pattern's positions: column c's rows are sorted, and
              // so are the local rows (ascending global order), so one merge per column.
              const int* outer = pattern->outerIndexPtr();
              const int* inner = pattern->innerIndexPtr();
              for (int64_t lcol = 0; lcol < L; ++lcol) {
                const int64_t c = w.local_cols[lcol];
                const double* lm = w.lm.data() + lcol * L;
                int64_t q = outer[c];
                const int64_t end = outer[c + 1];
                for (int64_t lrow = 0; lrow <= lcol; ++lrow) {
                  if (lm[lrow] == 0.0) continue;
                  const int32_t a = w.local_cols[lrow];
                  while (q < end && inner[q] < a) ++q;
                  if (q < end && inner[q] == a) {
                    w.pattern_values[q] += lm[lrow];
                  } else {
                    w.outside_pattern = true;
                  }
                }
              }
              for (int32_t c : w.local_cols) w.local_of[c] = -1;
              continue;
            }
            // Add the local sums to the band accumulators.
            for (int64_t lcol = 0; lcol < L; ++lcol) {
              const int64_t c = w.local_cols[lcol];
              if (c < band_begin || c >= band_end) continue;
              const int64_t base = (c - band_begin) * d;
              const double* lm = w.lm.data() + lcol * L;
              if (with_s) {
                const double* ls = w.ls.data() + lcol * L;
                const double* lbv = w.lb.data() + lcol * L;
                for (int64_t lrow = 0; lrow <= lcol; ++lrow) {
                  const int64_t a = w.local_cols[lrow];
                  w.s[base + a] += ls[lrow];
                  w.b[base + a] += lbv[lrow];
                }
              }
              for (int64_t lrow = 0; lrow <= lcol; ++lrow) {
                w.m[base + w.local_cols[lrow]] += lm[lrow];
              }
            }
            for (int32_t c : w.local_cols) w.local_of[c] = -1;
          }
        });
    if (pattern != nullptr) {
      out->pattern_values.assign(pattern_nnz, 0.0);
      for (ProductWorkspace& w : workspaces) {
        if (w.pattern_values.empty()) continue;
        out->outside_pattern = out->outside_pattern || w.outside_pattern;
        tbb::parallel_for(tbb::blocked_range<int64_t>(0, pattern_nnz, 1 << 16),
                          [&](const tbb::blocked_range<int64_t>& r) {
                            for (int64_t t = r.begin(); t < r.end(); ++t) {
                              out->pattern_values[t] += w.pattern_values[t];
                            }
                          });
      }
      continue;
    }
    // Reduce the thread-local accumulators and keep the entries of this band.
    ProductWorkspace* total = nullptr;
    for (ProductWorkspace& w : workspaces) {
      if (w.m.size() != static_cast<size_t>(width * d)) continue;
      if (total == nullptr) {
        total = &w;
        continue;
      }
      tbb::parallel_for(tbb::blocked_range<int64_t>(0, width * d, 1 << 16),
                        [&](const tbb::blocked_range<int64_t>& r) {
                          for (int64_t t = r.begin(); t < r.end(); ++t) {
                            if (with_s) {
                              total->s[t] += w.s[t];
                              total->b[t] += w.b[t];
                            }
                            total->m[t] += w.m[t];
                          }
                        });
    }
    if (total == nullptr) continue;
    for (int64_t c = band_begin; c < band_end; ++c) {
      const int64_t base = (c - band_begin) * d;
      for (int64_t a = 0; a <= c; ++a) {
        const double sv = with_s ? total->s[base + a] : 0.0;
        const double bv = with_s ? total->b[base + a] : 0.0;
        const double mv = total->m[base + a];
        if (sv != 0.0 || bv != 0.0 || mv != 0.0) {
          out->entries.push_back({static_cast<int32_t>(a), static_cast<int32_t>(c), sv, bv, mv});
        }
      }
    }
  }
  return !cancelled.load();
}

}  // namespace

namespace {

// `basis` without U's nonzeros (U keeps its k x d dimensions), for a system that serves the rows
// from its LiftPlan. Copies only the per-column and per-face arrays.
Basis WithoutRows(const Basis& basis) {
  Basis out;
  out.type = basis.type;
  out.params = basis.params;
  out.radius = basis.radius;
  out.U.resize(basis.U.rows(), basis.U.cols());
  out.U.makeCompressed();
  out.sample_faces = basis.sample_faces;
  out.local_eigenvalues = basis.local_eigenvalues;
  out.coverage_radius = basis.coverage_radius;
  out.uncovered_faces = basis.uncovered_faces;
  out.kernel_columns = basis.kernel_columns;
  out.timings = basis.timings;
  out.stats = basis.stats;
  return out;
}

// The checks both Builds make before any work: the basis and the options.
absl::Status CheckBasisAndOptions(const Basis* basis, const ReducedSystemOptions& options) {
  if (basis == nullptr) return absl::InvalidArgumentError("ReducedSystem: no basis");
  const int64_t d = basis->U.cols();
  if (d < 1) return absl::InvalidArgumentError("ReducedSystem: basis has no columns");
  if (d >= (int64_t{1} << 31) / 2) {
    return absl::InvalidArgumentError("ReducedSystem: basis dimension too large");
  }
  if (basis->U.rows() % basis->type.dofs_per_face() != 0) {
    return absl::InvalidArgumentError(
        "ReducedSystem: DOF count is not a multiple of the DOFs per face");
  }
  if (options.threads < 0 || options.accumulator_budget_bytes <= 0) {
    return absl::InvalidArgumentError(
        "ReducedSystem: threads must be >= 0 and the "
        "accumulator budget > 0");
  }
  return absl::OkStatus();
}

// The product pass's: those, and the operator against the basis.
absl::Status CheckBuildInputs(const Basis* basis, const FieldOperator& op,
                              const ReducedSystemOptions& options) {
  RETURN_IF_ERROR(CheckBasisAndOptions(basis, options));
  const int64_t k = basis->U.rows();
  if (!(basis->type == op.type)) {
    return absl::InvalidArgumentError(absl::StrCat("ReducedSystem: basis is for ",
                                                   basis->type.ToString(), ", operator for ",
                                                   op.type.ToString()));
  }
  if (!op.has_stiffness()) {
    return absl::InvalidArgumentError(
        "ReducedSystem: the operator's S is not assembled (AssembleStiffness)");
  }
  if (k != op.dofs() || op.stiffness.rows() != k || op.stiffness.cols() != k) {
    return absl::InvalidArgumentError(absl::StrCat(
        "ReducedSystem: basis has ", k, " rows but the operator has ", op.dofs(), " DOFs and a ",
        op.stiffness.rows(), " x ", op.stiffness.cols(), " stiffness"));
  }
  return absl::OkStatus();
}

// Runs `build` in an arena of options.threads threads (when > 0) with threads reset to 0.
template <typename F>
absl::StatusOr<std::shared_ptr<const ReducedSystem>> InArena(const ReducedSystemOptions& options,
                                                             const F& build) {
  tbb::task_arena arena(options.threads);
  ReducedSystemOptions inner = options;
  inner.threads = 0;
  absl::StatusOr<std::shared_ptr<const ReducedSystem>> result;
  arena.execute([&] { result = build(inner); });
  return result;
}

// That `m` is the given reduced matrices' shared pattern (ReducedMatrices): d x d, compressed,
// rows ascending in every column, the diagonal present, symmetric; values finite.
absl::Status CheckReducedMatrices(const ReducedMatrices& m, int64_t d) {
  const Eigen::SparseMatrix<double>* all[3] = {&m.stiffness, &m.bilaplacian, &m.mass_matrix};
  for (const Eigen::SparseMatrix<double>* a : all) {
    if (a->rows() != d || a->cols() != d || !a->isCompressed()) {
      return absl::InvalidArgumentError(
          absl::StrCat("ReducedSystem: the given reduced matrices are not ", d, " x ", d,
                       " compressed matrices (", a->rows(), " x ", a->cols(), ")"));
    }
  }
  // Each matrix's column pointers against its own storage first (nonZeros() trusts them), then
  // one pattern for all three.
  const int64_t nnz = m.stiffness.data().size();
  for (const Eigen::SparseMatrix<double>* a : all) {
    const int* outer = a->outerIndexPtr();
    bool ok = a->data().size() == nnz && outer[0] == 0 && outer[d] == nnz;
    for (int64_t c = 0; ok && c < d; ++c) ok = outer[c + 1] >= outer[c];
    if (!ok) {
      return absl::InvalidArgumentError("ReducedSystem: the given pattern's columns are malformed");
    }
  }
  for (const Eigen::SparseMatrix<double>* a : {&m.bilaplacian, &m.mass_matrix}) {
    if (!std::equal(a->outerIndexPtr(), a->outerIndexPtr() + d + 1, m.stiffness.outerIndexPtr()) ||
        !std::equal(a->innerIndexPtr(), a->innerIndexPtr() + nnz, m.stiffness.innerIndexPtr())) {
      return absl::InvalidArgumentError(
          "ReducedSystem: the given reduced matrices do not share one pattern");
    }
  }
  const int* outer = m.stiffness.outerIndexPtr();
  const int* inner = m.stiffness.innerIndexPtr();
  for (int64_t c = 0; c < d; ++c) {
    bool diagonal = false;
    for (int64_t q = outer[c]; q < outer[c + 1]; ++q) {
      const int r = inner[q];
      if (r < 0 || r >= d || (q > outer[c] && r <= inner[q - 1])) {
        return absl::InvalidArgumentError(absl::StrCat(
            "ReducedSystem: column ", c, " of the given pattern has rows out of range or order"));
      }
      diagonal = diagonal || r == c;
    }
    if (!diagonal) {
      return absl::InvalidArgumentError(
          absl::StrCat("ReducedSystem: the given pattern lacks diagonal entry ", c));
    }
  }
  for (int64_t c = 0; c < d; ++c) {
    for (int64_t q = outer[c]; q < outer[c + 1]; ++q) {
      const int r = inner[q];
      if (!std::binary_search(inner + outer[r], inner + outer[r + 1], static_cast<int>(c))) {
        return absl::InvalidArgumentError("ReducedSystem: the given pattern is not symmetric");
      }
    }
  }
  for (const Eigen::SparseMatrix<double>* a : all) {
    for (int64_t q = 0; q < nnz; ++q) {
      if (!std::isfinite(a->valuePtr()[q])) {
        return absl::InvalidArgumentError(
            "ReducedSystem: the given reduced matrices are not finite");
      }
    }
  }
  return absl::OkStatus();
}

constexpr char kReducedMagic[8] = {'F', 'S', 'R', 'E', 'D', 'U', 'C', '\1'};
constexpr uint32_t kReducedVersion = 1;
constexpr size_t kReducedHeaderBytes = 32;

}  // namespace

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::Build(
    std::shared_ptr<const Basis> basis, const FieldOperator& op,
    const ReducedSystemOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  RETURN_IF_ERROR(CheckBuildInputs(basis.get(), op, options));
  if (options.threads > 0) {
    // Run everything (the parallel loops included) in an arena of that many threads.
    return InArena(options, [&](const ReducedSystemOptions& inner) {
      return Build(std::move(basis), op, inner);
    });
  }
  RETURN_IF_ERROR(CheckPositiveVector(op.mass, basis->U.rows(), "ReducedSystem: operator mass"));
  RETURN_IF_ERROR(CheckFiniteValues(op.stiffness, "ReducedSystem: operator stiffness"));
  RETURN_IF_ERROR(CheckBasisMatrix(basis->U, "ReducedSystem"));
  return FromProducts(std::move(basis), &op.stiffness, nullptr, op.mass, options, t_start);
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::Build(
    std::shared_ptr<const Basis> basis, const TriangleMesh& mesh,
    const ReducedSystemOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  RETURN_IF_ERROR(CheckBasisAndOptions(basis.get(), options));
  if (options.threads > 0) {
    return InArena(options, [&](const ReducedSystemOptions& inner) {
      return Build(std::move(basis), mesh, inner);
    });
  }
  if (basis->type.kind != FieldKind::kVector) {
    ASSIGN_OR_RETURN(const FieldOperator op, BuildFieldOperator(mesh, basis->type));
    return Build(std::move(basis), op, options);
  }
  const int64_t k = 2 * static_cast<int64_t>(mesh.num_faces());
  if (basis->U.rows() != k) {
    return absl::InvalidArgumentError(absl::StrCat("ReducedSystem: basis has ", basis->U.rows(),
                                                   " rows but the mesh has ", k, " DOFs"));
  }
  RETURN_IF_ERROR(CheckBasisMatrix(basis->U, "ReducedSystem"));
  ASSIGN_OR_RETURN(const VectorHodgeRows rows, VectorHodgeRows::Create(mesh));
  return FromProducts(std::move(basis), nullptr, &rows, BuildFaceMass(mesh, 2), options, t_start);
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::FromProducts(
    std::shared_ptr<const Basis> basis, const Eigen::SparseMatrix<double>* S,
    const VectorHodgeRows* hodge_rows, Eigen::VectorXd mass, const ReducedSystemOptions& options,
    std::chrono::steady_clock::time_point t_start) {
  const int64_t d = basis->U.cols();
  auto sys = std::shared_ptr<ReducedSystem>(new ReducedSystem());
  ProductPass pass;
  pass.U = &basis->U;
  pass.S = S;
  pass.hodge_rows = hodge_rows;
  pass.row_mass = mass.data();
  pass.accumulator_budget_bytes = options.accumulator_budget_bytes;
  pass.cancel = options.cancel;
  pass.progress = &options.progress;
  ProductOutput products;
  if (!ComputeProducts(pass, &products)) return absl::CancelledError("ReducedSystem: cancelled");
  std::vector<Entry> entries = std::move(products.entries);

  // All diagonal entries are stored (the factorization needs them), even an all-zero column's.
  {
    std::vector<char> has_diagonal(d, 0);
    for (const Entry& e : entries) {
      if (e.row == e.col) has_diagonal[e.row] = 1;
    }
    for (int64_t c = 0; c < d; ++c) {
      if (!has_diagonal[c]) {
        entries.push_back({static_cast<int32_t>(c), static_cast<int32_t>(c), 0.0, 0.0, 0.0});
      }
    }
  }
  // One symmetric pattern for all three matrices: triplets carry entry ids, then values are
  // filled position by position.
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(2 * entries.size());
  for (size_t t = 0; t < entries.size(); ++t) {
    const Entry& e = entries[t];
    triplets.emplace_back(e.row, e.col, static_cast<double>(t));
    if (e.row != e.col) triplets.emplace_back(e.col, e.row, static_cast<double>(t));
  }
  Eigen::SparseMatrix<double> ids(d, d);
  ids.setFromTriplets(triplets.begin(), triplets.end());
  ids.makeCompressed();
  std::vector<Eigen::Triplet<double>>().swap(triplets);
  sys->stiffness_ = ids;
  sys->bilaplacian_ = ids;
  sys->mass_matrix_ = std::move(ids);
  for (int64_t p = 0; p < sys->mass_matrix_.nonZeros(); ++p) {
    const Entry& e = entries[static_cast<size_t>(sys->mass_matrix_.valuePtr()[p])];
    sys->stiffness_.valuePtr()[p] = e.s;
    sys->bilaplacian_.valuePtr()[p] = e.b;
    sys->mass_matrix_.valuePtr()[p] = e.m;
  }
  std::vector<Entry>().swap(entries);
  sys->stats_.products_seconds = SecondsSince(t_start);
  return Complete(std::move(sys), std::move(basis), std::move(mass), options, t_start);
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::Build(
    std::shared_ptr<const Basis> basis, Eigen::VectorXd mass, ReducedMatrices matrices,
    const ReducedSystemOptions& options) {
  return FromMatrices(std::move(basis), std::nullopt, std::move(mass), std::move(matrices),
                      options);
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::Build(
    std::shared_ptr<const Basis> basis, LiftPlan plan, Eigen::VectorXd mass,
    ReducedMatrices matrices, const ReducedSystemOptions& options) {
  return FromMatrices(std::move(basis), std::move(plan), std::move(mass), std::move(matrices),
                      options);
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::FromMatrices(
    std::shared_ptr<const Basis> basis, std::optional<LiftPlan> plan, Eigen::VectorXd mass,
    ReducedMatrices matrices, const ReducedSystemOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  RETURN_IF_ERROR(CheckBasisAndOptions(basis.get(), options));
  if (plan.has_value()) {
    if (basis->U.nonZeros() != 0) {
      return absl::InvalidArgumentError("ReducedSystem: a basis with rows given with a LiftPlan");
    }
    if (plan->dofs_per_face() != basis->type.dofs_per_face() ||
        plan->num_faces() * plan->dofs_per_face() != basis->U.rows()) {
      return absl::InvalidArgumentError(
          absl::StrCat("ReducedSystem: a LiftPlan of ", plan->num_faces(), " faces of ",
                       plan->dofs_per_face(), " DOFs for a basis of ", basis->U.rows(), " rows"));
    }
  }
  const int64_t d = basis->U.cols();
  if (options.threads > 0) {
    return InArena(options, [&](const ReducedSystemOptions& inner) {
      return FromMatrices(std::move(basis), std::move(plan), std::move(mass), std::move(matrices),
                          inner);
    });
  }
  RETURN_IF_ERROR(CheckPositiveVector(mass, basis->U.rows(), "ReducedSystem: operator mass"));
  RETURN_IF_ERROR(CheckBasisMatrix(basis->U, "ReducedSystem"));
  RETURN_IF_ERROR(CheckReducedMatrices(matrices, d));
  auto sys = std::shared_ptr<ReducedSystem>(new ReducedSystem());
  sys->stiffness_ = std::move(matrices.stiffness);
  sys->bilaplacian_ = std::move(matrices.bilaplacian);
  sys->mass_matrix_ = std::move(matrices.mass_matrix);
  sys->stats_.products_given = true;
  return Complete(std::move(sys), std::move(basis), std::move(mass), options, t_start,
                  std::move(plan));
}

absl::StatusOr<std::shared_ptr<const ReducedSystem>> ReducedSystem::Complete(
    std::shared_ptr<ReducedSystem> sys, std::shared_ptr<const Basis> basis, Eigen::VectorXd mass,
    const ReducedSystemOptions& options, std::chrono::steady_clock::time_point t_start,
    std::optional<LiftPlan> plan) {
  const BasisMatrix& U = basis->U;
  const int64_t k = U.rows();
  const int64_t d = U.cols();
  sys->mass_ = std::move(mass);
  const int64_t nnz = sys->mass_matrix_.nonZeros();
  int64_t nnz_s = 0, nnz_b = 0, nnz_m = 0;
  for (int64_t p = 0; p < nnz; ++p) {
    nnz_s += sys->stiffness_.valuePtr()[p] != 0.0;
    nnz_b += sys->bilaplacian_.valuePtr()[p] != 0.0;
    nnz_m += sys->mass_matrix_.valuePtr()[p] != 0.0;
  }
  sys->stats_.stiffness_nonzeros = nnz_s;
  sys->stats_.bilaplacian_nonzeros = nnz_b;
  sys->stats_.mass_nonzeros = nnz_m;
  sys->stats_.pattern_nonzeros = nnz;

  const auto t_analysis = std::chrono::steady_clock::now();
  SupernodalAnalyzeOptions analyze_options;
  analyze_options.thorough = options.thorough_ordering;
  ASSIGN_OR_RETURN(sys->symbolic_, SupernodalSymbolic::Analyze(sys->mass_matrix_, analyze_options));
  sys->stats_.analysis_seconds = SecondsSince(t_analysis);
  sys->stats_.factor_nonzeros = sys->symbolic_->factor_nonzeros();
  sys->stats_.factor_flops = sys->symbolic_->flops();

  const auto t_mass = std::chrono::steady_clock::now();
  auto mass_factor = SupernodalFactor::Factorize(sys->symbolic_, sys->mass_matrix_);
  if (!mass_factor.ok()) {
    if (absl::IsFailedPrecondition(mass_factor.status())) {
      return absl::FailedPreconditionError(absl::StrCat(
          "ReducedSystem: U^T M U is not positive definite: the basis columns are linearly "
          "dependent or zero (",
          mass_factor.status().message(), ")"));
    }
    return mass_factor.status();
  }
  sys->mass_factor_ = std::make_unique<SupernodalFactor>(*std::move(mass_factor));
  sys->stats_.mass_factor_seconds = SecondsSince(t_mass);
  const bool plan_given = plan.has_value();
  sys->lift_plan_ = plan_given ? *std::move(plan) : LiftPlan::Build(U, basis->type.dofs_per_face());
  const int64_t pattern_bytes = 3 * (sys->stats_.pattern_nonzeros * 12 + (d + 1) * 4);
  sys->stats_.memory_bytes = pattern_bytes + sys->lift_plan_.memory_bytes() + k * 8 +
                             sys->symbolic_->memory_bytes() + sys->symbolic_->factor_nonzeros() * 8;
  if (plan_given) {  // the basis came without rows
    sys->basis_ = std::move(basis);
    sys->rows_released_ = true;
  } else if (options.release_basis_rows) {
    sys->basis_ = std::make_shared<const Basis>(WithoutRows(*basis));
    sys->rows_released_ = true;
  } else {
    sys->basis_ = std::move(basis);
  }
  sys->stats_.total_seconds = SecondsSince(t_start);
  return std::shared_ptr<const ReducedSystem>(std::move(sys));
}

std::string EncodeReducedMatrices(const ReducedSystem& system) {
  const Eigen::SparseMatrix<double>& pattern = system.mass_matrix();
  const int64_t d = pattern.cols();
  const int64_t nnz = pattern.nonZeros();
  std::string out(kReducedHeaderBytes, '\0');
  std::memcpy(out.data(), kReducedMagic, 8);
  const uint32_t version = kReducedVersion;
  std::memcpy(out.data() + 8, &version, 4);
  std::memcpy(out.data() + 16, &d, 8);
  std::memcpy(out.data() + 24, &nnz, 8);
  out.reserve(kReducedHeaderBytes + 4 * (d + 1) + 28 * nnz);
  const auto append = [&out](const void* data, size_t bytes) {
    out.append(static_cast<const char*>(data), bytes);
  };
  append(pattern.outerIndexPtr(), 4 * static_cast<size_t>(d + 1));
  append(pattern.innerIndexPtr(), 4 * static_cast<size_t>(nnz));
  append(system.stiffness().valuePtr(), 8 * static_cast<size_t>(nnz));
  append(system.bilaplacian().valuePtr(), 8 * static_cast<size_t>(nnz));
  append(system.mass_matrix().valuePtr(), 8 * static_cast<size_t>(nnz));
  return out;
}

absl::StatusOr<ReducedMatrices> DecodeReducedMatrices(std::string_view bytes) {
  if (bytes.size() < kReducedHeaderBytes || std::memcmp(bytes.data(), kReducedMagic, 8) != 0) {
    return absl::DataLossError("not a reduced-matrices payload (bad magic)");
  }
  uint32_t version = 0;
  int64_t d = 0, nnz = 0;
  std::memcpy(&version, bytes.data() + 8, 4);
  std::memcpy(&d, bytes.data() + 16, 8);
  std::memcpy(&nnz, bytes.data() + 24, 8);
  if (version != kReducedVersion) {
    return absl::DataLossError(
        absl::StrCat("unsupported reduced-matrices format version ", version));
  }
  if (d < 1 || d >= (int64_t{1} << 30) || nnz < d || nnz > std::numeric_limits<int32_t>::max() ||
      static_cast<uint64_t>(bytes.size()) != kReducedHeaderBytes +
                                                 4 * static_cast<uint64_t>(d + 1) +
                                                 28 * static_cast<uint64_t>(nnz)) {
    return absl::DataLossError(absl::StrCat("reduced matrices: d ", d, ", ", nnz,
                                            " nonzeros do not match the payload's ", bytes.size(),
                                            " bytes"));
  }
  ReducedMatrices m;
  const char* p = bytes.data() + kReducedHeaderBytes;
  Eigen::SparseMatrix<double>& first = m.stiffness;
  first.resize(d, d);
  first.resizeNonZeros(nnz);
  std::memcpy(first.outerIndexPtr(), p, 4 * static_cast<size_t>(d + 1));
  p += 4 * (d + 1);
  std::memcpy(first.innerIndexPtr(), p, 4 * static_cast<size_t>(nnz));
  p += 4 * nnz;
  m.bilaplacian = first;
  m.mass_matrix = first;
  for (Eigen::SparseMatrix<double>* a : {&m.stiffness, &m.bilaplacian, &m.mass_matrix}) {
    std::memcpy(a->valuePtr(), p, 8 * static_cast<size_t>(nnz));
    p += 8 * nnz;
  }
  return m;
}

absl::StatusOr<Eigen::SparseMatrix<double>> WeightedMassMatrix(
    const ReducedSystem& system, const Eigen::Ref<const Eigen::VectorXd>& dof_weights,
    const WeightedMassOptions& options) {
  const int64_t k = system.dofs();
  const int64_t d = system.dimension();
  if (dof_weights.size() != k) {
    return absl::InvalidArgumentError(
        absl::StrCat("WeightedMassMatrix: ", dof_weights.size(), " weights for ", k, " DOFs"));
  }
  if (options.accumulator_budget_bytes <= 0) {
    return absl::InvalidArgumentError("WeightedMassMatrix: the accumulator budget must be > 0");
  }
  for (int64_t i = 0; i < k; ++i) {
    if (!std::isfinite(dof_weights[i]) || dof_weights[i] < 0) {
      return absl::InvalidArgumentError(absl::StrCat("WeightedMassMatrix: weight of DOF ", i,
                                                     " is ", dof_weights[i],
                                                     "; must be finite and >= 0"));
    }
  }
  const Eigen::VectorXd row_mass = system.mass().cwiseProduct(dof_weights);
  Eigen::SparseMatrix<double> C = system.mass_matrix();
  ProductPass pass;
  pass.rows_of = &system;
  pass.row_mass = row_mass.data();
  pass.accumulator_budget_bytes = options.accumulator_budget_bytes;
  pass.cancel = options.cancel;
  pass.pattern = &C;
  ProductOutput products;
  if (!ComputeProducts(pass, &products)) {
    return absl::CancelledError("WeightedMassMatrix: cancelled");
  }
  if (products.outside_pattern) {
    // A nonzero where U^T S U, U^T B U and U^T M U all vanish (exact cancellation): compute the
    // entries instead and return the union of both patterns (the caller analyzes it separately).
    pass.pattern = nullptr;
    if (!ComputeProducts(pass, &products)) {
      return absl::CancelledError("WeightedMassMatrix: cancelled");
    }
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(static_cast<size_t>(C.nonZeros()) + 2 * products.entries.size());
    for (int64_t c = 0; c < d; ++c) {
      for (Eigen::SparseMatrix<double>::InnerIterator it(C, c); it; ++it) {
        triplets.emplace_back(it.row(), c, 0.0);
      }
    }
    for (const Entry& en : products.entries) {
      triplets.emplace_back(en.row, en.col, en.m);
      if (en.row != en.col) triplets.emplace_back(en.col, en.row, en.m);
    }
    Eigen::SparseMatrix<double> union_matrix(d, d);
    union_matrix.setFromTriplets(triplets.begin(), triplets.end());
    union_matrix.makeCompressed();
    return union_matrix;
  }
  // The upper triangle came from the pass; mirror it below the diagonal column by column (a
  // transpose with one cursor per column).
  const int* outer = C.outerIndexPtr();
  const int* inner = C.innerIndexPtr();
  double* values = C.valuePtr();
  std::copy(products.pattern_values.begin(), products.pattern_values.end(), values);
  std::vector<int64_t> cursor(outer, outer + d);
  for (int64_t c = 0; c < d; ++c) {
    for (int64_t q = outer[c]; q < outer[c + 1]; ++q) {
      const int64_t r = inner[q];
      if (r <= c) continue;
      // (r, c) below the diagonal mirrors (c, r) in column r; rows of column r are visited in
      // ascending order c as c grows.
      int64_t& t = cursor[r];
      while (inner[t] < c) ++t;
      values[q] = values[t];
    }
  }
  return C;
}

}  // namespace fieldspace
