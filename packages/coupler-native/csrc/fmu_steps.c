/* The in-process FMUs' step loop in C: one call from Python steps every member of a base step.
 *
 * Python (coupler_orchestrator.master.native_fmu_step, through the cffi binding of fmu_steps.h,
 * which declares the structs) prepares everything once per run: each member's FMI functions,
 * instance, value references and buffers (the outputs' buffers are slices of one array per
 * type, so Python reads a whole row with one slice per type), and the routing of every
 * connection as a copy from an output's slot to an input's slot. A step is then plain C: copy
 * the connected values, set them, fmi2DoStep / fmi3DoStep, get every output. No allocation, no
 * Python, no conversion per call.
 *
 * Jacobi copies every member's inputs before the first member steps (all on the outputs of
 * t_k); Gauss-Seidel copies each member's just before it steps (it sees its predecessors'
 * outputs of t_k+1). A call whose status is worse than Warning (or an FMI 3.0 request to
 * terminate, or an FMI 2.0 discard) stops the step at that member and returns its index;
 * Python says what it means and may go on from the next member.
 *
 * While a member is under way, watch[0] holds its slot and watch[1] the CLOCK_MONOTONIC time
 * it began (what Python's time.monotonic reads), for the watchdog thread; watch[0] is -1
 * between steps. timing[slot] receives each member's wall time [s].
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <stdbool.h>
#include <stddef.h>
#include <string.h>
#include <time.h>

#include "fmu_steps.h"

enum { FMI2 = 2, FMI3 = 3 };

typedef int (*fmi2_access)(void *, const unsigned int *, size_t, void *);
typedef int (*fmi3_access)(void *, const unsigned int *, size_t, void *, size_t);
typedef int (*fmi2_step)(void *, double, double, int);
typedef int (*fmi3_step)(void *, double, double, bool, bool *, bool *, bool *, double *);

static double monotonic(void) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + (double)now.tv_nsec * 1e-9;
}

static int access_call(int version, const ck_call *call, void *instance) {
    if (version == FMI2)
        return ((fmi2_access)call->function)(instance, call->refs, call->count, call->buffer);
    return ((fmi3_access)call->function)(instance, call->refs, call->count, call->buffer,
                                         call->count);
}

static void copy_inputs(const ck_member *m) {
    for (int i = 0; i < m->copies; i++)
        memcpy(m->copy[i].target, m->copy[i].source, m->copy[i].size);
}

static bool stopped(int *stop, int call, int which, int status) {
    stop[0] = call, stop[1] = which, stop[2] = status;
    return true;
}

/* The member's setters or getters in order; true (stop[] set) at the first that fails. */
static bool access_all(const ck_member *m, const ck_call *calls, int count, int call, int *stop) {
    for (int c = 0; c < count; c++) {
        int result = access_call(m->version, &calls[c], m->instance);
        if (result > 1) return stopped(stop, call, c, result);
    }
    return false;
}

/* fmi2DoStep / fmi3DoStep; true (stop[] set) when it failed or asked to terminate. */
static bool do_step(ck_member *m, double time, int *stop) {
    if (m->version == FMI2) {
        int result = ((fmi2_step)m->do_step)(m->instance, time, m->step, 1);
        return result > 1 && stopped(stop, CK_CALL_STEP, 0, result);
    }
    m->event = m->terminate = m->early = false;
    int result = ((fmi3_step)m->do_step)(m->instance, time, m->step, true, &m->event,
                                         &m->terminate, &m->early, &m->last);
    if (result > 1) return stopped(stop, CK_CALL_STEP, 0, result);
    return m->terminate && stopped(stop, CK_CALL_TERMINATE, 0, result);
}

int ck_step(ck_member *members, int n, int jacobi, int from, double time, double *timing,
            volatile double *watch, int *stop) {
    if (jacobi && from == 0)
        for (int i = 0; i < n; i++) copy_inputs(&members[i]);
    for (int i = from; i < n; i++) {
        ck_member *m = &members[i];
        double began = monotonic();
        watch[1] = began;
        watch[0] = (double)m->slot;
        if (!jacobi) copy_inputs(m);
        bool halted = access_all(m, m->set, m->sets, CK_CALL_SET, stop) || do_step(m, time, stop) ||
                      access_all(m, m->get, m->gets, CK_CALL_GET, stop);
        timing[m->slot] = monotonic() - began;
        watch[0] = -1.0;
        if (halted) return i;
    }
    return CK_DONE;
}
