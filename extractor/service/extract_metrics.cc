#include "extractor/service/extract_metrics.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/proto_buffer_reader.h>

#include <memory>

#include "tpr/v1/extractor.pb.h"

namespace tpr::extractor {
namespace {

// The bytes of the `data` field (the mesh chunk) in one serialized
// tpr.v1.ExtractRequest, read from its wire form without copying the chunk
// (the extractor parses the message itself). 0 for bytes that do not parse.
size_t UploadBytes(grpc::ByteBuffer* raw) {
  using google::protobuf::internal::WireFormatLite;
  grpc::ProtoBufferReader reader(raw);
  google::protobuf::io::CodedInputStream in(&reader);
  const uint32_t data_tag =
      WireFormatLite::MakeTag(v1::ExtractRequest::kDataFieldNumber,
                              WireFormatLite::WIRETYPE_LENGTH_DELIMITED);
  size_t total = 0;
  while (const uint32_t tag = in.ReadTag()) {
    if (tag == data_tag) {
      uint32_t length = 0;
      if (!in.ReadVarint32(&length) || !in.Skip(static_cast<int>(length)))
        return 0;
      total += length;
    } else if (!WireFormatLite::SkipField(&in, tag)) {
      return 0;
    }
  }
  return total;
}

class ExtractObserver final : public common::MessageObserver {
 public:
  ExtractObserver(prometheus::Family<prometheus::Histogram>* stage,
                  prometheus::Histogram* mesh_bytes)
      : stage_(stage), mesh_bytes_(mesh_bytes) {}

  // The extractor reads its upload as raw bytes (common/stream_messages.h),
  // so the received message is a grpc::ByteBuffer holding one serialized
  // ExtractRequest.
  void OnReceive(void* message) override {
    upload_bytes_ += UploadBytes(static_cast<grpc::ByteBuffer*>(message));
  }

  void OnSend(const void* message) override {
    const auto* response = static_cast<const v1::ExtractResponse*>(message);
    for (const v1::StageTiming& t : response->timings()) {
      stage_->Add({{"stage", t.stage()}}, common::SecondsBuckets())
          .Observe(t.milliseconds() / 1000);
    }
    mesh_bytes_->Observe(static_cast<double>(upload_bytes_));
  }

 private:
  prometheus::Family<prometheus::Histogram>* stage_;
  prometheus::Histogram* mesh_bytes_;
  size_t upload_bytes_ = 0;
};

}  // namespace

void AddExtractMetrics(common::Metrics& metrics) {
  prometheus::Family<prometheus::Histogram>* stage =
      &prometheus::BuildHistogram()
           .Name("tpr_extractor_stage_duration_seconds")
           .Help("Duration of each extraction stage (ExtractResponse.timings)")
           .Register(metrics.registry());
  prometheus::Histogram* mesh_bytes =
      &prometheus::BuildHistogram()
           .Name("tpr_extractor_mesh_bytes")
           .Help("Size of each uploaded mesh, in bytes")
           .Register(metrics.registry())
           .Add({}, prometheus::Histogram::BucketBoundaries{1e3, 1e4, 1e5, 1e6,
                                                            1e7, 1e8});
  metrics.ObserveMethod("/tpr.v1.Extractor/Extract", [stage, mesh_bytes] {
    return std::make_unique<ExtractObserver>(stage, mesh_bytes);
  });
}

}  // namespace tpr::extractor
