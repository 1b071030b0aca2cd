// The part of an exported FMU's binary that is the same for FMI 2.0 and FMI 3.0: a client of
// the participant's GRPCComponentService (proto/coupler/v1/component.proto) holding the values
// of the exported channels between FMI calls. fmi2_proxy.cc and fmi3_proxy.cc map the FMI
// calls onto it; `coupler export-fmu` writes what it reads (resources/coupler-proxy.txt).

#pragma once

#include <chrono>
#include <cstdint>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "coupler/v1/component.grpc.pb.h"

namespace coupler_proxy {

// How a channel looks to the FMU: the FMI type it is exported as, or HIDDEN (FMI 2's binary
// channels: described, so a change is noticed, but never sent or read).
enum class Kind { REAL, INTEGER, BOOLEAN, STRING, BINARY, HIDDEN };

struct Channel {
  unsigned vr = 0;
  std::string name;
  Kind kind = Kind::REAL;
  int causality = 0;  // proto Causality: 1 input, 2 output, 3 parameter
  int type = 0;       // proto ValueType, as described at export
  std::string unit;
  uint64_t max_bytes = 0;  // largest value declared (Binary, String); 0: none, as at export
  double real = 0.0;
  int integer = 0;
  bool boolean = false;
  std::string bytes;  // String (UTF-8) and Binary values
  // A parameter is sent with Initialize when the participant declared a start value for it or
  // the FMI master set it; one it declared none for and nobody set keeps the participant's own
  // default (the FMU's start, 0 or "", is no value the participant ever gave).
  bool given = true;
};

// `error` is true for a failure (the caller answers fmiError), false for information.
using Logger = std::function<void(bool error, const std::string& message)>;

enum class StepResult { OK, TERMINATED, FAILED };

constexpr unsigned ADDRESS_VR = 0;  // the String parameter coupler_address

// Cancels a call that outlives its deadline: a stream has one context for all its steps, so
// each step's deadline is kept by this thread, not by gRPC.
class Watchdog {
 public:
  Watchdog();
  ~Watchdog();
  void arm(grpc::ClientContext* context, double seconds);
  // Whether the deadline passed (and the call was cancelled) since arm().
  bool disarm();

 private:
  void run();
  std::mutex mutex_;
  std::condition_variable wake_;
  grpc::ClientContext* context_ = nullptr;
  std::chrono::steady_clock::time_point deadline_;
  bool armed_ = false;
  bool fired_ = false;
  bool stop_ = false;
  std::thread thread_;
};

class Proxy {
 public:
  explicit Proxy(Logger logger) : log_(std::move(logger)) {}
  ~Proxy();

  // Reads coupler-proxy.txt from the resource folder (a path or a file: URI).
  bool load(const std::string& resources);
  const std::string& fingerprint() const { return fingerprint_; }
  // Connects to the exported address (or COUPLER_PROXY_ADDRESS) and checks its description.
  bool connect();
  // The coupler_address parameter: connect to `address` instead (before initialization).
  bool set_address(const std::string& address);
  const std::string& address() const { return address_; }

  bool initialize(double start_time, std::optional<double> stop_time);
  StepResult step(double time, double step_size);
  void terminate(const char* reason);
  void reset();

  Channel* find(unsigned vr);
  // A failure: logged as an error; false, for `return error(...)`.
  bool error(const std::string& message) const {
    log_(true, message);
    return false;
  }
  // FMI 3's independent variable: its value reference (from the export) and value.
  bool is_time(unsigned vr) const { return time_vr_ && vr == *time_vr_; }
  double time() const { return time_; }
  // Whether the participant ended the run itself (DoStepResponse.terminate).
  bool ended() const { return ended_; }

 private:
  void info(const std::string& message) const { log_(false, message); }
  bool failed(const char* call, const grpc::Status& status) const;
  // "participant 'NAME' at ADDRESS", for messages.
  std::string who() const { return "participant '" + name_ + "' at " + address_; }
  void prepare(grpc::ClientContext* context) const;
  std::string changes(const coupler::v1::DescribeResponse& description) const;
  void keep(const google::protobuf::RepeatedPtrField<coupler::v1::VariableBinding>& outputs);
  bool exchange(const coupler::v1::DoStepRequest& request, coupler::v1::DoStepResponse* response);
  void close_stream();

  Logger log_;
  std::string name_;  // the participant's name at export
  std::string address_;
  std::string fingerprint_;
  double timeout_ = 30.0;
  double step_size_ = 0.0;
  // Bytes an answer and a request may have (coupler-proxy.txt's max_receive and max_send: the
  // participant's declared maxima, else Coupler's message limit, plus framing, as `coupler
  // run` sets them); 0: gRPC's own (4 MiB received).
  int max_receive_ = 0;
  int max_send_ = 0;
  std::vector<Channel> channels_;
  std::map<unsigned, size_t> by_vr_;
  std::map<std::string, size_t> by_name_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<coupler::v1::GRPCComponentService::Stub> stub_;
  std::string token_;
  bool streaming_ = false;  // the participant's capabilities.streaming
  std::unique_ptr<grpc::ClientContext> stream_context_;
  std::unique_ptr<grpc::ClientReaderWriter<coupler::v1::DoStepRequest,
                                           coupler::v1::DoStepResponse>> stream_;
  std::unique_ptr<Watchdog> watchdog_;
  std::string run_id_;
  std::string run_secret_;  // the run's secret: every call of the run carries it
  bool initialized_ = false;
  bool terminated_ = false;
  bool ended_ = false;
  std::optional<unsigned> time_vr_;  // FMI 3 only
  double time_ = 0.0;
};

// The FMI getters and setters of both versions: `n` values of the channels `vr` of `kind`
// read into `value` (written from it); false, with a logged error, for a reference that is no
// variable of that kind (or, for a setter, an output).
template <typename T, typename Read>
bool read_values(Proxy& proxy, const unsigned vr[], size_t n, T value[], Kind kind, Read read) {
  for (size_t i = 0; i < n; ++i) {
    Channel* ch = proxy.find(vr[i]);
    if (ch == nullptr || ch->kind != kind)
      return proxy.error("no variable of this type with value reference " +
                          std::to_string(vr[i]));
    value[i] = read(*ch);
  }
  return true;
}

template <typename T, typename Write>
bool write_values(Proxy& proxy, const unsigned vr[], size_t n, const T value[], Kind kind,
                  Write write) {
  for (size_t i = 0; i < n; ++i) {
    Channel* ch = proxy.find(vr[i]);
    if (ch == nullptr || ch->kind != kind || ch->causality == 2 /* output */)
      return proxy.error("no settable variable of this type with value reference " +
                          std::to_string(vr[i]));
    write(*ch, value[i]);
    ch->given = true;
  }
  return true;
}

// The description's fingerprint, as coupler_orchestrator.tools.export_fmu computes it: FNV-1a 64 (hex)
// of the sorted lines "name|causality|type|unit" of every channel, joined by newlines.
std::string fingerprint_of(const coupler::v1::DescribeResponse& description);

}  // namespace coupler_proxy
