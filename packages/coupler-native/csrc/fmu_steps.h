/* The native FMU step's interface: what Python prepares and the one call that steps a base
 * step. Declared here only: fmu_steps.c includes it, and the cffi binding reads it (its cdef;
 * so no preprocessor lines here: the includer brings <stdbool.h> and <stddef.h>).
 *
 * Python (coupler_orchestrator.master.native_fmu_step) fills one ck_member per member, in stepping order:
 * its FMI instance and fmi2DoStep/fmi3DoStep, its setter and getter calls (each a function,
 * its value references, their count and a buffer) and the copies that route connected
 * outputs to its inputs' buffers.
 */

enum { CK_DONE = -1 };
/* what stop[0] names when a step stops at a member */
enum { CK_CALL_SET = 0, CK_CALL_STEP = 1, CK_CALL_GET = 2, CK_CALL_TERMINATE = 3 };

typedef struct {
    void *function;
    const unsigned int *refs;
    size_t count;
    void *buffer;
} ck_call;

typedef struct {
    void *target;
    const void *source;
    size_t size;
} ck_copy;

typedef struct {
    void *instance;
    void *do_step;
    double step;
    int version;
    int slot;
    int copies;
    const ck_copy *copy;
    int sets;
    const ck_call *set;
    int gets;
    const ck_call *get;
    /* fmi3DoStep's answers */
    bool event, terminate, early;
    double last;
} ck_member;

/* Steps members[from..n) at `time`; CK_DONE, or the index of the member that stopped the step
 * with stop[0] = CK_CALL_*, stop[1] = which set/get and stop[2] = the FMI status. While a
 * member is under way watch[0] holds its slot and watch[1] the CLOCK_MONOTONIC time it began;
 * timing[slot] receives each member's wall time [s]. */
int ck_step(ck_member *members, int n, int jacobi, int from, double time, double *timing,
            volatile double *watch, int *stop);
