/* Source: a ramp, a sine and a step counter, functions of time only.
 *
 * At every communication point t (the start time after initialization, t + h after
 * doStep(t, h)):  ramp = slope*t + offset,  sine = amplitude*sin(2*pi*freq*t),
 * counter = number of doStep calls completed since initialization (0 before the first).
 */
#include "core.h"

typedef struct {
    double slope, offset, amplitude, freq;
    double ramp, sine;
    int counter;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, slope),
    VAR(2, VT_REAL, VC_PARAMETER, offset),
    VAR(3, VT_REAL, VC_PARAMETER, amplitude),
    VAR(4, VT_REAL, VC_PARAMETER, freq),
    VAR(5, VT_REAL, VC_OUTPUT, ramp),
    VAR(6, VT_REAL, VC_OUTPUT, sine),
    VAR(7, VT_INTEGER, VC_OUTPUT, counter),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    d->slope = 1.0;
    d->offset = 0.0;
    d->amplitude = 1.0;
    d->freq = 1.0;
    d->ramp = 0.0;
    d->sine = 0.0;
    d->counter = 0;
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)initializing;
    d->ramp = d->slope * t + d->offset;
    d->sine = d->amplitude * sin(2.0 * M_PI * d->freq * t);
}

static void model_start(ModelData *d) { d->counter = 0; }

static void model_step(ModelData *d, double t, double h) {
    (void)t;
    (void)h;
    d->counter += 1;
}
