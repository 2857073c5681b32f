#include "server/served_basis.h"

#include <algorithm>
#include <iostream>
#include <iterator>
#include <utility>

#include "absl/strings/str_cat.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "server/curvature_alignment.h"

namespace fieldspace::server {

double OverallFraction(BuildStage stage, double fraction) {
  // Shares of a build's wall time measured with fieldspaced --threads 2 on 2 cores: vector
  // d = 500 on a 20,480-face icosphere (1.7 s), and vector d = 1000, tensor d = 600 and 4-field
  // d = 800 on the 49,152-face demo mesh (2.5-4.1 s); the local eigenproblems dominate (65-77 %).
  // Queued time is unknown in advance and counts as 0.
  static constexpr double kWeight[] = {
      0.0,    // kQueued
      0.02,   // kOperator
      0.015,  // kSampling
      0.025,  // kRegions
      0.71,   // kEigensolve
      0.08,   // kAssembly
      0.115,  // kPrecompute
      0.035,  // kSaving
  };
  const int s = static_cast<int>(stage);
  if (stage == BuildStage::kDone) return 1.0;
  if (s < 0 || s >= static_cast<int>(std::size(kWeight))) return 0.0;
  double before = 0, total = 0;
  for (int k = 0; k < static_cast<int>(std::size(kWeight)); ++k) {
    if (k < s) before += kWeight[k];
    total += kWeight[k];
  }
  const double f = std::clamp(fraction, 0.0, 1.0);
  return std::min(1.0, (before + kWeight[s] * f) / total);
}

namespace {

BuildStage StageFor(BasisPhase phase) {
  switch (phase) {
    case BasisPhase::kSampling:
      return BuildStage::kSampling;
    case BasisPhase::kRegions:
      return BuildStage::kRegions;
    case BasisPhase::kEigensolve:
      return BuildStage::kEigensolve;
    case BasisPhase::kAssembly:
      return BuildStage::kAssembly;
  }
  return BuildStage::kAssembly;
}

}  // namespace

absl::StatusOr<BuiltBasis> BuildBasisForKey(const TriangleMesh& mesh, const BasisKey& key,
                                            const Eigen::VectorXd& face_weights,
                                            const BuildContext& context) {
  if (context.progress) context.progress(BuildStage::kOperator, 0);
  ASSIGN_OR_RETURN(FieldOperator op, BuildFieldOperatorWithoutStiffness(mesh, key.field));
  BasisOptions options;
  options.params.dimension = key.dimension;
  options.params.sigma = key.sigma;
  options.params.fields_per_region = key.fields_per_region;
  options.params.seed = key.seed;
  options.params.face_weights = face_weights;
  options.kernel_columns = key.kernel_columns;
  options.threads = context.threads;
  options.cancel = context.cancel;
  if (context.progress) {
    options.progress = [&context](BasisPhase phase, double fraction) {
      context.progress(StageFor(phase), fraction);
    };
  }
  // S only if the build reads it (BuildBasisOfQuality); otherwise ServeBasis computes the reduced
  // system from the mesh, and neither step holds S.
  ASSIGN_OR_RETURN(Basis basis,
                   BuildBasisOfQuality(mesh, &op, options, key.quality, key.coarse_dimension));
  BuiltBasis out;
  out.basis = std::make_shared<const Basis>(std::move(basis));
  if (op.has_stiffness()) out.op = std::make_shared<const FieldOperator>(std::move(op));
  return out;
}

absl::StatusOr<std::shared_ptr<const ServedBasis>> ServeBasis(
    BasisRecord record, std::shared_ptr<const TriangleMesh> mesh,
    std::shared_ptr<const Basis> basis, const FieldOperator* op, const BuildContext& context,
    std::optional<ReducedMatrices> matrices, std::optional<LiftPlan> plan) {
  ReducedSystemOptions options;
  options.threads = context.threads;
  options.cancel = context.cancel;
  // The daemon serves U's rows from the LiftPlan: the caller's Basis (with U) is dropped once
  // the build has saved it.
  options.release_basis_rows = true;
  absl::StatusOr<std::shared_ptr<const ReducedSystem>> system;
  if (matrices.has_value()) {
    // Only M is needed then: S, whose assembly is most of a load's remaining time, is not.
    Eigen::VectorXd mass =
        op != nullptr ? op->mass : BuildFaceMass(*mesh, basis->type.dofs_per_face());
    const bool rows_in_plan = plan.has_value();
    system = rows_in_plan
                 ? ReducedSystem::Build(basis, *std::move(plan), std::move(mass),
                                        *std::move(matrices), options)
                 : ReducedSystem::Build(basis, std::move(mass), *std::move(matrices), options);
    if (!system.ok() && !absl::IsCancelled(system.status())) {
      std::cerr << "fieldspaced: the stored reduced matrices of basis " << record.id
                << " do not fit it (" << system.status().message() << "); computing them"
                << std::endl;
    }
    if (!system.ok() && rows_in_plan) return system.status();
  } else if (plan.has_value()) {
    return absl::InvalidArgumentError("ServeBasis: a basis read as a LiftPlan needs its matrices");
  }
  if (!system.ok()) {
    if (IsCancelled(context.cancel)) return absl::CancelledError("cancelled");
    if (context.progress) context.progress(BuildStage::kPrecompute, 0.5);
    // Without `op`, the mesh's operator: a vector field's S is then never assembled.
    system = op != nullptr ? ReducedSystem::Build(basis, *op, options)
                           : ReducedSystem::Build(basis, *mesh, options);
  }
  if (!system.ok()) return system.status();
  auto served = std::make_shared<ServedBasis>();
  served->record = std::move(record);
  served->mesh = std::move(mesh);
  served->basis = (*system)->shared_basis();  // without U's rows
  served->memory_bytes = served->basis->MemoryBytes() + (*system)->stats().memory_bytes;
  served->system = *std::move(system);
  served->energy_cache = std::make_shared<EnergyFactorCache>();
  served->alignment_cache = std::make_shared<AlignmentCache>();
  return std::shared_ptr<const ServedBasis>(std::move(served));
}

}  // namespace fieldspace::server
