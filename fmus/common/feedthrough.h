/* Feedthrough: one input and one output of every type, outputs computed directly from the
 * inputs (direct feedthrough, no state): they reflect the inputs as soon as these are set.
 *
 *   real_out = gain * real_in      int_out = int_in + int_offset
 *   bool_out = !bool_in            string_out = string_in     binary_out = binary_in (FMI 3)
 */
#include "core.h"

typedef struct {
    double gain;
    int int_offset;
    double real_in;
    int int_in;
    bool bool_in;
    char *string_in;
    Bytes binary_in;
    double real_out;
    int int_out;
    bool bool_out;
    char *string_out;
    Bytes binary_out;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, gain),
    VAR(2, VT_INTEGER, VC_PARAMETER, int_offset),
    VAR(3, VT_REAL, VC_INPUT, real_in),
    VAR(4, VT_INTEGER, VC_INPUT, int_in),
    VAR(5, VT_BOOLEAN, VC_INPUT, bool_in),
    VAR(6, VT_STRING, VC_INPUT, string_in),
    VAR(7, VT_BINARY, VC_INPUT, binary_in),
    VAR(8, VT_REAL, VC_OUTPUT, real_out),
    VAR(9, VT_INTEGER, VC_OUTPUT, int_out),
    VAR(10, VT_BOOLEAN, VC_OUTPUT, bool_out),
    VAR(11, VT_STRING, VC_OUTPUT, string_out),
    VAR(12, VT_BINARY, VC_OUTPUT, binary_out),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    d->gain = 2.0;
    d->int_offset = 0;
    d->real_in = 0.0;
    d->int_in = 0;
    d->bool_in = false;
    core_set_string(&d->string_in, "");
    core_set_bytes(&d->binary_in, NULL, 0);
    d->real_out = 0.0;
    d->int_out = 0;
    d->bool_out = true;
    core_set_string(&d->string_out, "");
    core_set_bytes(&d->binary_out, NULL, 0);
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)t;
    (void)initializing;
    d->real_out = d->gain * d->real_in;
    d->int_out = d->int_in + d->int_offset;
    d->bool_out = !d->bool_in;
    if (d->string_out == NULL || strcmp(d->string_out, d->string_in) != 0)
        core_set_string(&d->string_out, d->string_in);
    if (d->binary_out.size != d->binary_in.size || d->binary_out.data == NULL ||
        (d->binary_in.size > 0 &&
         memcmp(d->binary_out.data, d->binary_in.data, d->binary_in.size) != 0))
        core_set_bytes(&d->binary_out, d->binary_in.data, d->binary_in.size);
}

static void model_start(ModelData *d) { (void)d; }

static void model_step(ModelData *d, double t, double h) {
    (void)d;
    (void)t;
    (void)h;
}
