// The orchestrator's native step channel (step_streams.h;
// coupler_orchestrator/master/native_step_channel.py calls it through the cffi binding of that
// header): a remote member's StepStream driven from the calling thread through a completion
// queue of its own, without gRPC's asyncio integration in between. Messages stay serialized (the Python side encodes DoStepRequest and decodes
// DoStepResponse), so this file knows the protocol only by the method's name; a request's
// pieces are sent from the caller's memory, so a camera frame is not copied on its way out.
//
// A step is split in two, so that the requests of every member are on the wire before any
// answer is awaited: cs_send() writes a request and asks for the answer; cs_receive() waits
// for it (or for the stream's end, or for the step's deadline, which cancels the stream).
// Every call returns at once or by its deadline; none of them throws.

#include <chrono>
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

extern "C" {
#include "step_streams.h"
}

namespace {

const char* const METHOD = "/coupler.v1.GRPCComponentService/StepStream";
enum Op : uintptr_t { START = 1, WRITE = 2, READ = 3, FINISH = 4 };

using Deadline = std::chrono::system_clock::time_point;

Deadline after(double seconds) {
  return std::chrono::system_clock::now() +
         std::chrono::microseconds(static_cast<long long>(seconds * 1e6));
}

void* tag(Op op) { return reinterpret_cast<void*>(op); }

}  // namespace

struct cs_stream {
  grpc::CompletionQueue queue;
  std::shared_ptr<grpc::Channel> channel;
  std::unique_ptr<grpc::GenericStub> stub;
  grpc::ClientContext context;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call;
  grpc::ByteBuffer request;
  grpc::ByteBuffer reply;
  std::string reply_bytes;
  grpc::Status status;
  std::string error;
  int pending = 0;      // operations issued and not yet completed
  bool broken = false;  // an operation failed: the stream has ended, its status says why
  bool read_done = false;
  bool finishing = false;
  bool finished = false;

  // Takes one completion off the queue; false when the deadline passed first.
  bool next(Deadline deadline) {
    void* got = nullptr;
    bool ok = false;
    if (queue.AsyncNext(&got, &ok, deadline) != grpc::CompletionQueue::GOT_EVENT) return false;
    pending -= 1;
    auto op = static_cast<Op>(reinterpret_cast<uintptr_t>(got));
    if (op == READ) read_done = true;
    if (op == FINISH) finished = true;
    else if (!ok) broken = true;
    return true;
  }

  // Drains what is issued; false if it did not complete by the deadline.
  bool drain(Deadline deadline) {
    while (pending > 0)
      if (!next(deadline)) return false;
    return true;
  }

  // The status of a stream that ended (asked for once, waited for up to the deadline; then
  // the call is cancelled).
  void finish(Deadline deadline) {
    if (!call || finished) return;
    if (!finishing) {
      finishing = true;
      pending += 1;
      call->Finish(&status, tag(FINISH));
    }
    if (!drain(deadline)) {
      context.TryCancel();
      drain(after(5.0));
      if (!finished) status = grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, "no status");
    }
  }

  ~cs_stream() {
    if (call && !finished) {
      context.TryCancel();
      finish(after(5.0));
    }
    queue.Shutdown();
    void* got;
    bool ok;
    while (queue.Next(&got, &ok)) {
    }
  }
};

extern "C" {

// Opens the step stream to `target` (host:port or unix:PATH); with `tls`, PEM texts (each may
// be empty) for the roots, the client's key and its chain. `metadata` holds `count` pairs
// (key, value). Answers of up to `max_receive` bytes and requests of up to `max_send` travel
// (gRPC's channel arguments); a larger answer ends the stream with RESOURCE_EXHAUSTED. Never NULL: cs_error()
// is empty when the stream is open, else says why (the stream must still be closed).
cs_stream* cs_open(const char* target, int tls, const char* roots, const char* key,
                   const char* chain, const char* const* metadata, int count, double timeout,
                   int max_receive, int max_send) {
  auto* s = new cs_stream();
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (tls) {
    grpc::SslCredentialsOptions options;
    options.pem_root_certs = roots;
    options.pem_private_key = key;
    options.pem_cert_chain = chain;
    credentials = grpc::SslCredentials(options);
  }
  Deadline deadline = after(timeout);
  grpc::ChannelArguments arguments;
  arguments.SetMaxReceiveMessageSize(max_receive);
  arguments.SetMaxSendMessageSize(max_send);
  s->channel = grpc::CreateCustomChannel(target, credentials, arguments);
  if (!s->channel->WaitForConnected(deadline)) {
    s->error = "no connection within the deadline";
    return s;
  }
  s->stub = std::make_unique<grpc::GenericStub>(s->channel);
  for (int i = 0; i < count; ++i) s->context.AddMetadata(metadata[2 * i], metadata[2 * i + 1]);
  s->call = s->stub->PrepareCall(&s->context, METHOD, &s->queue);
  s->pending += 1;
  s->call->StartCall(tag(START));
  if (!s->drain(deadline) || s->broken) {
    s->finish(deadline);
    s->error = "the step stream did not start: " + s->status.error_message();
  }
  return s;
}

const char* cs_error(cs_stream* s) { return s->error.c_str(); }

// Writes one serialized DoStepRequest, given as `count` pieces whose concatenation is the
// message (not copied: gRPC sends from them), and asks for the answer; CS_FAILED when the stream
// has ended (cs_receive then tells its status) or the previous answer was not received.
int cs_send(cs_stream* s, const char* const* pieces, const size_t* sizes, int count) {
  if (!s->call || s->broken || s->pending > 0 || s->finishing) return CS_FAILED;
  std::vector<grpc::Slice> slices;
  slices.reserve(count);
  for (int i = 0; i < count; ++i)
    slices.emplace_back(pieces[i], sizes[i], grpc::Slice::STATIC_SLICE);
  s->request = grpc::ByteBuffer(slices.data(), slices.size());
  s->read_done = false;
  s->pending += 2;
  s->call->Write(s->request, tag(WRITE));
  s->call->Read(&s->reply, tag(READ));
  return CS_OK;
}

// Waits up to `timeout` seconds for the answer to cs_send(): CS_OK with the serialized
// DoStepResponse in (*data, *size), valid until the next call on this stream; CS_FAILED with the
// stream's final status (*code, and cs_error()); CS_TIMEOUT, the stream cancelled.
int cs_receive(cs_stream* s, double timeout, const char** data, size_t* size, int* code) {
  Deadline deadline = after(timeout);
  while (!s->broken && !(s->read_done && s->pending == 0)) {
    if (!s->next(deadline)) {
      s->context.TryCancel();
      s->drain(after(5.0));
      s->finished = true;  // the deadline is the status: nothing more to wait for
      s->broken = true;
      *code = static_cast<int>(grpc::StatusCode::DEADLINE_EXCEEDED);
      return CS_TIMEOUT;
    }
  }
  if (s->broken) {
    s->drain(deadline);
    s->finish(deadline);
    *code = static_cast<int>(s->status.error_code());
    s->error = s->status.error_message();
    return CS_FAILED;
  }
  std::vector<grpc::Slice> slices;
  s->reply.Dump(&slices);
  s->reply_bytes.clear();
  for (const auto& slice : slices)
    s->reply_bytes.append(reinterpret_cast<const char*>(slice.begin()), slice.size());
  *data = s->reply_bytes.data();
  *size = s->reply_bytes.size();
  return CS_OK;
}

// Ends the stream, half-closing it and waiting up to `timeout` for the participant's status
// (then cancelling it), and frees it. Safe in any state.
void cs_close(cs_stream* s, double timeout) {
  Deadline deadline = after(timeout);
  if (s->call && !s->finished && !s->broken && !s->finishing && s->drain(deadline)) {
    s->pending += 1;
    s->call->WritesDone(tag(WRITE));
  }
  s->finish(deadline);
  delete s;
}

}  // extern "C"
