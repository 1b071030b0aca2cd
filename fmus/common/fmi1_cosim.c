/* FMI 1.0 co-simulation (stand-alone) wrapper over a model (see core.h). Included, not
 * compiled alone.
 *
 * Types come from FMPy's fmi1Functions.h (the Reference FMUs' combined FMI 1.0 header: the
 * standard's fmiReal, fmiStatus, fmiCallbackFunctions... spelled fmi1Real, fmi1Status, ...,
 * plus one function type per API function). The exported names follow the FMI 1.0 standard:
 * every function is prefixed with the modelIdentifier, e.g. Integrator1_fmiDoStep; each is
 * declared with the header's function type first, so gcc checks the signature.
 *
 * There is no initialization mode: parameters and inputs are set after fmiInstantiateSlave,
 * fmiInitializeSlave ends initialization (model_start). Not supported (they log an error and
 * return fmiError): asynchronous steps (fmiCancelStep, pending status), repeating a step
 * (newStep = fmiFalse), input and output derivatives. */
#include "fmi1Functions.h"
#include "vars.h"
#ifdef MODEL_USES_RESOURCES
#include "resources.h"
#endif

#ifdef MODEL_CAN_TERMINATE
#error "the FMI 1.0 wrapper does not support models that end the simulation (MODEL_CAN_TERMINATE)"
#endif

#ifndef MODEL_IDENTIFIER
#error "MODEL_IDENTIFIER (the modelDescription modelIdentifier) must be defined by the build"
#endif
#ifndef INSTANTIATION_TOKEN
#error "INSTANTIATION_TOKEN (the modelDescription guid) must be defined by the build"
#endif

#define FMI1_PASTE(a, b) a##b
#define FMI1_PASTE_EXPANDED(a, b) FMI1_PASTE(a, b)
#define FMI1_NAME(name) FMI1_PASTE_EXPANDED(MODEL_IDENTIFIER, name)

#define fmiGetTypesPlatform FMI1_NAME(_fmiGetTypesPlatform)
#define fmiGetVersion FMI1_NAME(_fmiGetVersion)
#define fmiSetDebugLogging FMI1_NAME(_fmiSetDebugLogging)
#define fmiInstantiateSlave FMI1_NAME(_fmiInstantiateSlave)
#define fmiInitializeSlave FMI1_NAME(_fmiInitializeSlave)
#define fmiTerminateSlave FMI1_NAME(_fmiTerminateSlave)
#define fmiResetSlave FMI1_NAME(_fmiResetSlave)
#define fmiFreeSlaveInstance FMI1_NAME(_fmiFreeSlaveInstance)
#define fmiGetReal FMI1_NAME(_fmiGetReal)
#define fmiGetInteger FMI1_NAME(_fmiGetInteger)
#define fmiGetBoolean FMI1_NAME(_fmiGetBoolean)
#define fmiGetString FMI1_NAME(_fmiGetString)
#define fmiSetReal FMI1_NAME(_fmiSetReal)
#define fmiSetInteger FMI1_NAME(_fmiSetInteger)
#define fmiSetBoolean FMI1_NAME(_fmiSetBoolean)
#define fmiSetString FMI1_NAME(_fmiSetString)
#define fmiDoStep FMI1_NAME(_fmiDoStep)
#define fmiCancelStep FMI1_NAME(_fmiCancelStep)
#define fmiGetStatus FMI1_NAME(_fmiGetStatus)
#define fmiGetRealStatus FMI1_NAME(_fmiGetRealStatus)
#define fmiGetIntegerStatus FMI1_NAME(_fmiGetIntegerStatus)
#define fmiGetBooleanStatus FMI1_NAME(_fmiGetBooleanStatus)
#define fmiGetStringStatus FMI1_NAME(_fmiGetStringStatus)
#define fmiSetRealInputDerivatives FMI1_NAME(_fmiSetRealInputDerivatives)
#define fmiGetRealOutputDerivatives FMI1_NAME(_fmiGetRealOutputDerivatives)

fmi1GetTypesPlatformTYPE fmiGetTypesPlatform;
fmi1GetVersionTYPE fmiGetVersion;
fmi1SetDebugLoggingTYPE fmiSetDebugLogging;
fmi1InstantiateSlaveTYPE fmiInstantiateSlave;
fmi1InitializeSlaveTYPE fmiInitializeSlave;
fmi1TerminateSlaveTYPE fmiTerminateSlave;
fmi1ResetSlaveTYPE fmiResetSlave;
fmi1FreeSlaveInstanceTYPE fmiFreeSlaveInstance;
fmi1GetRealTYPE fmiGetReal;
fmi1GetIntegerTYPE fmiGetInteger;
fmi1GetBooleanTYPE fmiGetBoolean;
fmi1GetStringTYPE fmiGetString;
fmi1SetRealTYPE fmiSetReal;
fmi1SetIntegerTYPE fmiSetInteger;
fmi1SetBooleanTYPE fmiSetBoolean;
fmi1SetStringTYPE fmiSetString;
fmi1DoStepTYPE fmiDoStep;
fmi1CancelStepTYPE fmiCancelStep;
fmi1GetStatusTYPE fmiGetStatus;
fmi1GetRealStatusTYPE fmiGetRealStatus;
fmi1GetIntegerStatusTYPE fmiGetIntegerStatus;
fmi1GetBooleanStatusTYPE fmiGetBooleanStatus;
fmi1GetStringStatusTYPE fmiGetStringStatus;
fmi1SetRealInputDerivativesTYPE fmiSetRealInputDerivatives;
fmi1GetRealOutputDerivativesTYPE fmiGetRealOutputDerivatives;

typedef struct {
    ModelData d;
    double time;
    Mode mode;
    char *name;
    fmi1CallbackFunctions cb;
    bool logging;
    char msg[1024];
} Instance;

/* FMI 1.0 loggers expand #<type><vr># in messages, so the text goes in as a "%s" argument. */
static void logmsg(Instance *inst, fmi1Status status, const char *message) {
    if (inst->cb.logger == NULL) return;
    if (status == fmi1OK && !inst->logging) return;
    inst->cb.logger(inst, inst->name, status, status == fmi1OK ? "log" : "error", "%s", message);
}

static fmi1Status fail(Instance *inst, const char *message) {
    logmsg(inst, fmi1Error, message);
    return fmi1Error;
}

static fmi1Status unsupported(fmi1Component c, const char *function) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return fmi1Error;
    snprintf(inst->msg, sizeof inst->msg, "%s is not supported by this FMU", function);
    return fail(inst, inst->msg);
}

#define CHECK_INSTANCE(c) \
    Instance *inst = (Instance *)(c); \
    if (inst == NULL) return fmi1Error

#define REQUIRE_MODE(cond, function) \
    if (!(cond)) { \
        snprintf(inst->msg, sizeof inst->msg, "%s is not allowed in the current state", function); \
        return fail(inst, inst->msg); \
    }

const char *fmiGetTypesPlatform(void) { return "standard32"; }
const char *fmiGetVersion(void) { return "1.0"; }

fmi1Status fmiSetDebugLogging(fmi1Component c, fmi1Boolean loggingOn) {
    CHECK_INSTANCE(c);
    inst->logging = loggingOn != fmi1False;
    return fmi1OK;
}

fmi1Component fmiInstantiateSlave(fmi1String instanceName, fmi1String fmuGUID,
                                  fmi1String fmuLocation, fmi1String mimeType, fmi1Real timeout,
                                  fmi1Boolean visible, fmi1Boolean interactive,
                                  fmi1CallbackFunctions functions, fmi1Boolean loggingOn) {
    Instance *inst;
    (void)fmuLocation;
    (void)mimeType;
    (void)timeout;
    (void)visible;
    (void)interactive;
    if (functions.logger == NULL) return NULL;
    if (fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        functions.logger(NULL, instanceName, fmi1Error, "error", "GUID '%s' does not match '%s'",
                         fmuGUID ? fmuGUID : "", INSTANTIATION_TOKEN);
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (inst == NULL) return NULL;
    inst->cb = functions;
    inst->logging = loggingOn != fmi1False;
    if (!core_set_string(&inst->name, instanceName ? instanceName : "")) {
        free(inst);
        return NULL;
    }
    model_defaults(&inst->d);
#ifdef MODEL_USES_RESOURCES
    {
        /* FMI 1.0 passes the URI of the unzipped FMU; resources/ is a folder in it. */
        char dir[4096];
        size_t n;
        bool ok = core_resource_dir(fmuLocation, dir, sizeof dir, inst->msg, sizeof inst->msg);
        if (ok) {
            n = strlen(dir);
            ok = n + sizeof "/resources" <= sizeof dir;
            if (ok) {
                memcpy(dir + n, "/resources", sizeof "/resources");
            } else {
                snprintf(inst->msg, sizeof inst->msg, "FMU location '%.600s' is too long",
                         fmuLocation);
            }
        }
        if (!ok || !model_load_resources(&inst->d, dir, inst->msg, sizeof inst->msg)) {
            functions.logger(NULL, instanceName, fmi1Error, "error", "%s", inst->msg);
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

void fmiFreeSlaveInstance(fmi1Component c) {
    Instance *inst = (Instance *)c;
    if (inst == NULL) return;
#ifdef MODEL_USES_RESOURCES
    model_free_resources(&inst->d);
#endif
    core_free_data(&inst->d);
    free(inst->name);
    free(inst);
}

fmi1Status fmiInitializeSlave(fmi1Component c, fmi1Real tStart, fmi1Boolean StopTimeDefined,
                              fmi1Real tStop) {
    CHECK_INSTANCE(c);
    (void)StopTimeDefined;
    (void)tStop;
    REQUIRE_MODE(inst->mode == MODE_INSTANTIATED, "fmiInitializeSlave");
    inst->time = tStart;
    model_start(&inst->d);
    inst->mode = MODE_STEP;
    return fmi1OK;
}

fmi1Status fmiTerminateSlave(fmi1Component c) {
    CHECK_INSTANCE(c);
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmiTerminateSlave");
    inst->mode = MODE_TERMINATED;
    return fmi1OK;
}

/* Back to the state after fmiInstantiateSlave (start values); fmiInitializeSlave is next. */
fmi1Status fmiResetSlave(fmi1Component c) {
    CHECK_INSTANCE(c);
    model_defaults(&inst->d);
    inst->time = 0.0;
    inst->mode = MODE_INSTANTIATED;
    return fmi1OK;
}

/* Getters: outputs are calculated from the current inputs, parameters, state and time. */
#define DEFINE_GET(Name, CType, vtype, FieldT, convert, INDEPENDENT) \
    fmi1Status fmiGet##Name(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, \
                            CType value[]) { \
        size_t i; \
        CHECK_INSTANCE(c); \
        if (nvr > 0 && (vr == NULL || value == NULL)) return fail(inst, "NULL argument"); \
        model_calculate(&inst->d, inst->time, false); \
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
        return fmi1OK; \
    }

DEFINE_GET(Real, fmi1Real, VT_REAL, double, x, value[i] = inst->time)
DEFINE_GET(Integer, fmi1Integer, VT_INTEGER, int, x, (void)0)
DEFINE_GET(Boolean, fmi1Boolean, VT_BOOLEAN, bool, x ? fmi1True : fmi1False, (void)0)
DEFINE_GET(String, fmi1String, VT_STRING, char *, x, (void)0)

#define DEFINE_SET(Name, CType, vtype, ASSIGN) \
    fmi1Status fmiSet##Name(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, \
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
        return fmi1OK; \
    }

DEFINE_SET(Real, fmi1Real, VT_REAL, *FIELD(&inst->d, v, double) = value[i])
DEFINE_SET(Integer, fmi1Integer, VT_INTEGER, *FIELD(&inst->d, v, int) = value[i])
DEFINE_SET(Boolean, fmi1Boolean, VT_BOOLEAN,
           *FIELD(&inst->d, v, bool) = value[i] != fmi1False)
DEFINE_SET(String, fmi1String, VT_STRING,
           if (!core_set_string(FIELD(&inst->d, v, char *), value[i]))
               return fail(inst, "out of memory"))

fmi1Status fmiDoStep(fmi1Component c, fmi1Real currentCommunicationPoint,
                     fmi1Real communicationStepSize, fmi1Boolean newStep) {
    CHECK_INSTANCE(c);
    REQUIRE_MODE(inst->mode == MODE_STEP, "fmiDoStep");
    if (newStep == fmi1False) {
        return fail(inst, "fmiDoStep with newStep = fmiFalse (repeating a rejected step) is not "
                          "supported by this FMU");
    }
    if (!(communicationStepSize > 0.0)) {
        snprintf(inst->msg, sizeof inst->msg, "communication step size %g is not positive",
                 communicationStepSize);
        return fail(inst, inst->msg);
    }
    model_calculate(&inst->d, currentCommunicationPoint, false);
    model_step(&inst->d, currentCommunicationPoint, communicationStepSize);
    inst->time = currentCommunicationPoint + communicationStepSize;
    return fmi1OK;
}

/* Status inquiry: steps are synchronous, so the last fmiDoStep is done and its status was
 * returned by it; fmiLastSuccessfulTime is the current time. Pending status: unsupported. */
fmi1Status fmiGetStatus(fmi1Component c, const fmi1StatusKind s, fmi1Status *value) {
    CHECK_INSTANCE(c);
    if (s != fmi1DoStepStatus || value == NULL) return unsupported(c, "fmiGetStatus of this kind");
    *value = fmi1OK;
    return fmi1OK;
}
fmi1Status fmiGetRealStatus(fmi1Component c, const fmi1StatusKind s, fmi1Real *value) {
    CHECK_INSTANCE(c);
    if (s != fmi1LastSuccessfulTime || value == NULL) {
        return unsupported(c, "fmiGetRealStatus of this kind");
    }
    *value = inst->time;
    return fmi1OK;
}
fmi1Status fmiGetIntegerStatus(fmi1Component c, const fmi1StatusKind s, fmi1Integer *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmiGetIntegerStatus");
}
fmi1Status fmiGetBooleanStatus(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmiGetBooleanStatus");
}
fmi1Status fmiGetStringStatus(fmi1Component c, const fmi1StatusKind s, fmi1String *value) {
    (void)s;
    (void)value;
    return unsupported(c, "fmiGetStringStatus");
}

/* Unsupported optional functions (canRunAsynchronuously, canInterpolateInputs and
 * maxOutputDerivativeOrder are false / 0 in the model description). */
fmi1Status fmiCancelStep(fmi1Component c) { return unsupported(c, "fmiCancelStep"); }
fmi1Status fmiSetRealInputDerivatives(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                      const fmi1Integer order[], const fmi1Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, "fmiSetRealInputDerivatives");
}
fmi1Status fmiGetRealOutputDerivatives(fmi1Component c, const fmi1ValueReference vr[],
                                       size_t nvr, const fmi1Integer order[], fmi1Real value[]) {
    (void)vr;
    (void)nvr;
    (void)order;
    (void)value;
    return unsupported(c, "fmiGetRealOutputDerivatives");
}
