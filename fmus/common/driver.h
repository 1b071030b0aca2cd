/* Driver: a deterministic train driver for a run from one station to a stop point.
 *
 * Inputs distance [m] (travelled) and speed [m/s]; at every communication point (direct
 * feedthrough, evaluated with the inputs set before it):
 *   remaining = stop_distance - distance
 *   v_ref     = min(target_speed, sqrt(2 * service_decel * max(remaining, 0)))
 *   error     = v_ref - speed
 *   throttle  = clamp(kp_throttle * error, 0, 1)           when error > 0, else 0
 *   brake     = clamp(-kp_brake * error, 0, 1)             when error <= 0, else 0
 *   brake     = 1, throttle = 0                            once remaining <= 0 (hold at stop)
 * so the train accelerates to target_speed, cruises, and brakes on a constant-deceleration
 * curve to stand at stop_distance.
 */
#include "core.h"

typedef struct {
    double target_speed, stop_distance, service_decel, kp_throttle, kp_brake;
    double distance, speed;
    double throttle, brake, v_ref;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, target_speed),
    VAR(2, VT_REAL, VC_PARAMETER, stop_distance),
    VAR(3, VT_REAL, VC_PARAMETER, service_decel),
    VAR(4, VT_REAL, VC_PARAMETER, kp_throttle),
    VAR(5, VT_REAL, VC_PARAMETER, kp_brake),
    VAR(6, VT_REAL, VC_INPUT, distance),
    VAR(7, VT_REAL, VC_INPUT, speed),
    VAR(8, VT_REAL, VC_OUTPUT, throttle),
    VAR(9, VT_REAL, VC_OUTPUT, brake),
    VAR(10, VT_REAL, VC_OUTPUT, v_ref),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

static void model_defaults(ModelData *d) {
    d->target_speed = 16.0;
    d->stop_distance = 1000.0;
    d->service_decel = 0.5;
    d->kp_throttle = 0.5;
    d->kp_brake = 0.5;
    d->distance = 0.0;
    d->speed = 0.0;
    d->throttle = 0.0;
    d->brake = 0.0;
    d->v_ref = 0.0;
}

static double clamp01(double v) { return v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v); }

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)t;
    (void)initializing;
    double remaining = d->stop_distance - d->distance;
    double curve = sqrt(2.0 * d->service_decel * (remaining > 0.0 ? remaining : 0.0));
    d->v_ref = curve < d->target_speed ? curve : d->target_speed;
    if (remaining <= 0.0) {
        d->throttle = 0.0;
        d->brake = 1.0;
        return;
    }
    double error = d->v_ref - d->speed;
    d->throttle = error > 0.0 ? clamp01(d->kp_throttle * error) : 0.0;
    d->brake = error > 0.0 ? 0.0 : clamp01(-d->kp_brake * error);
}

static void model_start(ModelData *d) { (void)d; }

static void model_step(ModelData *d, double t, double h) {
    (void)d;
    (void)t;
    (void)h;
}
