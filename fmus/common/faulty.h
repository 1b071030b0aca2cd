/* Faulty: an FMU that misbehaves on purpose, for tests of how a host survives FMUs that crash
 * or hang (fmus/faulty/README.md says how to select each behaviour).
 *
 * Normal behaviour: y = u (direct feedthrough), steps = doStep calls since initialization.
 * Faults, chosen by parameters (a negative value, the default, disables each):
 *   crash_at  doStep(t, h) with t >= crash_at writes through a null pointer (SIGSEGV);
 *   hang_at   doStep(t, h) with t >= hang_at blocks forever in C (pause() in a loop; only a
 *             signal that kills the process ends it).
 * and by the first word of resources/fault.txt, read at instantiation (no file: none):
 *   none                  no fault;
 *   crash_in_instantiate  fmi2Instantiate writes through a null pointer (SIGSEGV);
 *   hang_in_instantiate   fmi2Instantiate blocks forever.
 */
#define _POSIX_C_SOURCE 200809L /* pause() */
#include <signal.h>
#include <unistd.h>

#include "core.h"

#define MODEL_USES_RESOURCES

typedef struct {
    double crash_at, hang_at;
    double u, y;
    int steps;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, crash_at),
    VAR(2, VT_REAL, VC_PARAMETER, hang_at),
    VAR(3, VT_REAL, VC_INPUT, u),
    VAR(4, VT_REAL, VC_OUTPUT, y),
    VAR(5, VT_INTEGER, VC_OUTPUT, steps),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

/* A real invalid memory access: the pointer is volatile, so the compiler cannot drop the store. */
static void faulty_crash(void) {
    volatile int *volatile p = NULL;
    *p = 1;
    raise(SIGSEGV); /* not reached */
}

static void faulty_hang(void) {
    for (;;) pause();
}

static void model_defaults(ModelData *d) {
    d->crash_at = -1.0;
    d->hang_at = -1.0;
    d->u = 0.0;
    d->y = 0.0;
    d->steps = 0;
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)t;
    (void)initializing;
    d->y = d->u;
}

static void model_start(ModelData *d) { d->steps = 0; }

static void model_step(ModelData *d, double t, double h) {
    (void)h;
    if (d->crash_at >= 0.0 && t >= d->crash_at) faulty_crash();
    if (d->hang_at >= 0.0 && t >= d->hang_at) faulty_hang();
    d->steps += 1;
}

static bool model_load_resources(ModelData *d, const char *dir, char *msg, size_t msg_size) {
    char path[4200];
    char word[64] = "none";
    FILE *file;
    (void)d;
    snprintf(path, sizeof path, "%s/fault.txt", dir);
    file = fopen(path, "r");
    if (file != NULL) {
        if (fscanf(file, "%63s", word) != 1) strcpy(word, "none");
        fclose(file);
    }
    if (strcmp(word, "crash_in_instantiate") == 0) faulty_crash();
    if (strcmp(word, "hang_in_instantiate") == 0) faulty_hang();
    if (strcmp(word, "none") != 0) {
        snprintf(msg, msg_size, "%.600s: unknown fault '%s' (none, crash_in_instantiate, "
                                "hang_in_instantiate)", path, word);
        return false;
    }
    return true;
}

static void model_free_resources(ModelData *d) { (void)d; }
