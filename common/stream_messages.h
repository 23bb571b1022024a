// Client streams read as raw bytes, so that a message that does not parse is
// an error instead of the end of the stream.
//
// Why: gRPC's typed readers (ServerReader<T>::Read, ServerReadReactor<T>::
// OnReadDone) report a message that fails to deserialize exactly as they
// report the client's half-close: Read returns false (grpcpp/impl/
// call_op_set.h, CallOpRecvMessage::FinishOp). A handler looping on Read
// then took garbage for the end and answered OK for a truncated stream
// (a BatchUpsert with garbage in the middle wrote the models
// before it and reported success). The client-streaming methods therefore
// receive grpc::ByteBuffer and parse each message here, which tells the two
// apart. RawClientStreamHandler (below) installs such a handler in place of
// the generated one:
//
//   // in a handler given a grpc::ServerReader<grpc::ByteBuffer>:
//   tpr::common::StreamParser<tpr::v1::UpsertRequest> parser("BatchUpsert");
//   grpc::ByteBuffer raw;
//   while (reader->Read(&raw)) {
//     TPR_RETURN_IF_ERROR(parser.Parse(&raw, &request));   // INVALID_ARGUMENT
//     ...
//   }
//
// Header-only (templates); for the services, never the pure libraries.
#ifndef TPR_COMMON_STREAM_MESSAGES_H_
#define TPR_COMMON_STREAM_MESSAGES_H_

#include <grpcpp/impl/codegen/proto_utils.h>
#include <grpcpp/impl/codegen/server_callback_handlers.h>
#include <grpcpp/server_context.h>
#include <grpcpp/support/byte_buffer.h>
#include <grpcpp/support/method_handler.h>
#include <grpcpp/support/sync_stream.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <utility>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace tpr::common {

// StreamParser parses the successive messages of one client stream of
// `Message` (a generated protobuf class). Not thread-safe (one stream).
template <class Message>
class StreamParser {
 public:
  // `method` names the RPC in errors ("BatchUpsert"). Must outlive the parser.
  explicit StreamParser(const char* method) : method_(method) {}

  // Parse replaces *message with the next message of the stream, read from
  // *raw (consumed: cleared whether or not it parses). Returns OK, or
  // INVALID_ARGUMENT "<method>: message N of the stream (B bytes) does not
  // parse as tpr.v1.X: ..." with N counted from 1. Cost O(B).
  absl::Status Parse(grpc::ByteBuffer* raw, Message* message) {
    ++count_;
    const size_t bytes = raw->Length();
    // gRPC's own protobuf deserializer (what the typed reader runs): parses
    // straight from the slices and clears *raw.
    const bool ok =
        grpc::SerializationTraits<Message>::Deserialize(raw, message).ok();
    if (ok) return absl::OkStatus();
    return absl::InvalidArgumentError(absl::StrCat(
        method_, ": message ", count_, " of the stream (", bytes,
        " bytes) does not parse as ", message->GetTypeName(),
        ": malformed protobuf bytes, or a string field (such as an id or "
        "label) that is not valid UTF-8; nothing after it was read"));
  }

  // count returns the messages parsed so far (the failed one included).
  int64_t count() const { return count_; }

 private:
  const char* method_;
  int64_t count_ = 0;
};

// CheckGenerated aborts unless `generated` (grpc::Service::GetHandler(i)
// of the generated service) is of type `Expected`: a reordered or changed
// proto then fails at start-up instead of misrouting calls.
template <class Expected>
void CheckGenerated(grpc::internal::MethodHandler* generated,
                    const char* method) {
  if (dynamic_cast<Expected*>(generated) == nullptr) {
    std::fprintf(stderr, "the generated handler replaced for %s is not %s's\n",
                 method, method);
    std::abort();
  }
}

// RawClientStreamHandler returns a sync-API handler running
// `service->*method`, which reads the stream as raw bytes (parsing each with
// a StreamParser). Install it in the service's constructor in place of the
// generated typed handler of method number `index` (the rpc's position in
// the .proto):
//   MarkMethodStreamed(index, RawClientStreamHandler<v1::Indexer::Service,
//       v1::UpsertRequest>(GetHandler(index), "BatchUpsert", this,
//       &IndexerService::BatchUpsertRaw));
// `GeneratedService` and `Request` name the generated handler it replaces
// (checked, see CheckGenerated). Uses grpc::internal handler classes, as
// the generated code does (gRPC 1.51).
template <class GeneratedService, class Request, class Service, class Response>
grpc::internal::MethodHandler* RawClientStreamHandler(
    grpc::internal::MethodHandler* generated, const char* name,
    Service* service,
    grpc::Status (Service::*method)(grpc::ServerContext*,
                                    grpc::ServerReader<grpc::ByteBuffer>*,
                                    Response*)) {
  CheckGenerated<grpc::internal::ClientStreamingHandler<GeneratedService,
                                                        Request, Response>>(
      generated, name);
  return new grpc::internal::ClientStreamingHandler<Service, grpc::ByteBuffer,
                                                    Response>(
      [method](Service* s, grpc::ServerContext* context,
               grpc::ServerReader<grpc::ByteBuffer>* reader,
               Response* response) {
        return (s->*method)(context, reader, response);
      },
      service);
}

// RawCallbackClientStreamHandler: the same for the callback API (install
// with MarkMethodCallback): `make_reactor` returns the reactor of one call,
// reading grpc::ByteBuffer.
template <class Request, class Response>
grpc::internal::MethodHandler* RawCallbackClientStreamHandler(
    grpc::internal::MethodHandler* generated, const char* name,
    std::function<grpc::ServerReadReactor<grpc::ByteBuffer>*(
        grpc::CallbackServerContext*, Response*)>
        make_reactor) {
  CheckGenerated<
      grpc::internal::CallbackClientStreamingHandler<Request, Response>>(
      generated, name);
  return new grpc::internal::CallbackClientStreamingHandler<grpc::ByteBuffer,
                                                            Response>(
      std::move(make_reactor));
}

}  // namespace tpr::common

#endif  // TPR_COMMON_STREAM_MESSAGES_H_
