/* Stair: a counter that rises by one every `period` seconds and asks to end the simulation at
 * `terminate_at` (after the Modelica Reference FMU of that name, which stops at t = 9).
 *
 * At every time t reached: counter = 1 + floor(t / period) (1 at t = 0, 10 at t = 9 with the
 * defaults). The step that reaches terminate_at stops there, also inside a communication step
 * (doStep(8, 2) ends at t = 9), and the model asks to end the simulation: FMI 2.0 answers
 * fmi2Discard with fmi2Terminated and fmi2LastSuccessfulTime = 9, FMI 3.0 sets
 * terminateSimulation and lastSuccessfulTime = 9. A step that starts at or after terminate_at
 * ends normally and asks to end the simulation at its end.
 */
#include "core.h"

#define MODEL_CAN_TERMINATE

typedef struct {
    double period, terminate_at;
    int counter;
    bool ended;
    double ended_at;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, period),
    VAR(2, VT_REAL, VC_PARAMETER, terminate_at),
    VAR(3, VT_INTEGER, VC_OUTPUT, counter),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    d->period = 1.0;
    d->terminate_at = 9.0;
    d->counter = 1;
    d->ended = false;
    d->ended_at = 0.0;
}

/* Whether a and b are equal up to rounding of times around their magnitude. */
static bool stair_close(double a, double b) {
    return fabs(a - b) <= 1e-9 * fmax(1.0, fmax(fabs(a), fabs(b)));
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)initializing;
    if (d->period > 0.0) d->counter = 1 + (int)floor(t / d->period + 1e-9);
}

static void model_start(ModelData *d) { d->ended = false; }

static void model_step(ModelData *d, double t, double h) {
    double end = t + h;
    if (d->ended) return;
    if (end > d->terminate_at || stair_close(end, d->terminate_at)) {
        d->ended = true;
        d->ended_at = d->terminate_at > t && !stair_close(end, d->terminate_at) ? d->terminate_at
                                                                                 : end;
    }
}

static bool model_ends(const ModelData *d, double *time) {
    if (d->ended) *time = d->ended_at;
    return d->ended;
}
