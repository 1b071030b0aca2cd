/* The native FMU step's interface: what Python prepares and the one call that steps a base
 * step. Declared here only: fmu_steps.c includes it, and so does its Python face,
 * fmu_steps_module.c, which builds these structs from what Python gives it (no preprocessor
 * lines here: the includer brings <stdbool.h> and <stddef.h>).
 *
 * Python (coupler_orchestrator.master.native_fmu_step) fills one ck_member per member, in stepping order:
 * its FMI instance and fmi2DoStep/fmi3DoStep, its setter and getter calls (each a function,
 * its value references, their count and a buffer) and the copies that route connected
 * outputs to its inputs' buffers.
 *
 * Several base steps go in one call (ck_steps) when nothing in Python needs to run between
 * them: each finished step's row is then logged (ck_log) for the observers to read in one go.
 */

enum { CK_DONE = -1, CK_NO_MEMORY = -2, CK_CLAIMED = -3 };
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
 * member is under way watch[0] holds its slot, watch[1] the CLOCK_MONOTONIC time it began and
 * watch[2] the step's time; timing[slot] receives each member's wall time [s]. */
int ck_step(ck_member *members, int n, int jacobi, int from, double time, double *timing,
            volatile double *watch, int *stop);

/* A column of the row log: its output's slot and the slot's C type: 'd' double, 'i' int,
 * 'q' int64, 'b' int as a Boolean, '?' bool, 's' char * (copied into the log: a string lives in
 * its FMU's memory only until that FMU's next call). */
typedef struct {
    const void *source;
    char code;
} ck_cell;

/* A logged value: code 'd' in `real`, the others in `integer` ('b' and '?' as 0 or 1; 's' the
 * offset of the string's copy in the log's text, -1 for a NULL pointer). */
typedef union {
    double real;
    long long integer;
} ck_value;

/* The rows of the base steps one ck_steps call took: for each, the communication point it
 * reached, every column's value there and each member's wall time of the step. Read by
 * coupler_native._rows (RowLog: the rows as Python values; RowFormat.lines: results.csv). */
typedef struct {
    int cells;
    ck_cell *cell;
    int slots;       /* timing values per row (one per member) */
    int capacity;    /* rows it can hold */
    int count;       /* rows logged */
    double *time;    /* [capacity] */
    ck_value *value; /* [capacity * cells] */
    double *timing;  /* [capacity * slots] */
    char *text;      /* the strings' copies, each NUL-terminated */
    size_t used, size;
    int state;       /* who may touch the rows (fmu_steps.c: FREE, BUSY, CLAIMED) */
    int taken;       /* the rows were handed over (ck_log_take, ck_log_claim) */
} ck_log;

/* A log of `capacity` rows of `cells` columns (copied from `cell`) and `slots` timings; NULL
 * when out of memory. ck_log_free releases it. */
ck_log *ck_log_new(int cells, const ck_cell *cell, int slots, int capacity);
void ck_log_free(ck_log *log);

/* Base steps k0, k0 + 1, ... (step k from t_k = (origin + k * stride) / scale: integers that
 * doubles hold exactly, so t_k is the correctly rounded quotient Python's int / int gives),
 * each as ck_step steps it from member 0, until `count` are done, the log is full or `budget`
 * seconds have passed (at least one step is taken). The log starts empty; each step taken
 * whole is logged: its row at t_{k+1}, and its members' timing. Returns CK_DONE; or the index
 * of the member that stopped step k0 + log->count (stop[] as ck_step sets it; that step is
 * not logged, its members after the one that stopped have not stepped); or CK_NO_MEMORY (a
 * string's copy did not fit; that step is not logged either, but every member stepped); or
 * CK_CLAIMED (ck_log_claim took the log). */
int ck_steps(ck_member *members, int n, int jacobi, double origin, double stride, double scale,
             long long k0, int count, double budget, double *timing, volatile double *watch,
             int *stop, ck_log *log);

/* The rows of the last ck_steps call are handed over once: to its caller once it has returned
 * (ck_log_take), or to another thread while it is still under way (ck_log_claim: the watchdog
 * ending a run whose member hangs), after which ck_steps logs nothing more and returns
 * CK_CLAIMED. Each returns how many rows (from row 0) are its to read; 0 when they were
 * handed over already. */
int ck_log_take(ck_log *log);
int ck_log_claim(ck_log *log);
