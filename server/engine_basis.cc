// Basis construction and (de)serialization (core/operators, core/basis, core/basis/basis_io).

#include "absl/strings/str_cat.h"
#include "core/basis/basis.h"
#include "core/basis/basis_io.h"
#include "core/common/cancel.h"
#include "core/common/status_macros.h"
#include "core/operators/field_operator.h"
#include "server/engine.h"

namespace fieldspace::server {
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
  ASSIGN_OR_RETURN(FieldOperator op, BuildFieldOperator(mesh, key.field));
  if (IsCancelled(context.cancel)) {
    return absl::CancelledError("basis construction cancelled");
  }
  BasisOptions options;
  options.params.dimension = key.dimension;
  options.params.sigma = key.sigma;
  options.params.fields_per_region = key.fields_per_region;
  options.params.seed = key.seed;
  options.params.face_weights = face_weights;
  options.threads = context.threads;
  options.cancel = context.cancel;
  if (context.progress) {
    options.progress = [&context](BasisPhase phase, double fraction) {
      context.progress(StageFor(phase), fraction);
    };
  }
  ASSIGN_OR_RETURN(Basis basis, BuildTwoLevelBasis(mesh, op, options, key.coarse_dimension));
  BuiltBasis out;
  out.basis = std::make_shared<const Basis>(std::move(basis));
  out.op = std::make_shared<const FieldOperator>(std::move(op));
  return out;
}

absl::StatusOr<std::string> SerializeBasis(const Basis& basis, const std::string& mesh_id) {
  return EncodeBasis(basis, mesh_id);
}

absl::StatusOr<DeserializedBasis> DeserializeBasis(std::string_view bytes) {
  ASSIGN_OR_RETURN(fieldspace::LoadedBasis loaded, DecodeBasis(bytes));
  DeserializedBasis out;
  out.mesh_id = std::move(loaded.mesh_id);
  out.basis = std::make_shared<const Basis>(std::move(loaded.basis));
  return out;
}

}  // namespace fieldspace::server
