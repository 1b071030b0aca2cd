// The FMI 3.0 co-simulation face of an exported FMU (`coupler export-fmu --fmi 3`): every FMI
// call becomes a call of the participant's GRPCComponentService through coupler_proxy::Proxy.
//
//   fmi3InstantiateCoSimulation -> connect, Describe; the description must be the exported one
//   fmi3ExitInitializationMode  -> Initialize (parameters and start inputs; a new run id)
//   fmi3DoStep                  -> DoStep (the inputs; the outputs kept for fmi3Get*); a
//                                  participant ending the run sets terminateSimulation
//   fmi3Terminate, FreeInstance -> Terminate
//
// Channels are Float64 (Real), Int32 (Integer, Enumeration), Boolean, String and Binary. Every
// failure is fmi3Error with a message through the FMU's logger (category logStatusError)
// naming the participant's address, the call and the gRPC status.

#include <optional>
#include <string>

#include "fmi3Functions.h"
#include "proxy_core.h"

namespace {

using coupler_proxy::ADDRESS_VR;
using coupler_proxy::Channel;
using coupler_proxy::Kind;
using coupler_proxy::StepResult;

struct Instance {
  std::string name;
  fmi3InstanceEnvironment environment = nullptr;
  fmi3LogMessageCallback logger = nullptr;
  bool logging = false;
  double start_time = 0.0;
  std::optional<double> stop_time;
  std::unique_ptr<coupler_proxy::Proxy> proxy;
};

void log(Instance* inst, fmi3Status status, const std::string& message) {
  if (inst->logger == nullptr) return;
  if (status == fmi3OK && !inst->logging) return;
  inst->logger(inst->environment, status, status == fmi3OK ? "logAll" : "logStatusError",
               message.c_str());
}

Instance* instance(fmi3Instance c) { return static_cast<Instance*>(c); }

template <typename T, typename Read>
fmi3Status get(fmi3Instance c, const fmi3ValueReference vr[], size_t n, T value[], Kind kind,
               Read read) {
  return coupler_proxy::read_values(*instance(c)->proxy, vr, n, value, kind, read) ? fmi3OK
                                                                                  : fmi3Error;
}

template <typename T, typename Write>
fmi3Status set(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const T value[],
               Kind kind, Write write) {
  return coupler_proxy::write_values(*instance(c)->proxy, vr, n, value, kind, write)
             ? fmi3OK
             : fmi3Error;
}

}  // namespace

extern "C" {

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t, const fmi3String[]) {
  instance(c)->logging = on;
  return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean, fmi3Boolean logging,
    fmi3Boolean, fmi3Boolean, const fmi3ValueReference[], size_t,
    fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger,
    fmi3IntermediateUpdateCallback) {
  auto* inst = new Instance();
  inst->name = name ? name : "proxy";
  inst->environment = environment;
  inst->logger = logger;
  inst->logging = logging;
  inst->proxy = std::make_unique<coupler_proxy::Proxy>([inst](bool error, const std::string& m) {
    log(inst, error ? fmi3Error : fmi3OK, m);
  });
  bool ok = inst->proxy->load(resources ? resources : "");
  std::string expected = "{coupler-proxy-" + inst->proxy->fingerprint() + "}";
  if (ok && (token == nullptr || expected != token)) {
    log(inst, fmi3Error, std::string("instantiation token ") + (token ? token : "(none)") +
                             " does not belong to this binary's resources (" + expected + ")");
    ok = false;
  }
  if (!ok || !inst->proxy->connect()) {
    delete inst;
    return nullptr;
  }
  return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String, fmi3String, fmi3String, fmi3Boolean,
                                          fmi3Boolean, fmi3InstanceEnvironment environment,
                                          fmi3LogMessageCallback logger) {
  if (logger)
    logger(environment, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
  return nullptr;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String, fmi3String, fmi3String, fmi3Boolean,
                                               fmi3Boolean, fmi3InstanceEnvironment environment,
                                               fmi3LogMessageCallback logger,
                                               fmi3ClockUpdateCallback,
                                               fmi3LockPreemptionCallback,
                                               fmi3UnlockPreemptionCallback) {
  if (logger)
    logger(environment, fmi3Error, "logStatusError", "this FMU supports co-simulation only");
  return nullptr;
}

void fmi3FreeInstance(fmi3Instance c) { delete instance(c); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean, fmi3Float64,
                                       fmi3Float64 start, fmi3Boolean stop_defined,
                                       fmi3Float64 stop) {
  auto* inst = instance(c);
  inst->start_time = start;
  inst->stop_time.reset();
  if (stop_defined) inst->stop_time = stop;
  return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) {
  auto* inst = instance(c);
  return inst->proxy->initialize(inst->start_time, inst->stop_time) ? fmi3OK : fmi3Error;
}

fmi3Status fmi3EnterStepMode(fmi3Instance) { return fmi3OK; }

fmi3Status fmi3Terminate(fmi3Instance c) {
  instance(c)->proxy->terminate("the FMU was terminated");
  return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
  instance(c)->proxy->reset();
  return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 time, fmi3Float64 step, fmi3Boolean,
                      fmi3Boolean* event_handling_needed, fmi3Boolean* terminate_simulation,
                      fmi3Boolean* early_return, fmi3Float64* last_successful_time) {
  auto* inst = instance(c);
  if (event_handling_needed) *event_handling_needed = fmi3False;
  if (terminate_simulation) *terminate_simulation = fmi3False;
  if (early_return) *early_return = fmi3False;
  switch (inst->proxy->step(time, step)) {
    case StepResult::OK:
      if (last_successful_time) *last_successful_time = time + step;
      return fmi3OK;
    case StepResult::TERMINATED:
      if (last_successful_time) *last_successful_time = time + step;
      if (terminate_simulation) *terminate_simulation = fmi3True;
      return fmi3OK;
    default:
      if (last_successful_time) *last_successful_time = time;
      return fmi3Error;
  }
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          fmi3Float64 value[], size_t) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    if (inst->proxy->is_time(vr[i])) {
      value[i] = inst->proxy->time();
      continue;
    }
    fmi3Status status =
        get(c, vr + i, 1, value + i, Kind::REAL, [](const Channel& ch) { return ch.real; });
    if (status != fmi3OK) return status;
  }
  return fmi3OK;
}
fmi3Status fmi3GetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                        fmi3Int32 value[], size_t) {
  return get(c, vr, n, value, Kind::INTEGER, [](const Channel& ch) { return ch.integer; });
}
fmi3Status fmi3GetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          fmi3Boolean value[], size_t) {
  return get(c, vr, n, value, Kind::BOOLEAN,
             [](const Channel& ch) { return ch.boolean ? fmi3True : fmi3False; });
}
fmi3Status fmi3GetString(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                         fmi3String value[], size_t) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    if (vr[i] == ADDRESS_VR) {
      value[i] = inst->proxy->address().c_str();
      continue;
    }
    fmi3Status status = get(c, vr + i, 1, value + i, Kind::STRING,
                            [](const Channel& ch) { return ch.bytes.c_str(); });
    if (status != fmi3OK) return status;
  }
  return fmi3OK;
}
fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                         size_t sizes[], fmi3Binary value[], size_t) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    Channel* ch = inst->proxy->find(vr[i]);
    if (ch == nullptr || ch->kind != Kind::BINARY) {
      log(inst, fmi3Error, "no Binary variable with value reference " + std::to_string(vr[i]));
      return fmi3Error;
    }
    sizes[i] = ch->bytes.size();
    value[i] = reinterpret_cast<fmi3Binary>(ch->bytes.data());
  }
  return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          const fmi3Float64 value[], size_t) {
  return set(c, vr, n, value, Kind::REAL, [](Channel& ch, fmi3Float64 v) { ch.real = v; });
}
fmi3Status fmi3SetInt32(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                        const fmi3Int32 value[], size_t) {
  return set(c, vr, n, value, Kind::INTEGER, [](Channel& ch, fmi3Int32 v) { ch.integer = v; });
}
fmi3Status fmi3SetBoolean(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          const fmi3Boolean value[], size_t) {
  return set(c, vr, n, value, Kind::BOOLEAN,
             [](Channel& ch, fmi3Boolean v) { ch.boolean = v != fmi3False; });
}
fmi3Status fmi3SetString(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                         const fmi3String value[], size_t) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    if (vr[i] == ADDRESS_VR) {
      std::string address = value[i] ? value[i] : "";
      if (address == inst->proxy->address()) continue;
      if (!inst->proxy->set_address(address)) return fmi3Error;
      continue;
    }
    fmi3Status status = set(c, vr + i, 1, value + i, Kind::STRING,
                            [](Channel& ch, fmi3String v) { ch.bytes = v ? v : ""; });
    if (status != fmi3OK) return status;
  }
  return fmi3OK;
}
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                         const size_t sizes[], const fmi3Binary value[], size_t) {
  auto* inst = instance(c);
  for (size_t i = 0; i < n; ++i) {
    Channel* ch = inst->proxy->find(vr[i]);
    if (ch == nullptr || ch->kind != Kind::BINARY || ch->causality == 2) {
      log(inst, fmi3Error, "no settable Binary variable with value reference " +
                               std::to_string(vr[i]));
      return fmi3Error;
    }
    ch->bytes.assign(reinterpret_cast<const char*>(value[i]), sizes[i]);
    ch->given = true;
  }
  return fmi3OK;
}

// Not supported by a proxy: other types, clocks, FMU state, derivatives, model exchange.
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance, fmi3ValueReference, size_t*) { return fmi3Error; }
fmi3Status fmi3GetVariableDependencies(fmi3Instance, fmi3ValueReference, size_t*, fmi3ValueReference*, size_t*, fmi3DependencyKind*, size_t) { return fmi3Error; }
fmi3Status fmi3EnterEventMode(fmi3Instance) { return fmi3Error; }
fmi3Status fmi3GetFloat32(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Float32*, size_t) { return fmi3Error; }
fmi3Status fmi3GetInt8(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Int8*, size_t) { return fmi3Error; }
fmi3Status fmi3GetUInt8(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt8*, size_t) { return fmi3Error; }
fmi3Status fmi3GetInt16(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Int16*, size_t) { return fmi3Error; }
fmi3Status fmi3GetUInt16(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt16*, size_t) { return fmi3Error; }
fmi3Status fmi3GetUInt32(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt32*, size_t) { return fmi3Error; }
fmi3Status fmi3GetInt64(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Int64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetUInt64(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetClock(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Clock*) { return fmi3Error; }
fmi3Status fmi3SetFloat32(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Float32*, size_t) { return fmi3Error; }
fmi3Status fmi3SetInt8(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Int8*, size_t) { return fmi3Error; }
fmi3Status fmi3SetUInt8(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt8*, size_t) { return fmi3Error; }
fmi3Status fmi3SetInt16(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Int16*, size_t) { return fmi3Error; }
fmi3Status fmi3SetUInt16(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt16*, size_t) { return fmi3Error; }
fmi3Status fmi3SetUInt32(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt32*, size_t) { return fmi3Error; }
fmi3Status fmi3SetInt64(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Int64*, size_t) { return fmi3Error; }
fmi3Status fmi3SetUInt64(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt64*, size_t) { return fmi3Error; }
fmi3Status fmi3SetClock(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Clock*) { return fmi3Error; }
fmi3Status fmi3GetFMUState(fmi3Instance, fmi3FMUState*) { return fmi3Error; }
fmi3Status fmi3SetFMUState(fmi3Instance, fmi3FMUState) { return fmi3Error; }
fmi3Status fmi3FreeFMUState(fmi3Instance, fmi3FMUState*) { return fmi3Error; }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance, fmi3FMUState, size_t*) { return fmi3Error; }
fmi3Status fmi3SerializeFMUState(fmi3Instance, fmi3FMUState, fmi3Byte*, size_t) { return fmi3Error; }
fmi3Status fmi3DeserializeFMUState(fmi3Instance, const fmi3Byte*, size_t, fmi3FMUState*) { return fmi3Error; }
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3ValueReference*, size_t, const fmi3Float64*, size_t, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetAdjointDerivative(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3ValueReference*, size_t, const fmi3Float64*, size_t, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3EnterConfigurationMode(fmi3Instance) { return fmi3Error; }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance) { return fmi3Error; }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Float64*, fmi3IntervalQualifier*) { return fmi3Error; }
fmi3Status fmi3GetIntervalFraction(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt64*, fmi3UInt64*, fmi3IntervalQualifier*) { return fmi3Error; }
fmi3Status fmi3GetShiftDecimal(fmi3Instance, const fmi3ValueReference*, size_t, fmi3Float64*) { return fmi3Error; }
fmi3Status fmi3GetShiftFraction(fmi3Instance, const fmi3ValueReference*, size_t, fmi3UInt64*, fmi3UInt64*) { return fmi3Error; }
fmi3Status fmi3SetIntervalDecimal(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Float64*) { return fmi3Error; }
fmi3Status fmi3SetIntervalFraction(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt64*, const fmi3UInt64*) { return fmi3Error; }
fmi3Status fmi3SetShiftDecimal(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Float64*) { return fmi3Error; }
fmi3Status fmi3SetShiftFraction(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3UInt64*, const fmi3UInt64*) { return fmi3Error; }
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance) { return fmi3Error; }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance, fmi3Boolean*, fmi3Boolean*, fmi3Boolean*, fmi3Boolean*, fmi3Boolean*, fmi3Float64*) { return fmi3Error; }
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance) { return fmi3Error; }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance, fmi3Boolean, fmi3Boolean*, fmi3Boolean*) { return fmi3Error; }
fmi3Status fmi3SetTime(fmi3Instance, fmi3Float64) { return fmi3Error; }
fmi3Status fmi3SetContinuousStates(fmi3Instance, const fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetEventIndicators(fmi3Instance, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetContinuousStates(fmi3Instance, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance, size_t*) { return fmi3Error; }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance, size_t*) { return fmi3Error; }
fmi3Status fmi3GetOutputDerivatives(fmi3Instance, const fmi3ValueReference*, size_t, const fmi3Int32*, fmi3Float64*, size_t) { return fmi3Error; }
fmi3Status fmi3ActivateModelPartition(fmi3Instance, fmi3ValueReference, fmi3Float64) { return fmi3Error; }

}  // extern "C"
