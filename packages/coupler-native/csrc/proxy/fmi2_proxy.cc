// The FMI 2.0 co-simulation face of an exported FMU (`coupler export-fmu --fmi 2`): every FMI
// call becomes a call of the participant's GRPCComponentService through coupler_proxy::Proxy.
//
//   fmi2Instantiate            -> connect, Describe; the description must be the exported one
//   fmi2ExitInitializationMode -> Initialize (parameters and start inputs; a new run id)
//   fmi2DoStep                 -> DoStep (the inputs; the outputs kept for fmi2Get*)
//   fmi2Terminate, FreeInstance-> Terminate
//
// Every failure is fmi2Error with a message through the FMU's logger (category
// logStatusError) naming the participant's address, the call and the gRPC status.

#include <cstdarg>
#include <cstdio>
#include <string>

#include "fmi2Functions.h"
#include "proxy_core.h"

namespace {

using coupler_proxy::ADDRESS_VR;
using coupler_proxy::Channel;
using coupler_proxy::Kind;
using coupler_proxy::StepResult;

struct Instance {
  std::string name;
  fmi2CallbackFunctions callbacks{};
  bool logging = false;
  double start_time = 0.0;
  bool stop_defined = false;
  double stop_time = 0.0;
  std::unique_ptr<coupler_proxy::Proxy> proxy;
};

void log(Instance* inst, fmi2Status status, const std::string& message) {
  if (inst->callbacks.logger == nullptr) return;
  if (status == fmi2OK && !inst->logging) return;
  // the logger reads the message as a format string: escape every '%'
  std::string safe;
  for (char c : message) {
    safe += c;
    if (c == '%') safe += '%';
  }
  inst->callbacks.logger(inst->callbacks.componentEnvironment, inst->name.c_str(), status,
                         status == fmi2OK ? "logAll" : "logStatusError", safe.c_str());
}

Instance* instance(fmi2Component c) { return static_cast<Instance*>(c); }

template <typename T, typename Read>
fmi2Status get(fmi2Component c, const fmi2ValueReference vr[], size_t n, T value[], Kind kind,
               Read read) {
  return coupler_proxy::read_values(*instance(c)->proxy, vr, n, value, kind, read) ? fmi2OK
                                                                                  : fmi2Error;
}

template <typename T, typename Write>
fmi2Status set(fmi2Component c, const fmi2ValueReference vr[], size_t n, const T value[],
               Kind kind, Write write) {
  return coupler_proxy::write_values(*instance(c)->proxy, vr, n, value, kind, write)
             ? fmi2OK
             : fmi2Error;
}

}  // namespace

extern "C" {

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t, const fmi2String[]) {
  instance(c)->logging = on;
  return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions* callbacks,
                              fmi2Boolean, fmi2Boolean logging) {
  auto* inst = new Instance();
  inst->name = name ? name : "proxy";
  if (callbacks) inst->callbacks = *callbacks;
  inst->logging = logging;
  inst->proxy = std::make_unique<coupler_proxy::Proxy>([inst](bool error, const std::string& m) {
    log(inst, error ? fmi2Error : fmi2OK, m);
  });
  bool ok = true;
  if (type != fmi2CoSimulation) {
    log(inst, fmi2Error, "this FMU supports co-simulation only");
    ok = false;
  }
  ok = ok && inst->proxy->load(resources ? resources : "");
  std::string expected = "{coupler-proxy-" + inst->proxy->fingerprint() + "}";
  if (ok && (guid == nullptr || expected != guid)) {
    log(inst, fmi2Error, std::string("GUID ") + (guid ? guid : "(none)") +
                             " does not belong to this binary's resources (" + expected + ")");
    ok = false;
  }
  if (!ok || !inst->proxy->connect()) {
    delete inst;
    return nullptr;
  }
  return inst;
}

void fmi2FreeInstance(fmi2Component c) { delete instance(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean, fmi2Real, fmi2Real start,
                               fmi2Boolean stop_defined, fmi2Real stop) {
  auto* inst = instance(c);
  inst->start_time = start;
  inst->stop_defined = stop_defined;
  inst->stop_time = stop;
  return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component) { return fmi2OK; }

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  auto* inst = instance(c);
  std::optional<double> stop;
  if (inst->stop_defined) stop = inst->stop_time;
  return inst->proxy->initialize(inst->start_time, stop) ? fmi2OK : fmi2Error;
}

fmi2Status fmi2Terminate(fmi2Component c) {
  instance(c)->proxy->terminate("the FMU was terminated");
  return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
  instance(c)->proxy->reset();
  return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real time, fmi2Real step, fmi2Boolean) {
  auto* inst = instance(c);
  switch (inst->proxy->step(time, step)) {
    case StepResult::OK: return fmi2OK;
    case StepResult::TERMINATED:
      // FMI 2: a step the FMU cannot complete as asked, and fmi2Terminated from GetBooleanStatus
      log(inst, fmi2Discard, "the participant ended the run");
      return fmi2Discard;
    default: return fmi2Error;
  }
}

fmi2Status fmi2CancelStep(fmi2Component) { return fmi2Error; }

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       fmi2Real value[]) {
  return get(c, vr, n, value, Kind::REAL, [](const Channel& ch) { return ch.real; });
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Integer value[]) {
  return get(c, vr, n, value, Kind::INTEGER, [](const Channel& ch) { return ch.integer; });
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          fmi2Boolean value[]) {
  return get(c, vr, n, value, Kind::BOOLEAN,
             [](const Channel& ch) { return ch.boolean ? fmi2True : fmi2False; });
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         fmi2String value[]) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    if (vr[i] == ADDRESS_VR) {
      value[i] = inst->proxy->address().c_str();
      continue;
    }
    fmi2Status status = get(c, vr + i, 1, value + i, Kind::STRING,
                            [](const Channel& ch) { return ch.bytes.c_str(); });
    if (status != fmi2OK) return status;
  }
  return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
  return set(c, vr, n, value, Kind::REAL, [](Channel& ch, fmi2Real v) { ch.real = v; });
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Integer value[]) {
  return set(c, vr, n, value, Kind::INTEGER, [](Channel& ch, fmi2Integer v) { ch.integer = v; });
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                          const fmi2Boolean value[]) {
  return set(c, vr, n, value, Kind::BOOLEAN,
             [](Channel& ch, fmi2Boolean v) { ch.boolean = v != fmi2False; });
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                         const fmi2String value[]) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    if (vr[i] == ADDRESS_VR) {
      std::string address = value[i] ? value[i] : "";
      if (address == inst->proxy->address()) continue;
      if (!inst->proxy->set_address(address)) return fmi2Error;
      continue;
    }
    fmi2Status status = set(c, vr + i, 1, value + i, Kind::STRING,
                            [](Channel& ch, fmi2String v) { ch.bytes = v ? v : ""; });
    if (status != fmi2OK) return status;
  }
  return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Boolean* value) {
  if (kind != fmi2Terminated) return fmi2Discard;
  auto* inst = instance(c);
  *value = inst->proxy->ended() ? fmi2True : fmi2False;
  return fmi2OK;
}

// Not supported by a proxy (no FMU state, no derivatives, no asynchronous steps).
fmi2Status fmi2GetFMUstate(fmi2Component, fmi2FMUstate*) { return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component, fmi2FMUstate) { return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component, fmi2FMUstate*) { return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component, fmi2FMUstate, size_t*) { return fmi2Error; }
fmi2Status fmi2SerializeFMUstate(fmi2Component, fmi2FMUstate, fmi2Byte[], size_t) {
  return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component, const fmi2Byte[], size_t, fmi2FMUstate*) {
  return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component, const fmi2ValueReference[], size_t,
                                        const fmi2ValueReference[], size_t, const fmi2Real[],
                                        fmi2Real[]) {
  return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component, const fmi2ValueReference[], size_t,
                                       const fmi2Integer[], const fmi2Real[]) {
  return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component, const fmi2ValueReference[], size_t,
                                        const fmi2Integer[], fmi2Real[]) {
  return fmi2Error;
}
fmi2Status fmi2GetStatus(fmi2Component, const fmi2StatusKind, fmi2Status*) { return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real* value) {
  if (kind != fmi2LastSuccessfulTime) return fmi2Discard;
  *value = instance(c)->proxy->time();  // the end of the last step the participant made
  return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component, const fmi2StatusKind, fmi2Integer*) {
  return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component, const fmi2StatusKind, fmi2String*) {
  return fmi2Discard;
}

}  // extern "C"
