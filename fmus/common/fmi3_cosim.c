/* FMI 3.0 co-simulation wrapper over a model (see core.h). Included, not compiled alone.
 * FMI 3.0 requires every function to be exported: model exchange, scheduled execution,
 * clocks, FMU state and derivatives are stubs that log an error and return fmi3Error.
 * Array variables (ARRAY in the model's table) are read and written element by element in
 * row-major order; nValues counts elements. A model that asks to end the simulation
 * (MODEL_CAN_TERMINATE) makes fmi3DoStep set terminateSimulation and lastSuccessfulTime. */
#include "fmi3Functions.h"
#include "vars.h"
#ifdef MODEL_USES_RESOURCES
#include "resources.h"
#endif

#ifndef INSTANTIATION_TOKEN
#error "INSTANTIATION_TOKEN (the modelDescription instantiationToken) must be defined by the build"
#endif

typedef struct {
    ModelData d;
    double time;
    Mode mode;
    bool terminated; /* the model asked to end the simulation (terminateSimulation was set) */
    char *name;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    bool logging;
    char msg[1024];
} Instance;

static void logmsg(Instance *inst, fmi3Status status, const char *message) {
    if (inst->log == NULL) return;
    if (status == fmi3OK && !inst->logging) return;
    inst->log(inst->env, status, status == fmi3OK ? "logEvents" : "logStatusError", message);
}

static fmi3Status fail(Instance *inst, const char *message) {
    logmsg(inst, fmi3Error, message);
    return fmi3Error;
}

static fmi3Status unsupported(fmi3Instance instance, const char *function) {
    Instance *inst = (Instance *)instance;
    if (inst == NULL) return fmi3Error;
    snprintf(inst->msg, sizeof inst->msg, "%s is not supported by this FMU", function);
    return fail(inst, inst->msg);
}

#define CHECK_INSTANCE(c) \
    Instance *inst = (Instance *)(c); \
    if (inst == NULL) return fmi3Error

#define REQUIRE_MODE(cond, function) \
    if (!(cond)) { \
        snprintf(inst->msg, sizeof inst->msg, "%s is not allowed in the current state", function); \
        return fail(inst, inst->msg); \
    }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    CHECK_INSTANCE(instance);
    (void)nCategories;
    (void)categories;
    inst->logging = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Instance *inst;
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (instantiationToken == NULL || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "instantiationToken does not match " INSTANTIATION_TOKEN);
        return NULL;
    }
    if (eventModeUsed) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "event mode is not supported (hasEventMode is false)");
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (inst == NULL) return NULL;
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    inst->logging = loggingOn;
    if (!core_set_string(&inst->name, instanceName ? instanceName : "")) {
        free(inst);
        return NULL;
    }
    model_defaults(&inst->d);
#ifdef MODEL_USES_RESOURCES
    {
        char dir[4096];
        if (!core_resource_dir(resourcePath, dir, sizeof dir, inst->msg, sizeof inst->msg) ||
            !model_load_resources(&inst->d, dir, inst->msg, sizeof inst->msg)) {
            if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", inst->msg);
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

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName,
                                          fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName;
    (void)instantiationToken;
    (void)resourcePath;
    (void)visible;
    (void)loggingOn;
    (void)clockUpdate;
    (void)lockPreemption;
    (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    Instance *inst = (Instance *)instance;
    if (inst == NULL) return;
#ifdef MODEL_USES_RESOURCES
    model_free_resources(&inst->d);
#endif
    core_free_data(&inst->d);
    free(inst->name);
    free(inst);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    CHECK_INSTANCE(instance);
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    REQUIRE_MODE(inst->mode == MODE_INSTANTIATED, "fmi3EnterInitializationMode");
    inst->time = startTime;
    inst->mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    CHECK_INSTANCE(instance);
    REQUIRE_MODE(inst->mode == MODE_INITIALIZATION, "fmi3ExitInitializationMode");
    model_start(&inst->d);
    inst->mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    CHECK_INSTANCE(instance);
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmi3Terminate");
    inst->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    CHECK_INSTANCE(instance);
    model_defaults(&inst->d);
    inst->time = 0.0;
    inst->mode = MODE_INSTANTIATED;
    inst->terminated = false;
    return fmi3OK;
}

#define CHECK_ARRAYS(nvr, nValues) \
    if (nvr > 0 && (valueReferences == NULL || values == NULL)) return fail(inst, "NULL argument"); \
    if (nValues < nvr) { \
        snprintf(inst->msg, sizeof inst->msg, "expected at least %zu values, got %zu", nvr, \
                 nValues); \
        return fail(inst, inst->msg); \
    }

/* Whether the next n values, from index k on, fit into nValues; else a message. */
static bool fits(Instance *inst, const VarInfo *v, size_t k, size_t nValues) {
    if (k + core_count(v) <= nValues) return true;
    snprintf(inst->msg, sizeof inst->msg, "nValues %zu is too small: %s has %zu element(s)",
             nValues, v->name, core_count(v));
    return false;
}

/* Whether exactly nValues values were used (k of them). */
static bool used_all(Instance *inst, size_t k, size_t nValues) {
    if (k == nValues) return true;
    snprintf(inst->msg, sizeof inst->msg, "expected %zu values for these variables, got %zu", k,
             nValues);
    return false;
}

/* Getters: outputs are calculated from the current inputs, parameters, state and time. */
#define DEFINE_GET(Name, CType, vtype, FieldT, INDEPENDENT) \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, CType values[], size_t nValues) { \
        size_t i, j, k = 0; \
        CHECK_INSTANCE(instance); \
        CHECK_ARRAYS(nValueReferences, nValues); \
        model_calculate(&inst->d, inst->time, inst->mode == MODE_INITIALIZATION); \
        for (i = 0; i < nValueReferences; i++) { \
            const VarInfo *v = \
                core_lookup(valueReferences[i], vtype, inst->msg, sizeof inst->msg); \
            if (v == NULL || !fits(inst, v, k, nValues)) return fail(inst, inst->msg); \
            if (v->causality == VC_INDEPENDENT) { \
                INDEPENDENT; \
                k++; \
            } else { \
                for (j = 0; j < core_count(v); j++) values[k++] = FIELD(&inst->d, v, FieldT)[j]; \
            } \
        } \
        if (!used_all(inst, k, nValues)) return fail(inst, inst->msg); \
        return fmi3OK; \
    }

DEFINE_GET(Float64, fmi3Float64, VT_REAL, double, values[k] = inst->time)
DEFINE_GET(Int32, fmi3Int32, VT_INTEGER, int, (void)0)
DEFINE_GET(UInt64, fmi3UInt64, VT_UINT64, uint64_t, (void)0)
DEFINE_GET(Boolean, fmi3Boolean, VT_BOOLEAN, bool, (void)0)
DEFINE_GET(String, fmi3String, VT_STRING, char *, (void)0)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    size_t i;
    CHECK_INSTANCE(instance);
    CHECK_ARRAYS(nValueReferences, nValues);
    if (!used_all(inst, nValueReferences, nValues)) return fail(inst, inst->msg);
    if (nValueReferences > 0 && valueSizes == NULL) return fail(inst, "NULL argument");
    model_calculate(&inst->d, inst->time, inst->mode == MODE_INITIALIZATION);
    for (i = 0; i < nValueReferences; i++) {
        const VarInfo *v = core_lookup(valueReferences[i], VT_BINARY, inst->msg, sizeof inst->msg);
        if (v == NULL) return fail(inst, inst->msg);
        values[i] = FIELD(&inst->d, v, Bytes)->data;
        valueSizes[i] = FIELD(&inst->d, v, Bytes)->size;
    }
    return fmi3OK;
}

/* Setters: the values of every array element in order; strings are scalars only. */
#define DEFINE_SET(Name, CType, vtype, ASSIGN) \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, const CType values[], size_t nValues) { \
        size_t i, j, k = 0; \
        CHECK_INSTANCE(instance); \
        CHECK_ARRAYS(nValueReferences, nValues); \
        for (i = 0; i < nValueReferences; i++) { \
            const VarInfo *v = \
                core_lookup(valueReferences[i], vtype, inst->msg, sizeof inst->msg); \
            if (v == NULL || !core_can_set(v, inst->mode, inst->msg, sizeof inst->msg) || \
                !fits(inst, v, k, nValues)) \
                return fail(inst, inst->msg); \
            for (j = 0; j < core_count(v); j++, k++) { \
                ASSIGN; \
            } \
        } \
        if (!used_all(inst, k, nValues)) return fail(inst, inst->msg); \
        return fmi3OK; \
    }

DEFINE_SET(Float64, fmi3Float64, VT_REAL, FIELD(&inst->d, v, double)[j] = values[k])
DEFINE_SET(Int32, fmi3Int32, VT_INTEGER, FIELD(&inst->d, v, int)[j] = values[k])
DEFINE_SET(UInt64, fmi3UInt64, VT_UINT64, FIELD(&inst->d, v, uint64_t)[j] = values[k])
DEFINE_SET(Boolean, fmi3Boolean, VT_BOOLEAN, FIELD(&inst->d, v, bool)[j] = values[k])
DEFINE_SET(String, fmi3String, VT_STRING,
           if (!core_set_string(FIELD(&inst->d, v, char *), values[k]))
               return fail(inst, "out of memory"))

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    size_t i;
    CHECK_INSTANCE(instance);
    CHECK_ARRAYS(nValueReferences, nValues);
    if (!used_all(inst, nValueReferences, nValues)) return fail(inst, inst->msg);
    if (nValueReferences > 0 && valueSizes == NULL) return fail(inst, "NULL argument");
    for (i = 0; i < nValueReferences; i++) {
        const VarInfo *v = core_lookup(valueReferences[i], VT_BINARY, inst->msg, sizeof inst->msg);
        if (v == NULL || !core_can_set(v, inst->mode, inst->msg, sizeof inst->msg))
            return fail(inst, inst->msg);
        if (values[i] == NULL && valueSizes[i] > 0) return fail(inst, "NULL binary value");
        if (!core_set_bytes(FIELD(&inst->d, v, Bytes), values[i], valueSizes[i]))
            return fail(inst, "out of memory");
    }
    return fmi3OK;
}

/* Types this FMU has no variables of. */
#define DEFINE_NO_TYPE(Name, CType) \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, CType values[], size_t nValues) { \
        CHECK_INSTANCE(instance); \
        (void)valueReferences; \
        (void)values; \
        (void)nValues; \
        if (nValueReferences == 0) return fmi3OK; \
        return fail(inst, "this FMU has no " #Name " variables"); \
    } \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                             size_t nValueReferences, const CType values[], size_t nValues) { \
        CHECK_INSTANCE(instance); \
        (void)valueReferences; \
        (void)values; \
        (void)nValues; \
        if (nValueReferences == 0) return fmi3OK; \
        return fail(inst, "this FMU has no " #Name " variables"); \
    }

DEFINE_NO_TYPE(Float32, fmi3Float32)
DEFINE_NO_TYPE(Int8, fmi3Int8)
DEFINE_NO_TYPE(UInt8, fmi3UInt8)
DEFINE_NO_TYPE(Int16, fmi3Int16)
DEFINE_NO_TYPE(UInt16, fmi3UInt16)
DEFINE_NO_TYPE(UInt32, fmi3UInt32)
DEFINE_NO_TYPE(Int64, fmi3Int64)

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    CHECK_INSTANCE(instance);
    (void)noSetFMUStatePriorToCurrentPoint;
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmi3DoStep");
    if (inst->terminated) {
        snprintf(inst->msg, sizeof inst->msg,
                 "fmi3DoStep after the model asked to end the simulation at t=%g", inst->time);
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
        logmsg(inst, fmi3OK, inst->msg);
    }
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = inst->terminated ? fmi3True : fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = inst->time;
    return fmi3OK;
}

/* Everything below is unsupported. */
#define UNUSED(x) (void)(x)

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterEventMode");
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(values);
    return unsupported(instance, "fmi3GetClock");
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(values);
    return unsupported(instance, "fmi3SetClock");
}
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    UNUSED(valueReference); UNUSED(nDependencies);
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    UNUSED(dependent); UNUSED(elementIndicesOfDependent); UNUSED(independents);
    UNUSED(elementIndicesOfIndependents); UNUSED(dependencyKinds); UNUSED(nDependencies);
    return unsupported(instance, "fmi3GetVariableDependencies");
}
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    UNUSED(FMUState);
    return unsupported(instance, "fmi3GetFMUState");
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    UNUSED(FMUState);
    return unsupported(instance, "fmi3SetFMUState");
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    UNUSED(FMUState);
    return unsupported(instance, "fmi3FreeFMUState");
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    UNUSED(FMUState); UNUSED(size);
    return unsupported(instance, "fmi3SerializedFMUStateSize");
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    UNUSED(FMUState); UNUSED(serializedState); UNUSED(size);
    return unsupported(instance, "fmi3SerializeFMUState");
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    UNUSED(serializedState); UNUSED(size); UNUSED(FMUState);
    return unsupported(instance, "fmi3DeserializeFMUState");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    UNUSED(unknowns); UNUSED(nUnknowns); UNUSED(knowns); UNUSED(nKnowns);
    UNUSED(seed); UNUSED(nSeed); UNUSED(sensitivity); UNUSED(nSensitivity);
    return unsupported(instance, "fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    UNUSED(unknowns); UNUSED(nUnknowns); UNUSED(knowns); UNUSED(nKnowns);
    UNUSED(seed); UNUSED(nSeed); UNUSED(sensitivity); UNUSED(nSensitivity);
    return unsupported(instance, "fmi3GetAdjointDerivative");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode");
}
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(intervals); UNUSED(qualifiers);
    return unsupported(instance, "fmi3GetIntervalDecimal");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(counters); UNUSED(resolutions);
    UNUSED(qualifiers);
    return unsupported(instance, "fmi3GetIntervalFraction");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(shifts);
    return unsupported(instance, "fmi3GetShiftDecimal");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(counters); UNUSED(resolutions);
    return unsupported(instance, "fmi3GetShiftFraction");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(intervals);
    return unsupported(instance, "fmi3SetIntervalDecimal");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(counters); UNUSED(resolutions);
    return unsupported(instance, "fmi3SetIntervalFraction");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(shifts);
    return unsupported(instance, "fmi3SetShiftDecimal");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(counters); UNUSED(resolutions);
    return unsupported(instance, "fmi3SetShiftFraction");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates");
}
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    UNUSED(discreteStatesNeedUpdate); UNUSED(terminateSimulation);
    UNUSED(nominalsOfContinuousStatesChanged); UNUSED(valuesOfContinuousStatesChanged);
    UNUSED(nextEventTimeDefined); UNUSED(nextEventTime);
    return unsupported(instance, "fmi3UpdateDiscreteStates");
}
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterContinuousTimeMode");
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    UNUSED(noSetFMUStatePriorToCurrentPoint); UNUSED(enterEventMode); UNUSED(terminateSimulation);
    return unsupported(instance, "fmi3CompletedIntegratorStep");
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    UNUSED(time);
    return unsupported(instance, "fmi3SetTime");
}
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    UNUSED(continuousStates); UNUSED(nContinuousStates);
    return unsupported(instance, "fmi3SetContinuousStates");
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    UNUSED(derivatives); UNUSED(nContinuousStates);
    return unsupported(instance, "fmi3GetContinuousStateDerivatives");
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    UNUSED(eventIndicators); UNUSED(nEventIndicators);
    return unsupported(instance, "fmi3GetEventIndicators");
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    UNUSED(continuousStates); UNUSED(nContinuousStates);
    return unsupported(instance, "fmi3GetContinuousStates");
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    UNUSED(nominals); UNUSED(nContinuousStates);
    return unsupported(instance, "fmi3GetNominalsOfContinuousStates");
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    UNUSED(nEventIndicators);
    return unsupported(instance, "fmi3GetNumberOfEventIndicators");
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    UNUSED(nContinuousStates);
    return unsupported(instance, "fmi3GetNumberOfContinuousStates");
}
fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterStepMode");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    UNUSED(valueReferences); UNUSED(nValueReferences); UNUSED(orders); UNUSED(values);
    UNUSED(nValues);
    return unsupported(instance, "fmi3GetOutputDerivatives");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    UNUSED(clockReference); UNUSED(activationTime);
    return unsupported(instance, "fmi3ActivateModelPartition");
}
