// See proxy_core.h. Every call has a deadline (the exported call timeout); every failure is
// logged naming the participant's address, the call and the gRPC status.

#include "proxy_core.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <locale>
#include <random>
#include <sstream>

namespace pb = coupler::v1;

namespace coupler_proxy {

namespace {

// The ceilings of coupler.durations: participants refuse a longer lease.
constexpr double kMaxLease = 86400.0;
constexpr double kMaxTimeout = 86400.0;

std::string unescape(const std::string& text) {
  std::string out;
  for (size_t i = 0; i < text.size(); ++i) {
    if (text[i] == '\\' && i + 1 < text.size()) {
      char c = text[++i];
      out += c == 't' ? '\t' : c == 'n' ? '\n' : c;
    } else {
      out += text[i];
    }
  }
  return out;
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> fields;
  std::string field;
  std::istringstream stream(line);
  while (std::getline(stream, field, '\t')) fields.push_back(field);
  if (!line.empty() && line.back() == '\t') fields.emplace_back();  // an empty last field
  return fields;
}

// Numbers as the export wrote them, whatever the host program's locale.
double to_double(const std::string& text) {
  std::istringstream stream(text);
  stream.imbue(std::locale::classic());
  double value = 0.0;
  stream >> value;
  return value;
}

std::string from_hex(const std::string& hex) {
  std::string out;
  for (size_t i = 0; i + 1 < hex.size(); i += 2)
    out += static_cast<char>(std::strtol(hex.substr(i, 2).c_str(), nullptr, 16));
  return out;
}

std::string read_file(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream content;
  content << file.rdbuf();
  return content.str();
}

const char* status_name(grpc::StatusCode code) {
  switch (code) {
    case grpc::OK: return "OK";
    case grpc::CANCELLED: return "CANCELLED";
    case grpc::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::NOT_FOUND: return "NOT_FOUND";
    case grpc::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::ABORTED: return "ABORTED";
    case grpc::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::INTERNAL: return "INTERNAL";
    case grpc::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}

std::string new_run_id() {
  std::random_device device;
  std::mt19937_64 random(device());
  char id[40];
  std::snprintf(id, sizeof id, "fmu-%016llx%016llx", static_cast<unsigned long long>(random()),
                static_cast<unsigned long long>(random()));
  return id;
}

// A new run's secret (docs/protocol.md): 32 bytes from the kernel's CSPRNG, never logged.
bool new_run_secret(std::string* secret) {
  secret->assign(32, '\0');
  std::ifstream random("/dev/urandom", std::ios::binary);
  return static_cast<bool>(
      random.read(&(*secret)[0], static_cast<std::streamsize>(secret->size())));
}

void bind(pb::VariableBinding* binding, const Channel& c) {
  binding->set_channel(c.name);
  switch (c.kind) {
    case Kind::REAL: binding->set_real(c.real); break;
    case Kind::INTEGER: binding->set_integer(c.integer); break;
    case Kind::BOOLEAN: binding->set_boolean(c.boolean); break;
    case Kind::STRING: binding->set_text(c.bytes); break;
    case Kind::BINARY: binding->set_binary(c.bytes); break;
    case Kind::HIDDEN: break;
  }
}

}  // namespace

std::string fingerprint_of(const pb::DescribeResponse& description) {
  std::vector<std::string> lines;
  for (const auto& c : description.channels()) {
    std::ostringstream line;
    line << c.name() << '|' << c.causality() << '|' << c.type() << '|' << c.unit();
    if (c.max_bytes()) line << '|' << c.max_bytes();
    lines.push_back(line.str());
  }
  std::sort(lines.begin(), lines.end());
  std::string joined;
  for (size_t i = 0; i < lines.size(); ++i) joined += (i ? "\n" : "") + lines[i];
  uint64_t hash = 14695981039346656037ULL;
  for (unsigned char c : joined) {
    hash ^= c;
    hash *= 1099511628211ULL;
  }
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(hash));
  return hex;
}

Watchdog::Watchdog() : thread_([this] { run(); }) {}

Watchdog::~Watchdog() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void Watchdog::arm(grpc::ClientContext* context, double seconds) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    context_ = context;
    deadline_ = std::chrono::steady_clock::now() +
                std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
    armed_ = true;
    fired_ = false;
  }
  wake_.notify_all();
}

bool Watchdog::disarm() {
  std::lock_guard<std::mutex> lock(mutex_);
  armed_ = false;
  return fired_;
}

void Watchdog::run() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_) {
    if (!armed_) {
      wake_.wait(lock);
      continue;
    }
    if (wake_.wait_until(lock, deadline_) == std::cv_status::timeout && armed_ && !stop_ &&
        std::chrono::steady_clock::now() >= deadline_) {
      context_->TryCancel();
      fired_ = true;
      armed_ = false;
    }
  }
}

Proxy::~Proxy() { terminate("the FMU instance was freed"); }

bool Proxy::failed(const char* call, const grpc::Status& status) const {
  return error(who() + ": " + call + " failed [" +
               status_name(status.error_code()) + "]: " + status.error_message());
}

void Proxy::prepare(grpc::ClientContext* context) const {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::microseconds(static_cast<int64_t>(timeout_ * 1e6)));
  if (!token_.empty()) context->AddMetadata("authorization", "Bearer " + token_);
}

bool Proxy::load(const std::string& resources) {
  std::string base = resources;
  if (base.rfind("file://", 0) == 0) base = base.substr(7);
  else if (base.rfind("file:", 0) == 0) base = base.substr(5);
  if (!base.empty() && base.back() != '/') base += '/';
  std::ifstream file(base + "coupler-proxy.txt");
  if (!file)
    return error("cannot read " + base + "coupler-proxy.txt (export the FMU again with "
                 "coupler export-fmu)");
  std::string line;
  while (std::getline(file, line)) {
    auto f = split(line);
    if (f.size() < 2) continue;
    if (f[0] == "address") address_ = f[1];
    else if (f[0] == "name") name_ = unescape(f[1]);
    else if (f[0] == "fingerprint") fingerprint_ = f[1];
    else if (f[0] == "timeout") timeout_ = to_double(f[1]);
    else if (f[0] == "step_size") step_size_ = to_double(f[1]);
    else if (f[0] == "max_receive") max_receive_ = std::atoi(f[1].c_str());
    else if (f[0] == "max_send") max_send_ = std::atoi(f[1].c_str());
    else if (f[0] == "time_vr")
      time_vr_ = static_cast<unsigned>(std::strtoul(f[1].c_str(), nullptr, 10));
    else if (f[0] == "channel" && f.size() >= 8) {
      Channel c;
      c.vr = static_cast<unsigned>(std::strtoul(f[1].c_str(), nullptr, 10));
      c.name = unescape(f[2]);
      c.type = std::atoi(f[3].c_str());
      c.causality = std::atoi(f[4].c_str());
      c.unit = unescape(f[5]);
      if (f.size() >= 9) c.max_bytes = std::strtoull(f[8].c_str(), nullptr, 10);
      if (f.size() >= 10) c.given = f[9] != "0";  // older exports: every parameter sent
      const std::string& kind = f[6];
      c.kind = kind == "Real" ? Kind::REAL
             : kind == "Integer" ? Kind::INTEGER
             : kind == "Boolean" ? Kind::BOOLEAN
             : kind == "String" ? Kind::STRING
             : kind == "Binary" ? Kind::BINARY : Kind::HIDDEN;
      std::string start = unescape(f[7]);
      if (c.kind == Kind::REAL) c.real = to_double(start);
      if (c.kind == Kind::INTEGER) c.integer = std::atoi(start.c_str());
      if (c.kind == Kind::BOOLEAN) c.boolean = start == "true";
      if (c.kind == Kind::STRING) c.bytes = start;
      if (c.kind == Kind::BINARY) c.bytes = from_hex(start);
      if (c.kind != Kind::HIDDEN) by_vr_[c.vr] = channels_.size();
      by_name_[c.name] = channels_.size();
      channels_.push_back(c);
    }
  }
  if (!std::isfinite(timeout_) || timeout_ <= 0 || timeout_ > kMaxTimeout) {
    std::ostringstream message;
    message << base << "coupler-proxy.txt: timeout " << timeout_
            << " must be a number of seconds > 0 and <= " << kMaxTimeout
            << " (24 h); export the FMU again with a valid --call-timeout";
    return error(message.str());
  }
  return true;
}

std::string Proxy::changes(const pb::DescribeResponse& description) const {
  std::ostringstream out;
  std::map<std::string, const pb::ChannelDescription*> now;
  for (const auto& c : description.channels()) now[c.name()] = &c;
  for (const auto& c : channels_) {
    auto found = now.find(c.name);
    if (found == now.end()) {
      out << " '" << c.name << "' is gone;";
      continue;
    }
    const auto* d = found->second;
    if (d->type() != c.type)
      out << " '" << c.name << "' changed type " << pb::ValueType_Name(c.type) << " -> "
          << pb::ValueType_Name(d->type()) << ";";
    if (d->causality() != c.causality)
      out << " '" << c.name << "' changed causality " << pb::Causality_Name(c.causality)
          << " -> " << pb::Causality_Name(d->causality()) << ";";
    if (d->unit() != c.unit)
      out << " '" << c.name << "' changed unit '" << c.unit << "' -> '" << d->unit() << "';";
    if (d->max_bytes() != c.max_bytes)
      out << " '" << c.name << "' changed its largest value " << c.max_bytes << " -> "
          << d->max_bytes() << " bytes (max_bytes);";
    now.erase(found);
  }
  for (const auto& entry : now) out << " '" << entry.first << "' is new;";
  return out.str();
}

bool Proxy::connect() {
  const char* overridden = std::getenv("COUPLER_PROXY_ADDRESS");
  if (overridden && *overridden) address_ = overridden;
  return set_address(address_);
}

bool Proxy::set_address(const std::string& address) {
  if (initialized_ && !terminated_)
    return error("coupler_address cannot change during a run (" + who() + ")");
  address_ = address;
  std::string target = address;
  bool tls = target.rfind("grpcs://", 0) == 0;
  if (tls) target = target.substr(8);
  else if (target.rfind("grpc://", 0) == 0) target = target.substr(7);
  else if (target.rfind("unix:///", 0) == 0) target = "unix:" + target.substr(7);
  else
    return error("coupler_address '" + address + "' is not grpc://HOST:PORT, grpcs://HOST:PORT "
                 "or unix:///PATH");
  std::shared_ptr<grpc::ChannelCredentials> credentials;
  if (tls) {
    grpc::SslCredentialsOptions options;
    if (const char* ca = std::getenv("COUPLER_TLS_CA")) options.pem_root_certs = read_file(ca);
    if (const char* cert = std::getenv("COUPLER_TLS_CERT"))
      options.pem_cert_chain = read_file(cert);
    if (const char* key = std::getenv("COUPLER_TLS_KEY")) options.pem_private_key = read_file(key);
    credentials = grpc::SslCredentials(options);
  } else {
    credentials = grpc::InsecureChannelCredentials();
  }
  token_.clear();
  if (const char* token_file = std::getenv("COUPLER_TOKEN_FILE")) {
    if (*token_file) {
      std::string token = read_file(token_file);
      while (!token.empty() && std::isspace(static_cast<unsigned char>(token.back())))
        token.pop_back();
      if (token.empty()) return error(std::string("COUPLER_TOKEN_FILE ") + token_file +
                                      " is missing or empty");
      token_ = token;
    }
  }
  grpc::ChannelArguments arguments;
  if (max_receive_ > 0) arguments.SetMaxReceiveMessageSize(max_receive_);
  if (max_send_ > 0) arguments.SetMaxSendMessageSize(max_send_);
  channel_ = grpc::CreateCustomChannel(target, credentials, arguments);
  stub_ = pb::GRPCComponentService::NewStub(channel_);
  pb::DescribeRequest request;
  pb::DescribeResponse description;
  grpc::ClientContext context;
  prepare(&context);
  context.set_wait_for_ready(true);  // a participant still starting: wait, within the deadline
  grpc::Status status = stub_->Describe(&context, request, &description);
  if (!status.ok()) return failed("Describe", status);
  if (fingerprint_of(description) != fingerprint_)
    return error(who() + " is not the one this FMU was exported from:" +
                 changes(description) + " export the FMU again (coupler export-fmu " + address_ +
                 " --out ...)");
  streaming_ = description.capabilities().streaming();
  info("connected to participant '" + description.name() + "' at " + address_ +
       (streaming_ ? " (steps over one StepStream)" : " (steps as DoStep calls)"));
  return true;
}

bool Proxy::initialize(double start_time, std::optional<double> stop_time) {
  if (!stub_) return error("not connected to a participant");
  run_id_ = new_run_id();
  if (!new_run_secret(&run_secret_))
    return error("cannot read /dev/urandom for the run's secret");
  time_ = start_time;
  pb::InitializeRequest request;
  request.set_run_id(run_id_);
  request.set_run_secret(run_secret_);
  request.set_start_time(start_time);
  request.set_step_size(step_size_);
  if (stop_time) request.set_stop_time(*stop_time);
  request.set_lease_seconds(std::min(std::max(60.0, 4 * timeout_), kMaxLease));
  for (const auto& c : channels_) {
    if (c.kind == Kind::HIDDEN) continue;
    if (c.causality == pb::CAUSALITY_PARAMETER && c.given) bind(request.add_parameters(), c);
    if (c.causality == pb::CAUSALITY_INPUT) bind(request.add_inputs(), c);
  }
  pb::InitializeResponse response;
  grpc::ClientContext context;
  prepare(&context);
  grpc::Status status = stub_->Initialize(&context, request, &response);
  if (!status.ok()) return failed("Initialize", status);
  initialized_ = true;
  terminated_ = ended_ = false;
  keep(response.outputs());
  return true;
}

StepResult Proxy::step(double time, double step_size) {
  if (!initialized_ || terminated_ || ended_) {
    error("DoStep outside a run (" + who() + ")" +
          (ended_ ? ": the participant has ended the run" : ""));
    return StepResult::FAILED;
  }
  pb::DoStepRequest request;
  request.set_run_id(run_id_);
  request.set_run_secret(run_secret_);
  request.set_current_time(time);
  request.set_step_size(step_size);
  for (const auto& c : channels_)
    if (c.causality == pb::CAUSALITY_INPUT && c.kind != Kind::HIDDEN) bind(request.add_inputs(), c);
  pb::DoStepResponse response;
  if (!exchange(request, &response)) return StepResult::FAILED;
  keep(response.outputs());
  time_ = time + step_size;
  if (response.terminate()) {
    std::ostringstream message;
    message << who() << " ended the run at t=" << time + step_size
            << " s: " << response.terminate_reason();
    info(message.str());
    ended_ = true;  // Terminate (fmiTerminate) still follows, as the protocol asks
    return StepResult::TERMINATED;
  }
  return StepResult::OK;
}

// One step: over the run's StepStream when the participant streams (opened at the first
// step), else one DoStep call.
bool Proxy::exchange(const pb::DoStepRequest& request, pb::DoStepResponse* response) {
  if (!streaming_) {
    grpc::ClientContext context;
    prepare(&context);
    grpc::Status status = stub_->DoStep(&context, request, response);
    return status.ok() || failed("DoStep", status);
  }
  if (!stream_) {
    stream_context_ = std::make_unique<grpc::ClientContext>();
    if (!token_.empty()) stream_context_->AddMetadata("authorization", "Bearer " + token_);
    if (!watchdog_) watchdog_ = std::make_unique<Watchdog>();
    stream_ = stub_->StepStream(stream_context_.get());
  }
  watchdog_->arm(stream_context_.get(), timeout_);
  bool ok = stream_->Write(request) && stream_->Read(response);
  bool late = watchdog_->disarm();
  if (ok) return true;
  grpc::Status status = stream_->Finish();
  stream_.reset();
  stream_context_.reset();
  if (late) {
    std::ostringstream message;
    message << "no answer within the call deadline of " << timeout_ << " s";
    status = grpc::Status(grpc::DEADLINE_EXCEEDED, message.str());
  }
  return failed("StepStream", status);
}

void Proxy::close_stream() {
  if (!stream_) return;
  watchdog_->arm(stream_context_.get(), timeout_);
  stream_->WritesDone();
  stream_->Finish();
  watchdog_->disarm();
  stream_.reset();
  stream_context_.reset();
}

void Proxy::terminate(const char* reason) {
  if (!initialized_ || terminated_ || !stub_) return;
  terminated_ = true;
  pb::TerminateRequest request;
  request.set_reason(reason);
  request.set_run_id(run_id_);
  request.set_run_secret(run_secret_);
  pb::TerminateResponse response;
  grpc::ClientContext context;
  prepare(&context);
  grpc::Status status = stub_->Terminate(&context, request, &response);
  if (!status.ok()) failed("Terminate", status);
  close_stream();
}

void Proxy::reset() {
  terminate("the FMU was reset");
  initialized_ = terminated_ = false;
}

void Proxy::keep(const google::protobuf::RepeatedPtrField<pb::VariableBinding>& outputs) {
  for (const auto& b : outputs) {
    auto found = by_name_.find(b.channel());
    if (found == by_name_.end()) continue;
    Channel& c = channels_[found->second];
    switch (b.value_case()) {
      case pb::VariableBinding::kReal: c.real = b.real(); break;
      case pb::VariableBinding::kInteger: c.integer = b.integer(); break;
      case pb::VariableBinding::kBoolean: c.boolean = b.boolean(); break;
      case pb::VariableBinding::kText: c.bytes = b.text(); break;
      case pb::VariableBinding::kBinary: c.bytes = b.binary(); break;
      default: break;
    }
  }
}

Channel* Proxy::find(unsigned vr) {
  auto found = by_vr_.find(vr);
  return found == by_vr_.end() ? nullptr : &channels_[found->second];
}

}  // namespace coupler_proxy
