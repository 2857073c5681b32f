#include "server/reflection_v1.h"

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/descriptor.pb.h"
#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "grpcpp/impl/server_builder_plugin.h"
#include "grpcpp/impl/server_initializer.h"

namespace fieldspace::server {
namespace {

namespace refl = ::grpc::reflection::v1;
using google::protobuf::DescriptorPool;
using google::protobuf::FileDescriptor;

class ReflectionV1Service final : public refl::ServerReflection::Service {
 public:
  // Called once the server knows its services (before it serves).
  void SetServices(std::vector<std::string> services) { services_ = std::move(services); }

  grpc::Status ServerReflectionInfo(
      grpc::ServerContext* /*context*/,
      grpc::ServerReaderWriter<refl::ServerReflectionResponse, refl::ServerReflectionRequest>*
          stream) override {
    refl::ServerReflectionRequest request;
    while (stream->Read(&request)) {
      refl::ServerReflectionResponse response;
      response.set_valid_host(request.host());
      *response.mutable_original_request() = request;
      if (absl::Status status = Answer(request, &response); !status.ok()) {
        response.mutable_error_response()->set_error_code(static_cast<int32_t>(status.code()));
        response.mutable_error_response()->set_error_message(std::string(status.message()));
      }
      if (!stream->Write(response)) break;
    }
    return grpc::Status::OK;
  }

 private:
  absl::Status Answer(const refl::ServerReflectionRequest& request,
                      refl::ServerReflectionResponse* response) const {
    const DescriptorPool* pool = DescriptorPool::generated_pool();
    switch (request.message_request_case()) {
      case refl::ServerReflectionRequest::kListServices:
        for (const std::string& name : services_) {
          response->mutable_list_services_response()->add_service()->set_name(name);
        }
        return absl::OkStatus();
      case refl::ServerReflectionRequest::kFileByFilename:
        return AddFile(pool->FindFileByName(request.file_by_filename()),
                       absl::StrCat("no file ", request.file_by_filename()), response);
      case refl::ServerReflectionRequest::kFileContainingSymbol:
        return AddFile(pool->FindFileContainingSymbol(request.file_containing_symbol()),
                       absl::StrCat("no symbol ", request.file_containing_symbol()), response);
      case refl::ServerReflectionRequest::kFileContainingExtension: {
        const refl::ExtensionRequest& ext = request.file_containing_extension();
        const google::protobuf::Descriptor* type =
            pool->FindMessageTypeByName(ext.containing_type());
        const google::protobuf::FieldDescriptor* field =
            type == nullptr ? nullptr : pool->FindExtensionByNumber(type, ext.extension_number());
        return AddFile(
            field == nullptr ? nullptr : field->file(),
            absl::StrCat("no extension ", ext.extension_number(), " of ", ext.containing_type()),
            response);
      }
      case refl::ServerReflectionRequest::kAllExtensionNumbersOfType: {
        const google::protobuf::Descriptor* type =
            pool->FindMessageTypeByName(request.all_extension_numbers_of_type());
        if (type == nullptr) {
          return absl::NotFoundError(
              absl::StrCat("no message type ", request.all_extension_numbers_of_type()));
        }
        std::vector<const google::protobuf::FieldDescriptor*> extensions;
        pool->FindAllExtensions(type, &extensions);
        refl::ExtensionNumberResponse* numbers = response->mutable_all_extension_numbers_response();
        numbers->set_base_type_name(type->full_name());
        for (const google::protobuf::FieldDescriptor* e : extensions) {
          numbers->add_extension_number(e->number());
        }
        return absl::OkStatus();
      }
      case refl::ServerReflectionRequest::MESSAGE_REQUEST_NOT_SET:
        break;
    }
    return absl::InvalidArgumentError("the request asks nothing (message_request is not set)");
  }

  // `file` and the files it imports, transitively, each once; NOT_FOUND `missing` without a file.
  static absl::Status AddFile(const FileDescriptor* file, const std::string& missing,
                              refl::ServerReflectionResponse* response) {
    if (file == nullptr) return absl::NotFoundError(missing);
    std::set<std::string> seen;
    std::vector<const FileDescriptor*> pending = {file};
    while (!pending.empty()) {
      const FileDescriptor* f = pending.back();
      pending.pop_back();
      if (!seen.insert(f->name()).second) continue;
      google::protobuf::FileDescriptorProto proto;
      f->CopyTo(&proto);
      proto.SerializeToString(
          response->mutable_file_descriptor_response()->add_file_descriptor_proto());
      for (int i = 0; i < f->dependency_count(); ++i) pending.push_back(f->dependency(i));
    }
    return absl::OkStatus();
  }

  std::vector<std::string> services_;
};

// Registers the service and hands it the server's service list, as gRPC's v1alpha plugin does.
class ReflectionV1Plugin final : public grpc::ServerBuilderPlugin {
 public:
  std::string name() override { return "fieldspace_reflection_v1"; }
  void InitServer(grpc::ServerInitializer* si) override { si->RegisterService(service_); }
  void Finish(grpc::ServerInitializer* si) override {
    service_->SetServices(*si->GetServiceList());
  }
  void ChangeArguments(const std::string& /*name*/, void* /*value*/) override {}
  bool has_sync_methods() const override { return true; }
  bool has_async_methods() const override { return false; }

 private:
  std::shared_ptr<ReflectionV1Service> service_ = std::make_shared<ReflectionV1Service>();
};

class ReflectionV1BuilderOption final : public grpc::ServerBuilderOption {
 public:
  void UpdateArguments(grpc::ChannelArguments* /*args*/) override {}
  void UpdatePlugins(std::vector<std::unique_ptr<grpc::ServerBuilderPlugin>>* plugins) override {
    plugins->push_back(std::make_unique<ReflectionV1Plugin>());
  }
};

}  // namespace

std::unique_ptr<grpc::ServerBuilderOption> ReflectionV1Option() {
  return std::make_unique<ReflectionV1BuilderOption>();
}

}  // namespace fieldspace::server
