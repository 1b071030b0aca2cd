/* Version-independent core shared by the FMI 1.0, 2.0 and 3.0 co-simulation wrappers.
 *
 * A model (source.h, feedthrough.h, integrator.h) defines, before including a wrapper:
 *   - `ModelData`, a struct holding every variable (double, int, bool, char *, Bytes);
 *   - `MODEL_VARS[]` / `MODEL_NVARS`, one VarInfo per variable (value reference, type,
 *     causality, offset into ModelData);
 *   - model_defaults(d)   start values (strings via core_set_string);
 *   - model_calculate(d, t, initializing)   outputs from parameters, inputs, state and time;
 *   - model_start(d)      called when initialization mode ends (state := its start value);
 *   - model_step(d, t, h) advance the state over [t, t+h] (the internal solver step is h).
 * Optionally (MODEL_USES_RESOURCES, see resources.h) it loads files from the FMU's resources/
 * folder at instantiation: model_load_resources(d, dir, msg, size), model_free_resources(d).
 * Optionally (MODEL_CAN_TERMINATE; FMI 2.0 and 3.0 only) it may ask to end the simulation:
 *   - model_step then stops where the model wants to end (a time in [t, t+h]) and
 *   - model_ends(d, &time) returns true with that time once it does (false before).
 *   The FMI 2.0 wrapper answers that doStep with fmi2Discard, fmi2GetBooleanStatus(
 *   fmi2Terminated) = true and fmi2GetRealStatus(fmi2LastSuccessfulTime) = time; the FMI 3.0
 *   wrapper sets terminateSimulation and lastSuccessfulTime. Further steps are refused.
 * Arrays (FMI 3.0 only, numeric and Boolean types): a field declared as a C array (1-D or 2-D,
 * row-major like FMI 3.0's serialization) is described by ARRAY(vr, type, causality, field,
 * element C type); FMI 3.0 getters and setters read and write all its elements in order.
 * The wrapper (fmi1_cosim.c, fmi2_cosim.c, fmi3_cosim.c) implements the FMI API over that,
 * with the helpers of vars.h. A model folder's C file includes the model, then the wrapper.
 */
#ifndef COUPLER_FMU_CORE_H
#define COUPLER_FMU_CORE_H

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* VT_UINT64 (uint64_t fields) is for FMI 3.0 structural parameters that size arrays. */
typedef enum { VT_REAL, VT_INTEGER, VT_BOOLEAN, VT_STRING, VT_BINARY, VT_UINT64 } VarType;
typedef enum { VC_INDEPENDENT, VC_PARAMETER, VC_INPUT, VC_OUTPUT } VarCausality;
typedef enum { MODE_INSTANTIATED, MODE_INITIALIZATION, MODE_STEP, MODE_TERMINATED } Mode;

typedef struct {
    unsigned int vr;
    VarType type;
    VarCausality causality;
    size_t offset; /* offsetof(ModelData, field); unused for the independent variable */
    const char *name;
    size_t count; /* number of elements of an array field; 0 for a scalar */
} VarInfo;

typedef struct {
    unsigned char *data;
    size_t size;
} Bytes;

#define VAR(vr, type, causality, field) {vr, type, causality, offsetof(ModelData, field), #field, 0}
#define ARRAY(vr, type, causality, field, T) \
    {vr, type, causality, offsetof(ModelData, field), #field, \
     sizeof(((ModelData *)0)->field) / sizeof(T)}
#define FIELD(d, var, T) ((T *)((char *)(d) + (var)->offset))

/* Number of values of a variable: its elements for an array, else 1. */
static inline size_t core_count(const VarInfo *v) { return v->count > 0 ? v->count : 1; }

static inline const char *core_type_name(VarType type) {
    switch (type) {
    case VT_REAL: return "Real/Float64";
    case VT_INTEGER: return "Integer/Int32";
    case VT_BOOLEAN: return "Boolean";
    case VT_STRING: return "String";
    case VT_UINT64: return "UInt64";
    default: return "Binary";
    }
}

/* Copy src into a fresh buffer owned by *dst; frees the previous value. */
static inline bool core_set_string(char **dst, const char *src) {
    size_t n;
    char *copy;
    if (src == NULL) src = "";
    n = strlen(src);
    copy = (char *)malloc(n + 1);
    if (copy == NULL) return false;
    memcpy(copy, src, n + 1);
    free(*dst);
    *dst = copy;
    return true;
}

static inline bool core_set_bytes(Bytes *dst, const unsigned char *src, size_t size) {
    unsigned char *copy = (unsigned char *)malloc(size > 0 ? size : 1);
    if (copy == NULL) return false;
    if (size > 0) memcpy(copy, src, size);
    free(dst->data);
    dst->data = copy;
    dst->size = size;
    return true;
}

#endif
