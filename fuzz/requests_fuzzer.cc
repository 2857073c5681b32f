// proto -> core conversion of every request that carries numbers for core (server/proto_convert.h),
// followed by the core call the service makes with the result, on a small basis of the fixture.
// Input: byte 0 picks the request type, byte 1 the basis (vector, 2-field, tensor), the rest is
// the serialized request. Each case calls what FieldService (field_service.cc, chunk_writers.cc)
// calls for that RPC, minus the transport and the registry lookup (basis_id / mesh_id are
// ignored: the fixture's basis and mesh are used).

#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/common/status_macros.h"
#include "core/mesh/mesh_io.h"
#include "core/operators/curvature.h"
#include "core/subspace/model_problem.h"
#include "core/subspace/projection.h"
#include "core/subspace/smoothing.h"
#include "core/subspace/spectrum.h"
#include "fuzz/tiny_bases.h"
#include "server/data_root.h"
#include "server/proto_convert.h"

namespace fieldspace::fuzz {
namespace {

namespace v1 = ::fieldspace::v1;
using server::ServedBasis;

// LoadMesh's data root: a folder holding the fixture's mesh in each format and a subfolder.
const std::string& DataRoot() {
  static const std::string* root = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string dir = std::string(tmp ? tmp : "/tmp") + "/fieldspace-root-fuzz-XXXXXX";
    if (mkdtemp(dir.data()) == nullptr) std::abort();
    const std::string sub = dir + "/sub";
    if (mkdir(sub.c_str(), 0755) != 0) std::abort();
    for (const char* format : {"obj", "off", "ply"}) {
      std::FILE* f = std::fopen(absl::StrCat(sub, "/torus.", format).c_str(), "wb");
      if (f == nullptr) std::abort();
      const std::string text = TinyMeshFile(format);
      std::fwrite(text.data(), 1, text.size(), f);
      std::fclose(f);
    }
    static const std::string remove = dir;
    std::atexit([] { std::system(("rm -rf '" + remove + "'").c_str()); });
    return new std::string(dir);
  }();
  return *root;
}

template <typename Message>
bool Parse(Message* m, const uint8_t* data, size_t size) {
  return m->ParseFromArray(data, static_cast<int>(size));
}

// The lifted field and singularities a response may carry (Solve, Smooth, Align).
absl::Status Outputs(const ServedBasis& basis, const Eigen::VectorXd& x, bool return_field,
                     int encoding, bool singularities) {
  ASSIGN_OR_RETURN(FieldEncoding e, server::EncodingFromProto(encoding));
  Eigen::VectorXd dofs;
  if (return_field) {
    google::protobuf::RepeatedField<float> values;
    RETURN_IF_ERROR(server::LiftAllToValues(basis, x, e, &values, &dofs));
  }
  if (singularities && basis.basis->type.kind != FieldKind::kTensor) {
    if (dofs.size() == 0) {
      ASSIGN_OR_RETURN(dofs, Lift(*basis.system, x));
    }
    v1::SingularitiesResponse out;
    RETURN_IF_ERROR(server::SingularitiesToProto(basis, dofs, 0, &out));
  }
  return absl::OkStatus();
}

absl::Status Smooth(const ServedBasis& basis, const Eigen::VectorXd& X0,
                    const EnergyWeights& weights, absl::Span<const double> face_weights,
                    bool scale_free) {
  RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(weights));
  SmoothingOptions options;
  options.scale_free = scale_free;
  ASSIGN_OR_RETURN(SmoothingResult r,
                   SmoothReduced(*basis.system, X0, weights, face_weights, options));
  return server::CheckSolutionFinite(r.coefficients);
}

absl::Status Run(uint8_t type, const ServedBasis& basis, const uint8_t* data, size_t size) {
  switch (type % 10) {
    case 0: {
      v1::LoadMeshRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(ReadableFile file, server::OpenDataFile(DataRoot(), r.path()));
      ASSIGN_OR_RETURN(MeshReadResult parsed, ReadMeshFile(std::move(file), r.path()));
      return TriangleMesh::Create(std::move(parsed.arrays)).status();
    }
    case 1: {
      v1::BuildBasisRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      return server::BuildRequestFromProto(r).status();
    }
    case 2: {
      v1::ProjectRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(Eigen::VectorXd X, server::FieldFromProto(r.field(), basis));
      return Project(*basis.system, X).status();
    }
    case 3: {
      v1::SolveRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ModelProblem problem;
      problem.weights = server::WeightsFromProto(r.weights(), EnergyWeights{});
      problem.scale_free = !r.raw_weights();
      RETURN_IF_ERROR(ValidateWeightsWithoutDataTerm(problem.weights));
      for (int i = 0; i < r.constraints_size(); ++i) {
        ASSIGN_OR_RETURN(FieldConstraint c, server::ConstraintFromProto(basis, r.constraints(i),
                                                                        absl::StrCat("c ", i)));
        problem.constraints.push_back(std::move(c));
      }
      RETURN_IF_ERROR(server::EncodingFromProto(r.field_encoding()).status());
      ASSIGN_OR_RETURN(ReducedSolution result, SolveReducedModelProblem(*basis.system, problem));
      RETURN_IF_ERROR(server::CheckSolutionFinite(result.coefficients));
      return Outputs(basis, result.coefficients, r.return_field(), r.field_encoding(),
                     r.singularities());
    }
    case 4: {
      v1::LiftRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(Eigen::VectorXd x, server::CoefficientsFromProto(r.coefficients(), basis));
      ASSIGN_OR_RETURN(FieldEncoding e, server::EncodingFromProto(r.encoding()));
      RETURN_IF_ERROR(server::CheckFaces(r.faces(), basis.mesh->num_faces(), "lift"));
      google::protobuf::RepeatedField<float> values;
      if (r.faces().empty()) return server::LiftAllToValues(basis, x, e, &values);
      return server::LiftToValues(basis, x, r.faces(), e, &values);
    }
    case 5: {
      v1::EigenfieldsRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      if (r.count() < 1 || r.count() > basis.basis->dimension()) return absl::OkStatus();
      ReducedEigenOptions options;
      options.count = r.count();
      return ReducedEigenpairs(*basis.system, options).status();
    }
    case 6: {
      v1::CurvatureRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(FieldEncoding e, server::EncodingFromProto(r.encoding()));
      ShapeOperatorOptions options;
      ASSIGN_OR_RETURN(options.estimator, server::EstimatorFromProto(r.estimator()));
      ASSIGN_OR_RETURN(Eigen::VectorXd dofs, ComputeShapeOperator(*basis.mesh, options));
      if (r.principal()) RETURN_IF_ERROR(ComputePrincipalCurvatures(*basis.mesh, dofs).status());
      const int32_t nf = basis.mesh->num_faces();
      std::vector<int32_t> faces(nf);
      std::iota(faces.begin(), faces.end(), 0);
      std::vector<float> values(int64_t{nf} * ValuesPerFace(FieldType::Tensor(), e));
      return DofsToValues(*basis.mesh, FieldType::Tensor(), e, faces, dofs, absl::MakeSpan(values));
    }
    case 7: {
      v1::SingularitiesRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      if (basis.basis->type.kind == FieldKind::kTensor) return absl::OkStatus();
      const bool has_field = !r.field().values().empty();
      if (has_field == !r.coefficients().empty()) return absl::OkStatus();
      Eigen::VectorXd dofs;
      if (has_field) {
        ASSIGN_OR_RETURN(dofs, server::FieldFromProto(r.field(), basis));
      } else {
        ASSIGN_OR_RETURN(Eigen::VectorXd x, server::CoefficientsFromProto(r.coefficients(), basis));
        ASSIGN_OR_RETURN(dofs, Lift(*basis.system, x));
      }
      v1::SingularitiesResponse out;
      return server::SingularitiesToProto(basis, dofs, r.zero_tolerance(), &out);
    }
    case 8: {
      v1::SmoothRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(Eigen::VectorXd X0, server::FieldFromProto(r.field(), basis));
      return Smooth(basis, X0, server::WeightsFromProto(r.weights(), kDefaultSmoothingWeights),
                    r.face_weights(), r.scale_free());
    }
    default: {
      v1::AlignRequest r;
      if (!Parse(&r, data, size)) return absl::OkStatus();
      ASSIGN_OR_RETURN(CurvatureEstimator estimator, server::EstimatorFromProto(r.estimator()));
      ASSIGN_OR_RETURN(server::AlignmentTarget target,
                       server::CurvatureAlignmentTarget(basis, estimator));
      return Smooth(basis, target.dofs,
                    server::WeightsFromProto(r.weights(), kDefaultSmoothingWeights),
                    absl::MakeConstSpan(target.face_weights.data(), target.face_weights.size()),
                    /*scale_free=*/true);
    }
  }
}

}  // namespace
}  // namespace fieldspace::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 2) return 0;
  const auto& basis = fieldspace::fuzz::TinyBasis(data[1]);
  (void)fieldspace::fuzz::Run(data[0], *basis, data + 2, size - 2);
  return 0;
}
