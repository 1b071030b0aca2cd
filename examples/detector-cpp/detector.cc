// A balise detector in C++, written from proto/coupler/v1/*.proto and their comments alone:
// a Coupler participant that takes camera frames (coupler.v1.Image, rgb8) on its input `image`
// and answers the balises it sees in each (coupler.v1.BaliseDetections) on `detections`.
//
// The detector: balise-yellow pixels (red and green strong, blue weak), blobs of 8-connected
// yellow pixels, each blob's distance ahead from the ground-plane geometry of the frame's
// intrinsics and the camera's mounting (parameters camera_height, camera_pitch): the blob's
// lowest row is the balise's near bottom edge on the plane of the sleepers' tops (0.172 m below
// the rails), its highest row the far top edge (0.072 m below); the distance is the mean of
// where the two rows' rays meet their planes. Nothing farther than max_range; at most
// max_detections a frame, the nearest (BaliseDetections.omitted counts the rest). Track
// position = track_offset + the train's distance travelled (input train_state) + distance.
//
// The protocol's rules (docs/protocol.md): one run at a time; the run id and the run secret on
// every call of a run, the secret compared in constant time; a call with the run's id but not
// its secret refused PERMISSION_DENIED and remembered, the owner's next call answered ABORTED;
// a lease of at most 24 h after which a silent run ends; finite times; Terminate idempotent.
// The standard gRPC health service answers SERVING once it listens.
//
//   balise-detector [--port N | --socket PATH] [--host H]
// prints "balise-detector listening at grpc://HOST:PORT" (or unix:///PATH) when it serves.

#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "coupler/v1/component.grpc.pb.h"
#include "coupler/v1/railway.pb.h"
#include "coupler/v1/sensors.pb.h"

namespace pb = coupler::v1;
using grpc::ServerContext;
using grpc::Status;
using grpc::StatusCode;
using Clock = std::chrono::steady_clock;

namespace {

const char* const kName = "Perception";
constexpr double kMaxLease = 86400.0;
constexpr double kDefaultLease = 60.0;
constexpr uint64_t kImageMax = 256 + 3840ull * 2160 * 3;  // 4K UHD rgb8 and the Image's fields
constexpr uint64_t kTrainStateMax = 128;
constexpr int kMaxDetectionsLimit = 10000;
constexpr double kBottomBelowRails = 0.172;  // the sleepers' top, below the top of the rails
constexpr double kTopBelowRails = 0.072;     // a Eurobalise's top

// ---- the detector ---------------------------------------------------------------------------

struct Camera {
  double fx, fy, cx, cy;
  double height_m, pitch_deg;
};

struct Detection {
  int left, top, right, bottom;
  double distance_m, lateral_m, confidence;
};

bool Yellow(const uint8_t* p) {
  int r = p[0], g = p[1], b = p[2];
  return r > 110 && g > 80 && r - b > 90 && g - b > 60 && g <= r && g * 10 >= r * 6;
}

// Where the ray through pixel (u, v) meets the plane `depth` below the camera: distance ahead
// along the ground and lateral offset; false above the horizon.
bool Ground(double u, double v, double depth, const Camera& c, double* ahead_m, double* lateral) {
  double x = (u - c.cx) / c.fx, y = (v - c.cy) / c.fy;
  double pitch = c.pitch_deg * M_PI / 180.0;
  double down = y * std::cos(pitch) + std::sin(pitch);
  double ahead = -y * std::sin(pitch) + std::cos(pitch);
  if (down <= 1e-9) return false;
  double t = depth / down;
  *ahead_m = std::hypot(x * t, ahead * t);
  *lateral = x * t;
  return true;
}

// Every balise-like blob within max_range, nearest first; `all` counts those in range.
std::vector<Detection> Detect(const uint8_t* rgb, int width, int height, const Camera& camera,
                              double max_range, int min_pixels, size_t* all) {
  std::vector<int32_t> label(static_cast<size_t>(width) * height, 0);
  std::vector<Detection> found;
  std::vector<int32_t> stack;
  int32_t next = 0;
  for (int row = 0; row < height; ++row) {
    for (int col = 0; col < width; ++col) {
      size_t at = static_cast<size_t>(row) * width + col;
      if (label[at] || !Yellow(rgb + at * 3)) continue;
      ++next;  // a new blob: flood it (8-neighbourhood)
      int top = row, bottom = row, left = col, right = col, pixels = 0;
      label[at] = next;
      stack.assign(1, static_cast<int32_t>(at));
      while (!stack.empty()) {
        int32_t here = stack.back();
        stack.pop_back();
        ++pixels;
        int r = here / width, c = here % width;
        top = std::min(top, r), bottom = std::max(bottom, r);
        left = std::min(left, c), right = std::max(right, c);
        for (int dr = -1; dr <= 1; ++dr) {
          for (int dc = -1; dc <= 1; ++dc) {
            int rr = r + dr, cc = c + dc;
            if (rr < 0 || rr >= height || cc < 0 || cc >= width) continue;
            size_t there = static_cast<size_t>(rr) * width + cc;
            if (!label[there] && Yellow(rgb + there * 3)) {
              label[there] = next;
              stack.push_back(static_cast<int32_t>(there));
            }
          }
        }
      }
      if (pixels < min_pixels) continue;
      double u = (left + right) / 2.0, near_m, near_x, far_m, far_x;
      if (!Ground(u, bottom + 0.5, camera.height_m + kBottomBelowRails, camera, &near_m,
                  &near_x) ||
          !Ground(u, top - 0.5, camera.height_m + kTopBelowRails, camera, &far_m, &far_x)) {
        continue;
      }
      double distance = (near_m + far_m) / 2.0;
      if (distance > max_range) continue;
      double expected = 0.52 * camera.fx / std::max(distance, 1.0);  // a balise's width
      double confidence = std::min(1.0, (right - left + 1) / std::max(expected, 1.0));
      found.push_back({left, top, right, bottom, distance, (near_x + far_x) / 2.0,
                       std::round(confidence * 1000.0) / 1000.0});
    }
  }
  std::stable_sort(found.begin(), found.end(), [](const Detection& a, const Detection& b) {
    return a.distance_m < b.distance_m;
  });
  *all = found.size();
  return found;
}

// ---- the participant ------------------------------------------------------------------------

double Round3(double x) { return std::round(x * 1000.0) / 1000.0; }

pb::ChannelDescription Channel(const std::string& name, pb::Causality causality,
                               pb::ValueType type, const std::string& unit,
                               const std::string& description) {
  pb::ChannelDescription channel;
  channel.set_name(name);
  channel.set_causality(causality);
  channel.set_type(type);
  channel.set_unit(unit);
  channel.set_description(description);
  return channel;
}

struct Run {
  std::string id, secret;
  double lease = kDefaultLease;
  Clock::time_point last_call;
  double reached = 0;
  std::string intrusion;
  int intrusions = 0;
  std::map<std::string, double> reals;
  int max_detections = 64;
  int min_pixels = 2;
  std::string image, train_state;
};

bool SameSecret(const std::string& given, const std::string& expected) {
  if (given.size() != expected.size()) return false;
  unsigned char differ = 0;  // constant time in the content
  for (size_t i = 0; i < given.size(); ++i) differ |= given[i] ^ expected[i];
  return differ == 0;
}

std::string Number(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", x);
  return text;
}

class Detector final : public pb::GRPCComponentService::Service {
 public:
  Status Describe(ServerContext*, const pb::DescribeRequest*,
                  pb::DescribeResponse* response) override {
    response->set_name(kName);
    response->set_implementation("examples/detector-cpp (C++, yellow blobs, ground plane)");
    response->mutable_capabilities()->set_variable_step_size(true);
    using C = pb::Causality;
    using T = pb::ValueType;
    auto* image = response->add_channels();
    *image = Channel("image", C::CAUSALITY_INPUT, T::VALUE_TYPE_BINARY, "",
                     "Camera frame (coupler.v1.Image, rgb8, up to 3840 x 2160)");
    image->set_message_type("coupler.v1.Image");
    image->set_max_bytes(kImageMax);
    image->mutable_start()->set_channel("image");
    image->mutable_start()->set_binary("");
    auto* state = response->add_channels();
    *state = Channel("train_state", C::CAUSALITY_INPUT, T::VALUE_TYPE_BINARY, "",
                     "Train state of the frame's time: distance travelled");
    state->set_message_type("coupler.v1.TrainState");
    state->set_max_bytes(kTrainStateMax);
    state->mutable_start()->set_channel("train_state");
    state->mutable_start()->set_binary("");
    for (const auto& [name, unit, start, text] : kReals) {
      auto* channel = response->add_channels();
      *channel = Channel(name, C::CAUSALITY_PARAMETER, T::VALUE_TYPE_REAL, unit, text);
      channel->mutable_start()->set_channel(name);
      channel->mutable_start()->set_real(start);
    }
    for (const auto& [name, start, text] : kIntegers) {
      auto* channel = response->add_channels();
      *channel = Channel(name, C::CAUSALITY_PARAMETER, T::VALUE_TYPE_INTEGER, "", text);
      channel->mutable_start()->set_channel(name);
      channel->mutable_start()->set_integer(start);
    }
    auto* detections = response->add_channels();
    *detections = Channel("detections", C::CAUSALITY_OUTPUT, T::VALUE_TYPE_BINARY, "",
                          "Every balise found in the last frame (coupler.v1.BaliseDetections)");
    detections->set_message_type("coupler.v1.BaliseDetections");
    *response->add_channels() = Channel("detection_count", C::CAUSALITY_OUTPUT,
                                        T::VALUE_TYPE_INTEGER, "", "How many balises");
    return Status::OK;
  }

  Status Initialize(ServerContext*, const pb::InitializeRequest* request,
                    pb::InitializeResponse* response) override {
    std::lock_guard<std::mutex> lock(mutex_);
    Expire();
    if (run_) {
      return Status(StatusCode::FAILED_PRECONDITION,
                    std::string("participant '") + kName +
                        "' is in another run; a participant serves one run at a time");
    }
    const std::string& secret = request->run_secret();
    if (secret.size() < 16 || secret.size() > 256) {
      return Status(StatusCode::INVALID_ARGUMENT, "run_secret must be 16 to 256 random bytes, got " +
                                                      std::to_string(secret.size()));
    }
    double lease = request->lease_seconds();
    if (lease != 0 && !(lease > 0 && lease <= kMaxLease)) {
      return Status(StatusCode::INVALID_ARGUMENT,
                    "lease_seconds must be a number of seconds > 0 and <= 86400 (24 h), got " +
                        Number(lease));
    }
    if (!std::isfinite(request->start_time()) || !std::isfinite(request->step_size()) ||
        (request->has_stop_time() && !std::isfinite(request->stop_time()))) {
      return Status(StatusCode::INVALID_ARGUMENT, "start_time, step_size and stop_time must be finite");
    }
    Run run;
    run.id = request->run_id();
    run.secret = secret;
    run.lease = lease ? lease : kDefaultLease;
    run.last_call = Clock::now();
    run.reached = request->start_time();
    for (const auto& [name, unit, start, text] : kReals) run.reals[name] = start;
    for (const auto& binding : request->parameters()) {
      Status refused = Parameter(binding, &run);
      if (!refused.ok()) return refused;
    }
    for (const auto& binding : request->inputs()) {
      Status refused = Input(binding, &run);
      if (!refused.ok()) return refused;
    }
    pb::DoStepResponse answer;
    Status perceived = Perceive(run, &answer);
    if (!perceived.ok()) return perceived;
    *response->mutable_outputs() = answer.outputs();
    run_ = std::move(run);
    std::cerr << "run_initialized run_id=" << run_->id << " lease_s=" << run_->lease << "\n";
    return Status::OK;
  }

  Status DoStep(ServerContext* context, const pb::DoStepRequest* request,
                pb::DoStepResponse* response) override {
    std::lock_guard<std::mutex> lock(mutex_);
    Expire();
    Status owned = OfTheRun(request->run_id(), request->run_secret(), "DoStep", context->peer());
    if (!owned.ok()) return owned;
    if (!run_->intrusion.empty()) return Status(StatusCode::ABORTED, Refusal());
    if (!(request->step_size() > 0) || !std::isfinite(request->step_size()) ||
        !std::isfinite(request->current_time())) {
      return Status(StatusCode::INVALID_ARGUMENT,
                    "step_size must be finite and positive and current_time finite, got "
                    "step_size=" + Number(request->step_size()) +
                        ", current_time=" + Number(request->current_time()));
    }
    for (const auto& binding : request->inputs()) {
      Status refused = Input(binding, &*run_);
      if (!refused.ok()) return refused;
    }
    run_->last_call = Clock::now();
    run_->reached = request->current_time() + request->step_size();
    return Perceive(*run_, response);
  }

  Status Terminate(ServerContext* context, const pb::TerminateRequest* request,
                   pb::TerminateResponse*) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!run_) return Status::OK;  // a run that has already ended: Terminate is idempotent
    Status owned =
        OfTheRun(request->run_id(), request->run_secret(), "Terminate", context->peer());
    if (!owned.ok()) return owned;
    std::string intrusion = run_->intrusion;
    std::string refusal = Refusal();
    std::cerr << "run_terminated run_id=" << run_->id << " reason=" << request->reason() << "\n";
    run_.reset();
    if (!intrusion.empty()) return Status(StatusCode::ABORTED, refusal);
    return Status::OK;
  }

 private:
  struct Real {
    const char* name;
    const char* unit;
    double start;
    const char* text;
  };
  struct Integer {
    const char* name;
    int start;
    const char* text;
  };
  static constexpr Real kReals[] = {
      {"camera_height", "m", 2.5, "Camera above the top of the rails"},
      {"camera_pitch", "deg", 4.0, "Camera pitched down from the track's direction"},
      {"track_offset", "m", 0.0, "Camera's position along the line at 0 m travelled"},
      {"max_range", "m", 40.0, "Balises farther ahead are not reported"},
  };
  static constexpr Integer kIntegers[] = {
      {"min_pixels", 2, "Smallest yellow blob taken for a balise [pixels]"},
      {"max_detections", 64, "Detections reported per frame at most (the nearest)"},
  };

  // A silent run past its lease ends (a dead orchestrator never locks the participant).
  void Expire() {
    if (!run_) return;
    double silent = std::chrono::duration<double>(Clock::now() - run_->last_call).count();
    if (silent > run_->lease) {
      std::cerr << "run_ended run_id=" << run_->id << " why=lease expired\n";
      run_.reset();
    }
  }

  std::string Refusal() const {
    int more = run_->intrusions - 1;
    return run_->intrusion +
           (more > 0 ? " (" + std::to_string(more) + " more such calls since)" : "");
  }

  Status OfTheRun(const std::string& id, const std::string& secret, const std::string& call,
                  const std::string& peer) {
    if (!run_) {
      return Status(StatusCode::FAILED_PRECONDITION,
                    call + " before Initialize: participant '" + kName + "' has no run");
    }
    if (id != run_->id) {
      return Status(StatusCode::FAILED_PRECONDITION,
                    call + " for run '" + id + "', which is not participant '" + kName +
                        "'s active run");
    }
    if (!SameSecret(secret, run_->secret)) {
      run_->intrusions += 1;
      if (run_->intrusion.empty()) {
        run_->intrusion = std::string(kName) + " refused the run: a call " +
                          (secret.empty() ? "without this run's secret" : "with a wrong secret") +
                          " arrived from " + peer + " (" + call + " at t=" +
                          Number(run_->reached) + " s); the run is no longer trusted";
      }
      return Status(StatusCode::PERMISSION_DENIED,
                    call + " refused: it names participant '" + kName +
                        "'s active run but does not carry that run's secret");
    }
    return Status::OK;
  }

  static Status Parameter(const pb::VariableBinding& binding, Run* run) {
    const std::string& name = binding.channel();
    if (run->reals.count(name)) {
      if (binding.value_case() != pb::VariableBinding::kReal || !std::isfinite(binding.real())) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "parameter '" + name + "' is Real: give a finite number");
      }
      run->reals[name] = binding.real();
      return Status::OK;
    }
    if (name == "min_pixels" || name == "max_detections") {
      if (binding.value_case() != pb::VariableBinding::kInteger) {
        return Status(StatusCode::INVALID_ARGUMENT, "parameter '" + name + "' is Integer");
      }
      int value = binding.integer();
      if (name == "max_detections" && (value < 1 || value > kMaxDetectionsLimit)) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "parameter 'max_detections' is " + std::to_string(value) +
                          "; it bounds the detections of one frame: give 1 to 10000");
      }
      (name == "min_pixels" ? run->min_pixels : run->max_detections) = value;
      return Status::OK;
    }
    return Status(StatusCode::INVALID_ARGUMENT,
                  "unknown parameter '" + name + "' (its parameters: camera_height, "
                  "camera_pitch, track_offset, max_range, min_pixels, max_detections)");
  }

  static Status Input(const pb::VariableBinding& binding, Run* run) {
    const std::string& name = binding.channel();
    if (name != "image" && name != "train_state") {
      return Status(StatusCode::INVALID_ARGUMENT,
                    "unknown input '" + name + "' (its inputs: image, train_state)");
    }
    if (binding.value_case() != pb::VariableBinding::kBinary) {
      return Status(StatusCode::INVALID_ARGUMENT, "input '" + name + "' is Binary");
    }
    uint64_t limit = name == "image" ? kImageMax : kTrainStateMax;
    if (binding.binary().size() > limit) {
      return Status(StatusCode::RESOURCE_EXHAUSTED,
                    "input '" + name + "' carries " + std::to_string(binding.binary().size()) +
                        " bytes, over its declared maximum of " + std::to_string(limit) +
                        " bytes");
    }
    (name == "image" ? run->image : run->train_state) = binding.binary();
    return Status::OK;
  }

  // The detections of the run's current frame, into `response`'s outputs.
  static Status Perceive(const Run& run, pb::DoStepResponse* response) {
    pb::BaliseDetections message;
    if (!run.image.empty()) {
      pb::Image image;
      if (!image.ParseFromString(run.image)) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "channel 'image' carries " + std::to_string(run.image.size()) +
                          " bytes that are not a coupler.v1.Image");
      }
      if (image.encoding() != "rgb8") {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "channel 'image' carries a '" + image.encoding() + "' frame of sensor '" +
                          image.sensor() + "'; the detector reads 'rgb8'");
      }
      uint64_t size = static_cast<uint64_t>(image.width()) * image.height() * 3;
      if (image.data().size() != size) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "channel 'image': sensor '" + image.sensor() + "' declares " +
                          std::to_string(image.width()) + " x " + std::to_string(image.height()) +
                          " rgb8 (" + std::to_string(size) + " bytes) but its data has " +
                          std::to_string(image.data().size()) + " bytes");
      }
      const auto& k = image.intrinsics();
      if (!(std::isfinite(k.fx()) && k.fx() > 0 && std::isfinite(k.fy()) && k.fy() > 0 &&
            std::isfinite(k.cx()) && std::isfinite(k.cy()))) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "channel 'image': sensor '" + image.sensor() +
                          "' has intrinsics no camera has (fx, fy finite and positive; cx, cy "
                          "finite)");
      }
      pb::TrainState state;
      if (!state.ParseFromString(run.train_state)) {
        return Status(StatusCode::INVALID_ARGUMENT,
                      "channel 'train_state' carries bytes that are not a coupler.v1.TrainState");
      }
      Camera camera{k.fx(), k.fy(), k.cx(), k.cy(), run.reals.at("camera_height"),
                    run.reals.at("camera_pitch")};
      size_t all = 0;
      auto found = Detect(reinterpret_cast<const uint8_t*>(image.data().data()),
                          static_cast<int>(image.width()), static_cast<int>(image.height()),
                          camera, run.reals.at("max_range"), run.min_pixels, &all);
      size_t shown = std::min(found.size(), static_cast<size_t>(run.max_detections));
      double camera_at = run.reals.at("track_offset") + state.distance_m();
      message.set_time_s(image.time_s());
      message.set_sensor(image.sensor());
      message.set_omitted(static_cast<uint32_t>(all - shown));
      for (size_t i = 0; i < shown; ++i) {
        const Detection& d = found[i];
        auto* out = message.add_detections();
        out->set_time_s(image.time_s());
        out->mutable_box()->set_left(d.left);
        out->mutable_box()->set_top(d.top);
        out->mutable_box()->set_right(d.right);
        out->mutable_box()->set_bottom(d.bottom);
        out->set_distance_ahead_m(Round3(d.distance_m));
        out->set_track_position_m(Round3(camera_at + d.distance_m));
        out->set_confidence(d.confidence);
      }
    }
    auto* detections = response->add_outputs();
    detections->set_channel("detections");
    std::string bytes;
    message.SerializeToString(&bytes);
    detections->set_binary(bytes);
    auto* count = response->add_outputs();
    count->set_channel("detection_count");
    count->set_integer(message.detections_size());
    return Status::OK;
  }

  std::mutex mutex_;
  std::optional<Run> run_;
};

std::unique_ptr<grpc::Server>* g_server = nullptr;

void Stop(int) {
  if (g_server && *g_server) {
    std::thread([] { (*g_server)->Shutdown(); }).detach();
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string host = "127.0.0.1", port = "0", socket;
  for (int i = 1; i + 1 < argc; i += 2) {
    std::string option = argv[i];
    if (option == "--host") host = argv[i + 1];
    else if (option == "--port") port = argv[i + 1];
    else if (option == "--socket") socket = argv[i + 1];
    else {
      std::cerr << "balise-detector: unknown option " << option
                << " (options: --host H, --port N, --socket PATH)\n";
      return 2;
    }
  }
  grpc::EnableDefaultHealthCheckService(true);
  Detector detector;
  grpc::ServerBuilder builder;
  int bound = 0;
  std::string address = socket.empty() ? host + ":" + port : "unix:" + socket;
  builder.AddListeningPort(address, grpc::InsecureServerCredentials(), &bound);
  builder.RegisterService(&detector);
  builder.SetMaxReceiveMessageSize(static_cast<int>(kImageMax + kTrainStateMax + (8 << 20)));
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  if (!server || (socket.empty() && bound == 0)) {
    std::cerr << "balise-detector: cannot listen at " << address << "\n";
    return 1;
  }
  g_server = &server;
  std::signal(SIGTERM, Stop);
  std::signal(SIGINT, Stop);
  std::cout << "balise-detector listening at "
            << (socket.empty() ? "grpc://" + host + ":" + std::to_string(bound)
                               : "unix://" + socket)
            << std::endl;
  server->Wait();
  return 0;
}
