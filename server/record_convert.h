#ifndef FIELDSPACE_SERVER_RECORD_CONVERT_H_
#define FIELDSPACE_SERVER_RECORD_CONVERT_H_

// The registry's records and build states as fieldspace.v1 messages, and a BuildBasisRequest as
// the registry's BuildRequest (the conversions that need the registry's types; the rest is
// proto_convert.h).

#include "absl/status/statusor.h"
#include "fieldspace/v1/fieldspace.pb.h"
#include "server/registry.h"

namespace fieldspace::server {

namespace v1 = ::fieldspace::v1;

v1::BuildPhase PhaseToProto(BuildStage stage);

void MeshInfoFromRecord(const MeshRecord& r, bool loaded, v1::MeshInfo* p);
void BasisInfoFromStatus(const BasisStatus& s, v1::BasisInfo* p);
void BasisInfoFromRecord(const BasisRecord& r, v1::BasisInfo* p);

// The build a BuildBasisRequest asks for (validated further by Registry::StartBuild).
absl::StatusOr<BuildRequest> BuildRequestFromProto(const v1::BuildBasisRequest& p);

}  // namespace fieldspace::server

#endif  // FIELDSPACE_SERVER_RECORD_CONVERT_H_
