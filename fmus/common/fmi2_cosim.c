/* FMI 2.0 co-simulation wrapper over a model (see core.h). Included, not compiled alone.
 * Model exchange and the optional capabilities (FMU state, derivatives, asynchronous steps)
 * are not supported: those functions log an error and return fmi2Error. A model that asks to
 * end the simulation (MODEL_CAN_TERMINATE) makes fmi2DoStep return fmi2Discard; then
 * fmi2GetBooleanStatus(fmi2Terminated) and fmi2GetRealStatus(fmi2LastSuccessfulTime) answer. */
#include "fmi2Functions.h"
#include "vars.h"
#ifdef MODEL_USES_RESOURCES
#include "resources.h"
#endif

#ifndef INSTANTIATION_TOKEN
#error "INSTANTIATION_TOKEN (the modelDescription guid) must be defined by the build"
#endif

typedef struct {
    ModelData d;
    double time;
    Mode mode;
    bool terminated; /* the model asked to end the simulation (fmi2DoStep returned fmi2Discard) */
    char *name;
    fmi2CallbackFunctions cb;
    bool logging;
    char msg[1024];
} Instance;

static void logmsg(Instance *inst, fmi2Status status, const char *message) {
    if (inst->cb.logger == NULL) return;
    if (status == fmi2OK && !inst->logging) return;
    inst->cb.logger(inst->cb.componentEnvironment, inst->name, status,
                    status == fmi2OK ? "logAll" : "logStatusError", "%s", message);
}

static fmi2Status fail(Instance *inst, const char *message) {
    logmsg(inst, fmi2Error, message);
    return fmi2Error;
}

static fmi2Status unsupported(fmi2Component c, const char *function) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi2Error;
    snprintf(inst->msg, sizeof inst->msg, "%s is not supported by this FMU", function);
    return fail(inst, inst->msg);
}

#define CHECK_INSTANCE(c) \
    Instance *inst = (Instance *)(c); \
    if (inst == NULL) return fmi2Error

#define REQUIRE_MODE(cond, function) \
    if (!(cond)) { \
        snprintf(inst->msg, sizeof inst->msg, "%s is not allowed in the current state", function); \
        return fail(inst, inst->msg); \
    }

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    CHECK_INSTANCE(c);
    (void)nCategories;
    (void)categories;
    inst->logging = loggingOn != fmi2False;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Instance *inst;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->logger == NULL) return NULL;
    if (fmuType != fmi2CoSimulation) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "this FMU supports co-simulation only");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "GUID '%s' does not match '%s'",
                          fmuGUID ? fmuGUID : "", INSTANTIATION_TOKEN);
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (inst == NULL) return NULL;
    inst->cb = *functions;
    inst->logging = loggingOn != fmi2False;
    if (!core_set_string(&inst->name, instanceName ? instanceName : "")) {
        free(inst);
        return NULL;
    }
    model_defaults(&inst->d);
#ifdef MODEL_USES_RESOURCES
    {
        char dir[4096];
        if (!core_resource_dir(fmuResourceLocation, dir, sizeof dir, inst->msg, sizeof inst->msg) ||
            !model_load_resources(&inst->d, dir, inst->msg, sizeof inst->msg)) {
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                              "logStatusError", "%s", inst->msg);
            model_free_resources(&inst->d);
            core_free_data(&inst->d);
            free(inst->name);
            free(inst);
            return NULL;
        }
    }
#endif
    inst->mode = MODE_INSTANTIATED;
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return;
#ifdef MODEL_USES_RESOURCES
    model_free_resources(&inst->d);
#endif
    core_free_data(&inst->d);
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    CHECK_INSTANCE(c);
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    REQUIRE_MODE(inst->mode == MODE_INSTANTIATED, "fmi2SetupExperiment");
    inst->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CHECK_INSTANCE(c);
    REQUIRE_MODE(inst->mode == MODE_INSTANTIATED, "fmi2EnterInitializationMode");
    inst->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    CHECK_INSTANCE(c);
    REQUIRE_MODE(inst->mode == MODE_INITIALIZATION, "fmi2ExitInitializationMode");
    model_start(&inst->d);
    inst->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK_INSTANCE(c);
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmi2Terminate");
    inst->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    CHECK_INSTANCE(c);
    model_defaults(&inst->d);
    inst->time = 0.0;
    inst->mode = MODE_INSTANTIATED;
    inst->terminated = false;
    return fmi2OK;
}

/* Getters: outputs are calculated from the current inputs, parameters, state and time. */
#define DEFINE_GET(Name, CType, vtype, FieldT, convert, INDEPENDENT) \
    fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, \
                             CType value[]) { \
        size_t i; \
        CHECK_INSTANCE(c); \
        if (nvr > 0 && (vr == NULL || value == NULL)) return fail(inst, "NULL argument"); \
        model_calculate(&inst->d, inst->time, inst->mode == MODE_INITIALIZATION); \
        for (i = 0; i < nvr; i++) { \
            const VarInfo *v = core_lookup(vr[i], vtype, inst->msg, sizeof inst->msg); \
            if (v == NULL) return fail(inst, inst->msg); \
            if (v->causality == VC_INDEPENDENT) { \
                INDEPENDENT; \
            } else { \
                FieldT x = *FIELD(&inst->d, v, FieldT); \
                value[i] = convert; \
            } \
        } \
        return fmi2OK; \
    }

DEFINE_GET(Real, fmi2Real, VT_REAL, double, x, value[i] = inst->time)
DEFINE_GET(Integer, fmi2Integer, VT_INTEGER, int, x, (void)0)
DEFINE_GET(Boolean, fmi2Boolean, VT_BOOLEAN, bool, x ? fmi2True : fmi2False, (void)0)
DEFINE_GET(String, fmi2String, VT_STRING, char *, x, (void)0)

#define DEFINE_SET(Name, CType, vtype, ASSIGN) \
    fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, \
                             const CType value[]) { \
        size_t i; \
        CHECK_INSTANCE(c); \
        if (nvr > 0 && (vr == NULL || value == NULL)) return fail(inst, "NULL argument"); \
        for (i = 0; i < nvr; i++) { \
            const VarInfo *v = core_lookup(vr[i], vtype, inst->msg, sizeof inst->msg); \
            if (v == NULL || !core_can_set(v, inst->mode, inst->msg, sizeof inst->msg)) \
                return fail(inst, inst->msg); \
            ASSIGN; \
        } \
        return fmi2OK; \
    }

DEFINE_SET(Real, fmi2Real, VT_REAL, *FIELD(&inst->d, v, double) = value[i])
DEFINE_SET(Integer, fmi2Integer, VT_INTEGER, *FIELD(&inst->d, v, int) = value[i])
DEFINE_SET(Boolean, fmi2Boolean, VT_BOOLEAN,
           *FIELD(&inst->d, v, bool) = value[i] != fmi2False)
DEFINE_SET(String, fmi2String, VT_STRING,
           if (!core_set_string(FIELD(&inst->d, v, char *), value[i]))
               return fail(inst, "out of memory"))

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    CHECK_INSTANCE(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmi2DoStep");
    if (inst->terminated) {
        snprintf(inst->msg, sizeof inst->msg,
                 "fmi2DoStep after the model asked to end the simulation at t=%g", inst->time);
        return fail(inst, inst->msg);
    }
    if (!(communicationStepSize > 0.0)) {
        snprintf(inst->msg, sizeof inst->msg, "communication step size %g is not positive",
                 communicationStepSize);
        return fail(inst, inst->msg);
    }
    model_calculate(&inst->d, currentCommunicationPoint, false);
    model_step(&inst->d, currentCommunicationPoint, communicationStepSize);
    inst->time = currentCommunicationPoint + communicationStepSize;
    if (core_model_ends(&inst->d, &inst->time, inst->msg, sizeof inst->msg)) {
        inst->terminated = true;
        logmsg(inst, fmi2OK, inst->msg); /* a request, not an error: logged when asked */
        return fmi2Discard;
    }
    return fmi2OK;
}

/* Unsupported optional functions. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    return unsupported(c, "fmi2GetFMUstate");
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    (void)FMUstate;
    return unsupported(c, "fmi2SetFMUstate");
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    (void)FMUstate;
    return unsupported(c, "fmi2FreeFMUstate");
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    (void)size;
    return unsupported(c, "fmi2SerializedFMUstateSize");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate,
                                 fmi2Byte serializedState[], size_t size) {
    (void)FMUstate;
    (void)serializedState;
    (void)size;
    return unsupported(c, "fmi2SerializeFMUstate");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[],
                                   size_t size, fmi2FMUstate *FMUstate) {
    (void)serializedState;
    (void)size;
    (void)FMUstate;
    return unsupported(c, "fmi2DeSerializeFMUstate");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown_ref;
    (void)nUnknown;
    (void)vKnown_ref;
    (void)nKnown;
    (void)dvKnown;
    (void)dvUnknown;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}
fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetStatus");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    CHECK_INSTANCE(c);
    if (s != fmi2LastSuccessfulTime || value == NULL) return unsupported(c, "fmi2GetRealStatus");
    *value = inst->time;
    return fmi2OK;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetIntegerStatus");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    CHECK_INSTANCE(c);
    if (s != fmi2Terminated || value == NULL) return unsupported(c, "fmi2GetBooleanStatus");
    *value = inst->terminated ? fmi2True : fmi2False;
    return fmi2OK;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmi2GetStringStatus");
}

/* Model exchange: not supported. */
fmi2Status fmi2EnterEventMode(fmi2Component c) { return unsupported(c, "fmi2EnterEventMode"); }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    (void)eventInfo;
    return unsupported(c, "fmi2NewDiscreteStates");
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    return unsupported(c, "fmi2EnterContinuousTimeMode");
}
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c,
                                       fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    (void)enterEventMode;
    (void)terminateSimulation;
    return unsupported(c, "fmi2CompletedIntegratorStep");
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    return unsupported(c, "fmi2SetTime");
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x;
    (void)nx;
    return unsupported(c, "fmi2SetContinuousStates");
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives;
    (void)nx;
    return unsupported(c, "fmi2GetDerivatives");
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    (void)ni;
    return unsupported(c, "fmi2GetEventIndicators");
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x;
    (void)nx;
    return unsupported(c, "fmi2GetContinuousStates");
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal;
    (void)nx;
    return unsupported(c, "fmi2GetNominalsOfContinuousStates");
}
