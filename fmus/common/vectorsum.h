/* VectorSum: two 3-element vectors added element by element, as FMI 2.0 scalar variables named
 * by the structured naming convention (a[1], a[2], a[3]), the way OpenMCx's vector ports
 * (`<mc:RealVector startIndex="1" endIndex="3"/>`) bind to an FMU.
 *
 *   s[i] = a[i] + b[i]  (i = 1, 2, 3)      total = s[1] + s[2] + s[3]
 *
 * Direct feedthrough, no state: the outputs reflect the inputs as soon as these are set.
 */
#include "core.h"

#define VS_N 3

typedef struct {
    double a[VS_N], b[VS_N];
    double s[VS_N];
    double total;
} ModelData;

#define ELEMENT(vr, causality, field, i, name) \
    {vr, VT_REAL, causality, offsetof(ModelData, field) + (i) * sizeof(double), name, 0}

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    ELEMENT(1, VC_INPUT, a, 0, "a[1]"),
    ELEMENT(2, VC_INPUT, a, 1, "a[2]"),
    ELEMENT(3, VC_INPUT, a, 2, "a[3]"),
    ELEMENT(4, VC_INPUT, b, 0, "b[1]"),
    ELEMENT(5, VC_INPUT, b, 1, "b[2]"),
    ELEMENT(6, VC_INPUT, b, 2, "b[3]"),
    ELEMENT(7, VC_OUTPUT, s, 0, "s[1]"),
    ELEMENT(8, VC_OUTPUT, s, 1, "s[2]"),
    ELEMENT(9, VC_OUTPUT, s, 2, "s[3]"),
    VAR(10, VT_REAL, VC_OUTPUT, total),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    int i;
    for (i = 0; i < VS_N; i++) {
        d->a[i] = 0.0;
        d->b[i] = 0.0;
        d->s[i] = 0.0;
    }
    d->total = 0.0;
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    int i;
    (void)t;
    (void)initializing;
    d->total = 0.0;
    for (i = 0; i < VS_N; i++) {
        d->s[i] = d->a[i] + d->b[i];
        d->total += d->s[i];
    }
}

static void model_start(ModelData *d) { (void)d; }

static void model_step(ModelData *d, double t, double h) {
    (void)d;
    (void)t;
    (void)h;
}
