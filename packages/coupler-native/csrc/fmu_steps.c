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
 * While a member is under way, watch[0] holds its slot, watch[1] the CLOCK_MONOTONIC time it
 * began (what Python's time.monotonic reads) and watch[2] the step's time, for the watchdog
 * thread; watch[0] is -1 between steps. timing[slot] receives each member's wall time [s].
 *
 * ck_steps takes several base steps in one call, when nothing in Python has to run between
 * them (the master decides), and logs each one's row in a ck_log: the values of the recorded
 * slots after the step (numbers as they are, strings copied), the time it reached and its
 * members' timing. Python tells its observers about the whole log at once.
 */
#define _POSIX_C_SOURCE 199309L /* clock_gettime */
#include <stdbool.h>
#include <stddef.h>
#include <sched.h>
#include <stdlib.h>
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
        watch[2] = time;
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

ck_log *ck_log_new(int cells, const ck_cell *cell, int slots, int capacity) {
    ck_log *log = calloc(1, sizeof *log);
    if (log == NULL) return NULL;
    log->cells = cells, log->slots = slots, log->capacity = capacity;
    log->cell = malloc(sizeof *log->cell * (size_t)(cells ? cells : 1));
    log->time = malloc(sizeof *log->time * (size_t)capacity);
    log->value = malloc(sizeof *log->value * (size_t)(cells ? cells : 1) * (size_t)capacity);
    log->timing = malloc(sizeof *log->timing * (size_t)(slots ? slots : 1) * (size_t)capacity);
    log->size = 4096;
    log->text = malloc(log->size);
    if (log->cell == NULL || log->time == NULL || log->value == NULL || log->timing == NULL ||
        log->text == NULL) {
        ck_log_free(log);
        return NULL;
    }
    if (cells) memcpy(log->cell, cell, sizeof *log->cell * (size_t)cells);
    return log;
}

void ck_log_free(ck_log *log) {
    if (log == NULL) return;
    free(log->cell);
    free(log->time);
    free(log->value);
    free(log->timing);
    free(log->text);
    free(log);
}

/* A copy of `text` in the log's text (the previous row's, when it holds the same string);
 * its offset, -1 for NULL, or CK_NO_MEMORY - 1 (-3) when it does not fit. */
static long long logged_text(ck_log *log, const char *text, const ck_value *before) {
    if (text == NULL) return -1;
    if (before != NULL && before->integer >= 0 && strcmp(log->text + before->integer, text) == 0)
        return before->integer;
    size_t size = strlen(text) + 1;
    if (log->used + size > log->size) {
        size_t grown = log->size;
        while (log->used + size > grown) grown *= 2;
        char *moved = realloc(log->text, grown);
        if (moved == NULL) return -3;
        log->text = moved, log->size = grown;
    }
    memcpy(log->text + log->used, text, size);
    log->used += size;
    return (long long)(log->used - size);
}

/* The log's state: FREE (nobody is touching its rows), BUSY (ck_steps is writing a row, or
 * its caller is taking them), CLAIMED (another thread took it: ck_steps writes no more). */
enum { FREE = 0, BUSY = 1, CLAIMED = 2 };

/* FREE -> BUSY for the thread stepping; false when the log is claimed. */
static bool hold(ck_log *log) {
    int free = FREE;
    return __atomic_compare_exchange_n(&log->state, &free, BUSY, false, __ATOMIC_ACQUIRE,
                                       __ATOMIC_RELAXED);
}

static void release(ck_log *log) { __atomic_store_n(&log->state, FREE, __ATOMIC_RELEASE); }

/* The recorded slots' values after step `row` into the log; false when a string did not fit. */
static bool log_row(ck_log *log, int row) {
    ck_value *value = log->value + (size_t)row * (size_t)log->cells;
    const ck_value *before = row ? value - log->cells : NULL;
    for (int c = 0; c < log->cells; c++) {
        const void *at = log->cell[c].source;
        switch (log->cell[c].code) {
        case 'd': value[c].real = *(const double *)at; break;
        case 'i': value[c].integer = *(const int *)at; break;
        case 'q': value[c].integer = *(const long long *)at; break;
        case 'b': value[c].integer = *(const int *)at != 0; break;
        case '?': value[c].integer = *(const bool *)at; break;
        default:
            value[c].integer = logged_text(log, *(const char *const *)at, before ? &before[c] : NULL);
            if (value[c].integer < -1) return false;
        }
    }
    return true;
}

int ck_steps(ck_member *members, int n, int jacobi, double origin, double stride, double scale,
             long long k0, int count, double budget, double *timing, volatile double *watch,
             int *stop, ck_log *log) {
    double began = monotonic();
    if (!hold(log)) return CK_CLAIMED;
    log->count = 0, log->used = 0, log->taken = 0;
    release(log);
    if (count > log->capacity) count = log->capacity;
    for (int j = 0; j < count; j++) {
        double k = (double)(k0 + j);
        int stopped = ck_step(members, n, jacobi, 0, (origin + k * stride) / scale, timing, watch,
                              stop);
        if (stopped != CK_DONE) return stopped;
        if (!hold(log)) return CK_CLAIMED;
        bool logged = log_row(log, j);
        if (logged) {
            log->time[j] = (origin + (k + 1) * stride) / scale;
            memcpy(log->timing + (size_t)j * (size_t)log->slots, timing,
                   sizeof *timing * (size_t)log->slots);
            log->count = j + 1;
        }
        release(log);
        if (!logged) return CK_NO_MEMORY;
        if (monotonic() - began >= budget) break;
    }
    return CK_DONE;
}

/* The rows not handed over yet, now handed over (the log held). */
static int hand_over(ck_log *log) {
    int rows = log->taken ? 0 : log->count;
    log->taken = 1;
    return rows;
}

int ck_log_take(ck_log *log) {
    if (!hold(log)) return 0; /* claimed: the rows are the claimer's */
    int rows = hand_over(log);
    release(log);
    return rows;
}

int ck_log_claim(ck_log *log) {
    for (;;) {
        int state = FREE;
        if (__atomic_compare_exchange_n(&log->state, &state, CLAIMED, false, __ATOMIC_ACQUIRE,
                                        __ATOMIC_RELAXED))
            return hand_over(log);
        if (state == CLAIMED) return 0;
        sched_yield(); /* BUSY: a row being written, which takes microseconds */
    }
}
