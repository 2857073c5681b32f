#ifndef FIELDSPACE_BENCH_CMD_SUBSPACE_H_
#define FIELDSPACE_BENCH_CMD_SUBSPACE_H_

// Helpers shared by the approx, eigen and design subcommands (defined in cmd_approx.cc).

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "bench/bench_util.h"
#include "core/basis/basis.h"
#include "core/mesh/triangle_mesh.h"
#include "core/operators/field_operator.h"
#include "core/subspace/problem.h"
#include "core/subspace/reduced_system.h"

namespace fieldspace::bench {

// Reads a mesh and scales it to unit total area (vertices * 1/sqrt(A)) before validating it, so
// that errors and weights are comparable across meshes.
absl::StatusOr<TriangleMesh> LoadUnitAreaMesh(const std::string& path);

// --quality: paper (default), low-modes or smooth (BasisQuality).
absl::StatusOr<BasisQuality> QualityFromArgs(const Args& args);
// --biharmonic exact|mixed (default mixed): the reduced solvers' BiharmonicForm.
absl::StatusOr<BiharmonicForm> BiharmonicFormFromArgs(const Args& args);

// BuildBasisOfQuality with --dim (required), --sigma (default 40), --seed (default 0),
// --coarse-dim (default 0: no coarse level; see StackBases), --quality (QualityFromArgs) and
// kernel columns unless --no-kernel-columns. S is assembled into `op` if it lacks S and the
// build reads it.
absl::StatusOr<std::shared_ptr<const Basis>> BuildBenchBasis(const TriangleMesh& mesh,
                                                             FieldOperator* op, const Args& args);

// What the eigen and design subcommands start from: the unit-area mesh of the first positional
// argument, its operator, the bench basis and its reduced system, with the two build times.
struct BenchSubspace {
  TriangleMesh mesh;
  FieldOperator op;
  std::shared_ptr<const Basis> basis;
  std::shared_ptr<const ReducedSystem> system;
  double basis_seconds = 0;
  double reduced_seconds = 0;
};
absl::StatusOr<BenchSubspace> LoadBenchSubspace(const Args& args, const FieldType& type);

}  // namespace fieldspace::bench

#endif  // FIELDSPACE_BENCH_CMD_SUBSPACE_H_
