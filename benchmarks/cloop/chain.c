/* The physical limit of an in-process FMU chain: a bare C loop that makes the FMI calls a
 * Coupler run of the benchmark's chain (Source2 -> Feedthrough2 x n, Jacobi) makes and writes
 * the results.csv text it writes, and nothing else: no SSD, no checks, no watchdog, no
 * observers. Numbers are formatted by the algorithm Coupler's CSV row uses (CPython's
 * PyOS_double_to_string, 'r' with Py_DTSF_ADD_DOT_0: the shortest text that reads back to the
 * same double, which float.__repr__ gives), with the same reuse of a cell's text while its
 * value does not change. benchmarks/suite.py builds it (cloop.py), runs it beside `coupler run`
 * on the same FMUs and checks that both wrote the same bytes.
 *
 *   chain N STEPS DENOMINATOR OUT SOURCE_SO SOURCE_GUID SOURCE_URI FEED_SO FEED_GUID FEED_URI
 *
 * The step is 1/DENOMINATOR s; t_k = k / DENOMINATOR, as Coupler's grid computes it. Prints
 * the loop's wall time in seconds from the first row to the last (instantiation,
 * initialization and closing the file are not counted, as the suite's clock counts Coupler's).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2DoStepTYPE *do_step;
    fmi2GetRealTYPE *get_real;
    fmi2GetIntegerTYPE *get_integer;
    fmi2GetBooleanTYPE *get_boolean;
    fmi2GetStringTYPE *get_string;
    fmi2SetRealTYPE *set_real;
} Api;

/* A cell's last value and its text (Coupler's rows.c keeps the same). */
typedef struct {
    double real;
    int integer;
    int size;
    char text[40];
} Last;

static void fail(const char *what, const char *detail) {
    fprintf(stderr, "chain: %s: %s\n", what, detail);
    exit(2);
}

static void *symbol(void *library, const char *name) {
    void *found = dlsym(library, name);
    if (found == NULL) fail("missing FMI function", name);
    return found;
}

static Api load(const char *path) {
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) fail("cannot load", dlerror());
    Api api = {
        symbol(library, "fmi2Instantiate"),
        symbol(library, "fmi2SetupExperiment"),
        symbol(library, "fmi2EnterInitializationMode"),
        symbol(library, "fmi2ExitInitializationMode"),
        symbol(library, "fmi2DoStep"),
        symbol(library, "fmi2GetReal"),
        symbol(library, "fmi2GetInteger"),
        symbol(library, "fmi2GetBoolean"),
        symbol(library, "fmi2GetString"),
        symbol(library, "fmi2SetReal"),
    };
    return api;
}

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env, (void)name, (void)status, (void)category, (void)message;
}

static const fmi2CallbackFunctions CALLBACKS = {logger, calloc, free, NULL, NULL};

static fmi2Component start(const Api *api, const char *name, const char *guid, const char *uri) {
    fmi2Component c = api->instantiate(name, fmi2CoSimulation, guid, uri, &CALLBACKS, 0, 0);
    if (c == NULL) fail("fmi2Instantiate failed", name);
    if (api->setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) > fmi2Warning ||
        api->enter(c) > fmi2Warning || api->exit_init(c) > fmi2Warning)
        fail("initialization failed", name);
    return c;
}

static void real_cell(FILE *out, Last *last, double value) {
    if (last->size == 0 || memcmp(&last->real, &value, sizeof value) != 0) {
        char *text = PyOS_double_to_string(value, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
        last->size = (int)strlen(text);
        memcpy(last->text, text, (size_t)last->size);
        PyMem_Free(text);
        last->real = value;
    }
    fputc(',', out);
    fwrite(last->text, 1, (size_t)last->size, out);
}

static void integer_cell(FILE *out, Last *last, int value) {
    if (last->size == 0 || last->integer != value) {
        last->size = snprintf(last->text, sizeof last->text, "%d", value);
        last->integer = value;
    }
    fputc(',', out);
    fwrite(last->text, 1, (size_t)last->size, out);
}

/* A String cell as the csv module writes it: quoted when it holds a comma, quote or newline. */
static void string_cell(FILE *out, const char *value) {
    fputc(',', out);
    if (strpbrk(value, ",\"\r\n") == NULL) {
        fputs(value, out);
        return;
    }
    fputc('"', out);
    for (const char *c = value; *c; c++) {
        if (*c == '"') fputc('"', out);
        fputc(*c, out);
    }
    fputc('"', out);
}

int main(int argc, char **argv) {
    if (argc != 11)
        fail("usage", "chain N STEPS DENOMINATOR OUT SOURCE_SO SOURCE_GUID SOURCE_URI FEED_SO "
                      "FEED_GUID FEED_URI");
    int n = atoi(argv[1]);
    long steps = atol(argv[2]);
    double denominator = atof(argv[3]);
    Py_InitializeEx(0); /* PyOS_double_to_string's memory */
    Api source_api = load(argv[5]), feed_api = load(argv[8]);
    fmi2Component source = start(&source_api, "Source", argv[6], argv[7]);
    fmi2Component *feeds = calloc((size_t)n, sizeof *feeds);
    for (int k = 0; k < n; k++) {
        char name[32];
        snprintf(name, sizeof name, "Feed%d", k + 1);
        feeds[k] = start(&feed_api, name, argv[9], argv[10]);
    }
    FILE *out = fopen(argv[4], "w");
    if (out == NULL) fail("cannot write", argv[4]);
    static char buffer[1 << 16];
    setvbuf(out, buffer, _IOFBF, sizeof buffer);
    fputs("time,Source.ramp,Source.sine,Source.counter", out);
    for (int k = 1; k <= n; k++)
        fprintf(out, ",Feed%d.real_out,Feed%d.int_out,Feed%d.bool_out,Feed%d.string_out", k, k, k, k);
    fputc('\n', out);

    const fmi2ValueReference source_reals[] = {5, 6}, source_counter = 7;
    const fmi2ValueReference feed_in = 3, feed_real = 8, feed_int = 9, feed_bool = 10,
                             feed_string = 11;
    double *reals = calloc((size_t)(2 + n), sizeof *reals); /* ramp, sine, each feed's real */
    int counter = 0;
    int *ints = calloc((size_t)n, sizeof *ints);
    int *bools = calloc((size_t)n, sizeof *bools);
    const char **strings = calloc((size_t)n, sizeof *strings);
    Last *last = calloc((size_t)(3 + 3 * n), sizeof *last); /* time, ramp, sine, counter, per feed */
    const double h = 1.0 / denominator;

    struct timespec began, ended; /* from the first row to the last, as the suite's clock */
    for (long k = 0; k <= steps; k++) {
        if (k > 0) { /* Jacobi: every input from the outputs of t_k, then every member steps */
            double t = (double)(k - 1) / denominator;
            double inputs[n];
            inputs[0] = reals[0];
            for (int j = 1; j < n; j++) inputs[j] = reals[2 + j - 1];
            for (int j = 0; j < n; j++) feed_api.set_real(feeds[j], &feed_in, 1, &inputs[j]);
            if (source_api.do_step(source, t, h, fmi2True) > fmi2Warning) fail("step", "Source");
            for (int j = 0; j < n; j++)
                if (feed_api.do_step(feeds[j], t, h, fmi2True) > fmi2Warning) fail("step", "Feed");
        }
        source_api.get_real(source, source_reals, 2, reals);
        source_api.get_integer(source, &source_counter, 1, &counter);
        for (int j = 0; j < n; j++) {
            feed_api.get_real(feeds[j], &feed_real, 1, &reals[2 + j]);
            feed_api.get_integer(feeds[j], &feed_int, 1, &ints[j]);
            feed_api.get_boolean(feeds[j], &feed_bool, 1, &bools[j]);
            feed_api.get_string(feeds[j], &feed_string, 1, &strings[j]);
        }
        /* the row: time first (Coupler's first cell is a Real too) */
        double now = (double)k / denominator;
        char *text = PyOS_double_to_string(now, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
        fputs(text, out);
        PyMem_Free(text);
        real_cell(out, &last[0], reals[0]);
        real_cell(out, &last[1], reals[1]);
        integer_cell(out, &last[2], counter);
        for (int j = 0; j < n; j++) {
            real_cell(out, &last[3 + 3 * j], reals[2 + j]);
            integer_cell(out, &last[4 + 3 * j], ints[j]);
            fputc(',', out);
            fputc(bools[j] ? '1' : '0', out);
            string_cell(out, strings[j]);
        }
        fputc('\n', out);
        if (k == 0) clock_gettime(CLOCK_MONOTONIC, &began);
    }
    clock_gettime(CLOCK_MONOTONIC, &ended);
    fclose(out);
    printf("%.9f\n", (double)(ended.tv_sec - began.tv_sec) + 1e-9 * (double)(ended.tv_nsec - began.tv_nsec));
    return 0;
}
