// The orchestrator's native step channel (step_streams.h;
// coupler_orchestrator/master/native_step_channel.py calls it through its Python face,
// step_streams_module.c): a remote member's StepStream driven from the calling thread through a completion
// queue of its own, without gRPC's asyncio integration in between. Messages stay serialized (the Python side encodes DoStepRequest and decodes
// DoStepResponse), so this file knows the protocol only by the method's name; a request's
// pieces are sent from the caller's memory, so a camera frame is not copied on its way out.
//
// A step is split in two, so that the requests of every member are on the wire before any
// answer is awaited: cs_send() writes a request and asks for the answer; cs_receive() waits
// for it (or for the stream's end, or for the step's deadline, which cancels the stream).
// Every call returns at once or by its deadline; none of them throws. A target `steps:PATH`
// drives a participant's step socket instead (StepSocket below), behind the same calls.

#include <poll.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstring>
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

// gRPC status code numbers a step socket's end may carry or this side gives.
enum Code { OK = 0, DEADLINE_EXCEEDED = 4, RESOURCE_EXHAUSTED = 8, INTERNAL = 13, UNAVAILABLE = 14 };

const char* const STEPS = "steps:";  // a target naming a step socket: steps:/abs/path
const size_t HEADER = 5;             // uint32 little-endian payload length, uint8 kind
enum Kind : uint8_t { STEP = 0, END = 1 };

// A participant's step socket (docs/protocol.md "Step socket"): the StepStream's requests and
// answers framed on a plain unix socket, no gRPC. One request at a time: cs_send() writes it
// (header and pieces with one sendmsg, not copied), cs_receive() reads the answer into a buffer
// kept for the next one.
struct StepSocket {
  int fd = -1;
  size_t max_receive = 0, max_send = 0;
  double send_timeout = 0;
  std::vector<char> buffer;  // bytes received: [head, tail) not yet taken
  size_t head = 0, tail = 0;
  bool awaiting = false;  // a request was sent, its answer not yet received
  bool ended = false;     // the participant's end arrived, or the connection failed
  int code = OK;          // why it ended
  std::string error;

  ~StepSocket() {
    if (fd >= 0) ::close(fd);
  }

  // Connects to `path`; false with `error` set.
  bool open(const std::string& path, double timeout) {
    send_timeout = timeout;
    sockaddr_un address{};
    address.sun_family = AF_UNIX;
    if (path.size() >= sizeof(address.sun_path)) {
      error = "the step socket path " + path + " is longer than " +
              std::to_string(sizeof(address.sun_path) - 1) + " bytes";
      return false;
    }
    std::memcpy(address.sun_path, path.c_str(), path.size() + 1);
    fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
    if (fd < 0 ||
        ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) != 0) {
      error = "cannot connect to the step socket " + path + ": " + std::strerror(errno);
      return false;
    }
    // A request's write waits for room no longer than a call may take.
    timeval wait{};
    wait.tv_sec = static_cast<time_t>(timeout);
    wait.tv_usec = static_cast<suseconds_t>((timeout - static_cast<double>(wait.tv_sec)) * 1e6);
    ::setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &wait, sizeof(wait));
    return true;
  }

  void fail(int why, std::string message) {
    if (!ended) {
      ended = true;
      code = why;
      error = std::move(message);
    }
    ::shutdown(fd, SHUT_RDWR);
  }

  int send(const char* const* pieces, const size_t* sizes, int count) {
    if (ended || awaiting) return CS_FAILED;
    if (answered_unasked()) {
      fail(INTERNAL,
           "an answer arrived on the step socket before its request was sent: the "
           "participant answered a request twice (every later answer would belong to the "
           "step before it)");
      return CS_FAILED;
    }
    size_t total = 0;
    for (int i = 0; i < count; ++i) total += sizes[i];
    if (total > max_send || total > UINT32_MAX) {
      fail(RESOURCE_EXHAUSTED, "a request of " + std::to_string(total) +
                                   " bytes, over the step socket's send limit of " +
                                   std::to_string(max_send) + " bytes");
      return CS_FAILED;
    }
    unsigned char header[HEADER];
    for (int i = 0; i < 4; ++i) header[i] = static_cast<unsigned char>(total >> (8 * i));
    header[4] = STEP;
    std::vector<iovec> parts(count + 1);
    parts[0] = {header, HEADER};
    for (int i = 0; i < count; ++i) parts[i + 1] = {const_cast<char*>(pieces[i]), sizes[i]};
    awaiting = true;
    iovec* part = parts.data();
    size_t left = parts.size();
    while (left > 0) {
      msghdr message{};
      message.msg_iov = part;
      message.msg_iovlen = left;
      ssize_t sent = ::sendmsg(fd, &message, MSG_NOSIGNAL);
      if (sent < 0) {
        if (errno == EINTR) continue;
        // the participant may have ended the loop with a status: cs_receive() reads it
        bool slow = errno == EAGAIN || errno == EWOULDBLOCK;
        std::string why = slow ? "the participant took no request bytes for " +
                                     std::to_string(send_timeout) + " s"
                               : std::string("writing to the step socket failed: ") +
                                     std::strerror(errno);
        write_error = why;
        write_code = slow ? DEADLINE_EXCEEDED : UNAVAILABLE;
        ::shutdown(fd, SHUT_WR);
        return CS_OK;
      }
      auto done = static_cast<size_t>(sent);
      while (left > 0 && done >= part->iov_len) {
        done -= part->iov_len;
        ++part;
        --left;
      }
      if (left > 0) {
        part->iov_base = static_cast<char*>(part->iov_base) + done;
        part->iov_len -= done;
      }
    }
    return CS_OK;
  }
  // Whether a step's answer came that no request asked for: one more answer frame buffered,
  // or already arriving, after the last request's answer (its end frame, kind 1, is not one:
  // the participant may end the loop between two steps).
  bool answered_unasked() {
    if (tail - head < HEADER) {
      pollfd ready{fd, POLLIN, 0};
      if (::poll(&ready, 1, 0) > 0 && (ready.revents & POLLIN)) {
        if (head > 0) {
          std::memmove(buffer.data(), buffer.data() + head, tail - head);
          tail -= head;
          head = 0;
        }
        if (buffer.size() < 64 * 1024) buffer.resize(64 * 1024);
        ssize_t got = ::recv(fd, buffer.data() + tail, buffer.size() - tail, MSG_DONTWAIT);
        if (got > 0) tail += static_cast<size_t>(got);
      }
    }
    return tail - head >= HEADER && static_cast<uint8_t>(buffer[head + 4]) == STEP;
  }

  std::string write_error;  // a request's write failed: the status when no end arrives
  int write_code = OK;

  // Until `need` unread bytes are buffered: CS_OK, CS_TIMEOUT, or CS_FAILED (the connection
  // ended; `error` says why).
  int fill(size_t need, Deadline deadline) {
    if (tail - head >= need) return CS_OK;
    if (head > 0) {  // the last frame was taken: move what follows it to the front
      std::memmove(buffer.data(), buffer.data() + head, tail - head);
      tail -= head;
      head = 0;
    }
    if (buffer.size() < need) buffer.resize(std::max(need, static_cast<size_t>(64 * 1024)));
    while (tail < need) {
      auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                      deadline - std::chrono::system_clock::now())
                      .count();
      pollfd ready{fd, POLLIN, 0};
      int polled = ::poll(&ready, 1, static_cast<int>(std::max<long long>(left, 0)));
      if (polled < 0 && errno == EINTR) continue;
      if (polled == 0) return CS_TIMEOUT;
      ssize_t got = ::recv(fd, buffer.data() + tail, buffer.size() - tail, 0);
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) {
        std::string why = got == 0 ? "the participant closed its step socket without an end"
                                   : std::string("reading the step socket failed: ") +
                                         std::strerror(errno);
        if (!write_error.empty()) fail(write_code, write_error);
        else fail(UNAVAILABLE, why);
        return CS_FAILED;
      }
      tail += static_cast<size_t>(got);
    }
    return CS_OK;
  }

  // The next frame: CS_OK (a step's answer in (*data, *size)), CS_FAILED (the end, or the
  // connection's failure: `code`, `error`), CS_TIMEOUT (the connection shut down).
  int receive(double timeout, const char** data, size_t* size) {
    if (ended) return CS_FAILED;
    Deadline deadline = after(timeout);
    int got = fill(HEADER, deadline);
    uint32_t length = 0;
    if (got == CS_OK) {
      auto* bytes = reinterpret_cast<const unsigned char*>(buffer.data() + head);
      for (int i = 0; i < 4; ++i) length |= static_cast<uint32_t>(bytes[i]) << (8 * i);
      if (length > max_receive) {
        fail(RESOURCE_EXHAUSTED,
             "an answer of " + std::to_string(length) +
                 " bytes arrived on the step socket, over the limit of " +
                 std::to_string(max_receive) + " bytes");
        return CS_FAILED;
      }
      got = fill(HEADER + length, deadline);
    }
    if (got == CS_TIMEOUT) {
      fail(DEADLINE_EXCEEDED, "no answer within the deadline");
      return CS_TIMEOUT;
    }
    if (got != CS_OK) return CS_FAILED;
    uint8_t kind = static_cast<uint8_t>(buffer[head + 4]);
    const char* payload = buffer.data() + head + HEADER;
    head += HEADER + length;
    if (kind == STEP) {
      awaiting = false;
      *data = payload;
      *size = length;
      return CS_OK;
    }
    if (kind == END) {
      int status = UNAVAILABLE;
      std::string message;
      if (!read_end(payload, length, &status, &message))
        message = "the participant's step socket ended with an unreadable status";
      else if (status == OK)
        message = "the participant ended its step socket";
      ended = true;
      code = status == OK ? UNAVAILABLE : status;
      error = message;
      return CS_FAILED;
    }
    fail(INTERNAL, "a frame of unknown kind " + std::to_string(kind) + " on the step socket");
    return CS_FAILED;
  }

  // Half-closes and waits up to `timeout` for the participant's end (or the connection's);
  // how many step answers came before it that no request asked for.
  int close(double timeout) {
    if (fd < 0) return 0;
    int unasked = 0;
    if (!ended) {
      ::shutdown(fd, SHUT_WR);
      Deadline deadline = after(timeout);
      const char* data;
      size_t size;
      while (!ended && receive(std::chrono::duration<double>(deadline -
                                                             std::chrono::system_clock::now())
                                   .count(),
                               &data, &size) == CS_OK) {
        unasked += 1;
      }
    }
    ::close(fd);
    fd = -1;
    return unasked;
  }

  // A serialized StepSocketEnd { int32 code = 1; string message = 2; } read (this file has no
  // generated code: two fields, read by hand); false when it is not one.
  static bool read_end(const char* data, size_t size, int* code, std::string* message) {
    auto varint = [&](size_t& at, uint64_t& value) {
      value = 0;
      for (int shift = 0; shift < 64 && at < size; shift += 7) {
        auto byte = static_cast<unsigned char>(data[at++]);
        value |= static_cast<uint64_t>(byte & 0x7F) << shift;
        if (byte < 0x80) return true;
      }
      return false;
    };
    *code = OK;
    size_t at = 0;
    while (at < size) {
      uint64_t key, value;
      if (!varint(at, key)) return false;
      if ((key & 7) == 0) {
        if (!varint(at, value)) return false;
        if (key >> 3 == 1) *code = static_cast<int>(static_cast<int32_t>(value));
      } else if ((key & 7) == 2) {
        if (!varint(at, value) || value > size - at) return false;
        if (key >> 3 == 2) message->assign(data + at, value);
        at += value;
      } else {
        return false;
      }
    }
    return true;
  }
};

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
  std::unique_ptr<StepSocket> socket;  // a step socket instead of the StepStream

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

// Opens the step stream to `target` (host:port or unix:PATH; steps:PATH: a step socket); with
// `tls`, PEM texts (each may be empty) for the roots, the client's key and its chain. `metadata` holds `count` pairs
// (key, value). Answers of up to `max_receive` bytes and requests of up to `max_send` travel
// (gRPC's channel arguments); a larger answer ends the stream with RESOURCE_EXHAUSTED. Never NULL: cs_error()
// is empty when the stream is open, else says why (the stream must still be closed).
cs_stream* cs_open(const char* target, int tls, const char* roots, const char* key,
                   const char* chain, const char* const* metadata, int count, double timeout,
                   int max_receive, int max_send) {
  auto* s = new cs_stream();
  if (std::strncmp(target, STEPS, std::strlen(STEPS)) == 0) {
    s->socket = std::make_unique<StepSocket>();
    s->socket->max_receive = static_cast<size_t>(max_receive);
    s->socket->max_send = static_cast<size_t>(max_send);
    if (!s->socket->open(target + std::strlen(STEPS), timeout)) s->error = s->socket->error;
    return s;
  }
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
  if (s->socket) return s->socket->send(pieces, sizes, count);
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
  if (s->socket) {
    int got = s->socket->receive(timeout, data, size);
    *code = s->socket->code;
    s->error = got == CS_OK ? "" : s->socket->error;
    return got;
  }
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
int cs_close(cs_stream* s, double timeout) {
  if (s->socket) {
    int unasked = s->socket->close(timeout);
    delete s;
    return unasked;
  }
  Deadline deadline = after(timeout);
  int unasked = 0;
  if (s->call && !s->finished && !s->broken && !s->finishing && s->drain(deadline)) {
    s->pending += 1;
    s->call->WritesDone(tag(WRITE));
    // what the participant still sends before its status is an answer nobody asked for
    while (s->drain(deadline) && !s->broken) {
      s->read_done = false;
      s->pending += 1;
      s->call->Read(&s->reply, tag(READ));
      if (!s->drain(deadline) || s->broken || !s->read_done) break;
      unasked += 1;
    }
  }
  s->finish(deadline);
  delete s;
  return unasked;
}

}  // extern "C"
