/* StateSpace: a linear time-invariant system with array variables (FMI 3.0 only), after the
 * Modelica Reference FMU of that name; 2 states, 3 inputs, 2 outputs, fixed at build time.
 *
 *   x' = A x + B u      y = C x + D u      x = x0 at the end of initialization
 *
 * by explicit Euler, one step per communication step: doStep(t, h) does x := x + h (A x + B u)
 * with the u set before that call; y follows u directly. Matrices are row-major (B[i][j] is
 * B[i+1,j+1] in the model description). The structural parameters nx = 2 and nu = 3 size the
 * arrays in the model description; this build has exactly those sizes.
 */
#include "core.h"

#define SS_NX 2
#define SS_NU 3
#define SS_NY 2

typedef struct {
    uint64_t nx, nu;
    double A[SS_NX][SS_NX], B[SS_NX][SS_NU], C[SS_NY][SS_NX], D[SS_NY][SS_NU];
    double x0[SS_NX];
    double u[SS_NU];
    double y[SS_NY];
    double x[SS_NX];
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_UINT64, VC_PARAMETER, nx),
    VAR(2, VT_UINT64, VC_PARAMETER, nu),
    ARRAY(3, VT_REAL, VC_PARAMETER, A, double),
    ARRAY(4, VT_REAL, VC_PARAMETER, B, double),
    ARRAY(5, VT_REAL, VC_PARAMETER, C, double),
    ARRAY(6, VT_REAL, VC_PARAMETER, D, double),
    ARRAY(7, VT_REAL, VC_PARAMETER, x0, double),
    ARRAY(8, VT_REAL, VC_INPUT, u, double),
    ARRAY(9, VT_REAL, VC_OUTPUT, y, double),
    ARRAY(10, VT_REAL, VC_OUTPUT, x, double),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

/* The start values of the model description, in the same order. */
static void model_defaults(ModelData *d) {
    static const double A[SS_NX][SS_NX] = {{0.0, 1.0}, {-2.0, -0.5}};
    static const double B[SS_NX][SS_NU] = {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.5}};
    static const double C[SS_NY][SS_NX] = {{1.0, 0.0}, {0.5, 1.0}};
    static const double D[SS_NY][SS_NU] = {{0.0, 0.0, 0.0}, {0.0, 0.0, 1.0}};
    static const double x0[SS_NX] = {1.0, 0.0};
    static const double u[SS_NU] = {0.5, -1.0, 2.0};
    d->nx = SS_NX;
    d->nu = SS_NU;
    memcpy(d->A, A, sizeof A);
    memcpy(d->B, B, sizeof B);
    memcpy(d->C, C, sizeof C);
    memcpy(d->D, D, sizeof D);
    memcpy(d->x0, x0, sizeof x0);
    memcpy(d->u, u, sizeof u);
    memcpy(d->x, x0, sizeof x0);
    memset(d->y, 0, sizeof d->y);
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    int i, j;
    (void)t;
    if (initializing) memcpy(d->x, d->x0, sizeof d->x);
    for (i = 0; i < SS_NY; i++) {
        d->y[i] = 0.0;
        for (j = 0; j < SS_NX; j++) d->y[i] += d->C[i][j] * d->x[j];
        for (j = 0; j < SS_NU; j++) d->y[i] += d->D[i][j] * d->u[j];
    }
}

static void model_start(ModelData *d) { memcpy(d->x, d->x0, sizeof d->x); }

static void model_step(ModelData *d, double t, double h) {
    double dx[SS_NX];
    int i, j;
    (void)t;
    for (i = 0; i < SS_NX; i++) {
        dx[i] = 0.0;
        for (j = 0; j < SS_NX; j++) dx[i] += d->A[i][j] * d->x[j];
        for (j = 0; j < SS_NU; j++) dx[i] += d->B[i][j] * d->u[j];
    }
    for (i = 0; i < SS_NX; i++) d->x[i] += h * dx[i];
}
