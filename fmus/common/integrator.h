/* Integrator: x' = u by explicit Euler, one Euler step per communication step.
 *
 * x = x0 at the end of initialization (x0 as set before then); doStep(t, h) does exactly
 * x := x + u*h with the value of u set before that doStep call. Hence, with inputs u_0, u_1,
 * ... applied before steps 0, 1, ... of sizes h_0, h_1, ...:
 *   x_k = x0 + sum_{i<k} h_i * u_i     (x_k = x0 + h * (u_0 + ... + u_{k-1}) for a fixed h).
 */
#include "core.h"

typedef struct {
    double x0;
    double u;
    double x;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, x0),
    VAR(2, VT_REAL, VC_INPUT, u),
    VAR(3, VT_REAL, VC_OUTPUT, x),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    d->x0 = 0.0;
    d->u = 0.0;
    d->x = 0.0;
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)t;
    if (initializing) d->x = d->x0;
}

static void model_start(ModelData *d) { d->x = d->x0; }

static void model_step(ModelData *d, double t, double h) {
    (void)t;
    d->x += d->u * h;
}
