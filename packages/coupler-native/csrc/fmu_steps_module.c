/* coupler_native._fmu_steps: the native FMU step (fmu_steps.h, implemented by fmu_steps.c) as a
 * CPython extension of the stable ABI (Python 3.11 on).
 *
 * coupler_orchestrator.master.native_fmu_step describes each member as plain numbers (the
 * addresses of its FMI instance, functions, value references and buffers, which ctypes holds)
 * and this module builds the C structs of fmu_steps.h from them, once:
 *
 *   Members(members, timing, watch, stop, jacobi)
 *       members: per member, in stepping order, (instance, do_step, step, version, slot,
 *                copies [(target, source, size)], sets [(function, refs, count, buffer)],
 *                gets [(function, refs, count, buffer)]); timing, watch, stop: the addresses
 *                of the arrays ck_step writes (double[members], double[3], int[3])
 *   .step(start, time) -> int                     ck_step
 *   .steps(origin, stride, scale, k0, count, budget, log) -> int    ck_steps
 *   .last(index) -> float                         the member's fmi3DoStep lastSuccessfulTime
 *   Log(cells, slots, capacity)  cells: [(address, code)]          ck_log_new (freed with it)
 *   .address -> int   .take() -> int   .claim() -> int
 *
 * Steps run without the GIL: the watchdog's thread watches them (and claims the log of a
 * batch whose member hangs).
 */
#define Py_LIMITED_API 0x030B0000
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

#include "fmu_steps.h"

/* --- Log -------------------------------------------------------------------------------- */

typedef struct {
    PyObject_HEAD
    ck_log *log;
} Log;

static void *address_of(PyObject *number) {
    return (void *)(uintptr_t)PyLong_AsUnsignedLongLong(number);
}

static int Log_init(PyObject *self_, PyObject *args, PyObject *kwargs) {
    Log *self = (Log *)self_;
    PyObject *cells;
    int slots, capacity;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "Log takes no keyword arguments");
        return -1;
    }
    if (self->log != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Log is made already");
        return -1;
    }
    if (!PyArg_ParseTuple(args, "Oii", &cells, &slots, &capacity)) return -1;
    Py_ssize_t count = PySequence_Size(cells);
    if (count < 0) return -1;
    ck_cell *cell = calloc((size_t)count + 1, sizeof(ck_cell));
    if (cell == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    int failed = 0;
    for (Py_ssize_t i = 0; !failed && i < count; ++i) {
        PyObject *item = PySequence_GetItem(cells, i);
        PyObject *address;
        const char *code;
        Py_ssize_t length;
        if (item == NULL || !PyArg_ParseTuple(item, "Os#", &address, &code, &length) ||
            length != 1) {
            if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "a cell's code: one letter");
            failed = 1;
        } else {
            cell[i].source = address_of(address);
            cell[i].code = code[0];
            failed = PyErr_Occurred() != NULL;
        }
        Py_XDECREF(item);
    }
    if (!failed) {
        self->log = ck_log_new((int)count, cell, slots, capacity);
        if (self->log == NULL) {
            PyErr_SetString(PyExc_MemoryError, "no memory for the native FMU step's row log");
            failed = 1;
        }
    }
    free(cell);
    return failed ? -1 : 0;
}

static int made_or_raise(Log *self) {
    if (self->log != NULL) return 1;
    PyErr_SetString(PyExc_ValueError, "the log was not made");
    return 0;
}

static PyObject *Log_address(PyObject *self_, void *closure) {
    (void)closure;
    Log *self = (Log *)self_;
    if (!made_or_raise(self)) return NULL;
    return PyLong_FromUnsignedLongLong((unsigned long long)(uintptr_t)self->log);
}

static PyObject *Log_take(PyObject *self_, PyObject *unused) {
    (void)unused;
    Log *self = (Log *)self_;
    if (!made_or_raise(self)) return NULL;
    return PyLong_FromLong(ck_log_take(self->log));
}

static PyObject *Log_claim(PyObject *self_, PyObject *unused) {
    (void)unused;
    Log *self = (Log *)self_;
    if (!made_or_raise(self)) return NULL;
    return PyLong_FromLong(ck_log_claim(self->log));
}

static void Log_dealloc(PyObject *self_) {
    Log *self = (Log *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    if (self->log != NULL) ck_log_free(self->log);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyMethodDef Log_methods[] = {
    {"take", Log_take, METH_NOARGS,
     "take() -> int: the rows of the last steps call, handed over once (ck_log_take)"},
    {"claim", Log_claim, METH_NOARGS,
     "claim() -> int: the rows of a steps call under way, from another thread (ck_log_claim)"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Log_getset[] = {
    {"address", Log_address, NULL, "the ck_log's address (what _rows.RowLog reads)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyType_Slot Log_slots[] = {
    {Py_tp_init, Log_init},
    {Py_tp_new, PyType_GenericNew},
    {Py_tp_dealloc, Log_dealloc},
    {Py_tp_methods, Log_methods},
    {Py_tp_getset, Log_getset},
    {Py_tp_doc, "Log(cells, slots, capacity): the rows of the base steps one steps call takes"},
    {0, NULL},
};

static PyType_Spec Log_spec = {
    "coupler_native._fmu_steps.Log", sizeof(Log), 0, Py_TPFLAGS_DEFAULT, Log_slots,
};

/* --- Members ---------------------------------------------------------------------------- */

typedef struct {
    PyObject_HEAD
    ck_member *member;
    int n, jacobi;
    void *arrays; /* every ck_call and ck_copy, in one allocation */
    double *timing;
    volatile double *watch;
    int *stop;
} Members;

/* Reads a list of (a, b, c[, d]) address tuples into calls (4 items) or copies (3 items). */
static int read_calls(PyObject *list, ck_call *call) {
    Py_ssize_t count = PySequence_Size(list);
    for (Py_ssize_t i = 0; i < count; ++i) {
        PyObject *item = PySequence_GetItem(list, i);
        PyObject *function, *refs, *buffer;
        Py_ssize_t size;
        int ok = item != NULL && PyArg_ParseTuple(item, "OOnO", &function, &refs, &size, &buffer);
        if (ok) {
            call[i].function = address_of(function);
            call[i].refs = address_of(refs);
            call[i].count = (size_t)size;
            call[i].buffer = address_of(buffer);
        }
        Py_XDECREF(item);
        if (!ok || PyErr_Occurred()) return -1;
    }
    return 0;
}

static int read_copies(PyObject *list, ck_copy *copy) {
    Py_ssize_t count = PySequence_Size(list);
    for (Py_ssize_t i = 0; i < count; ++i) {
        PyObject *item = PySequence_GetItem(list, i);
        PyObject *target, *source;
        Py_ssize_t size;
        int ok = item != NULL && PyArg_ParseTuple(item, "OOn", &target, &source, &size);
        if (ok) {
            copy[i].target = address_of(target);
            copy[i].source = address_of(source);
            copy[i].size = (size_t)size;
        }
        Py_XDECREF(item);
        if (!ok || PyErr_Occurred()) return -1;
    }
    return 0;
}

static int Members_init(PyObject *self_, PyObject *args, PyObject *kwargs) {
    Members *self = (Members *)self_;
    PyObject *members, *timing, *watch, *stop;
    int jacobi;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "Members takes no keyword arguments");
        return -1;
    }
    if (self->member != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Members are made already");
        return -1;
    }
    if (!PyArg_ParseTuple(args, "OOOOp", &members, &timing, &watch, &stop, &jacobi)) return -1;
    Py_ssize_t n = PySequence_Size(members);
    if (n < 0) return -1;
    PyObject **parts = calloc((size_t)n * 3 + 1, sizeof(PyObject *)); /* borrowed */
    ck_member *member = calloc((size_t)n + 1, sizeof(ck_member));
    PyObject **items = calloc((size_t)n + 1, sizeof(PyObject *));
    int failed = parts == NULL || member == NULL || items == NULL;
    if (failed) PyErr_NoMemory();
    size_t calls = 0, copies = 0;
    for (Py_ssize_t i = 0; !failed && i < n; ++i) {
        PyObject *instance, *do_step;
        double step;
        int version, slot;
        items[i] = PySequence_GetItem(members, i);
        if (items[i] == NULL ||
            !PyArg_ParseTuple(items[i], "OOdiiOOO", &instance, &do_step, &step, &version, &slot,
                              &parts[3 * i], &parts[3 * i + 1], &parts[3 * i + 2])) {
            failed = 1;
            break;
        }
        member[i].instance = address_of(instance);
        member[i].do_step = address_of(do_step);
        member[i].step = step;
        member[i].version = version;
        member[i].slot = slot;
        member[i].copies = (int)PySequence_Size(parts[3 * i]);
        member[i].sets = (int)PySequence_Size(parts[3 * i + 1]);
        member[i].gets = (int)PySequence_Size(parts[3 * i + 2]);
        if (PyErr_Occurred() || member[i].copies < 0 || member[i].sets < 0 ||
            member[i].gets < 0) {
            failed = 1;
            break;
        }
        copies += (size_t)member[i].copies;
        calls += (size_t)member[i].sets + (size_t)member[i].gets;
    }
    char *arrays = NULL;
    if (!failed) {
        arrays = calloc(calls * sizeof(ck_call) + copies * sizeof(ck_copy) + 1, 1);
        if (arrays == NULL) {
            PyErr_NoMemory();
            failed = 1;
        }
    }
    ck_call *call = (ck_call *)arrays;
    ck_copy *copy = (ck_copy *)(arrays + calls * sizeof(ck_call));
    for (Py_ssize_t i = 0; !failed && i < n; ++i) {
        member[i].copy = copy;
        member[i].set = call;
        member[i].get = call + member[i].sets;
        if (read_copies(parts[3 * i], copy) < 0 || read_calls(parts[3 * i + 1], call) < 0 ||
            read_calls(parts[3 * i + 2], call + member[i].sets) < 0)
            failed = 1;
        copy += member[i].copies;
        call += member[i].sets + member[i].gets;
    }
    if (!failed) {
        self->timing = address_of(timing);
        self->watch = address_of(watch);
        self->stop = address_of(stop);
        failed = PyErr_Occurred() != NULL;
    }
    for (Py_ssize_t i = 0; items != NULL && i < n; ++i) Py_XDECREF(items[i]);
    free(items);
    free(parts);
    if (failed) {
        free(member);
        free(arrays);
        return -1;
    }
    self->member = member;
    self->arrays = arrays;
    self->n = (int)n;
    self->jacobi = jacobi;
    return 0;
}

static int ready_or_raise(Members *self) {
    if (self->member != NULL) return 1;
    PyErr_SetString(PyExc_ValueError, "the members were not made");
    return 0;
}

static PyObject *Members_step(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    Members *self = (Members *)self_;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "step(start, time)");
        return NULL;
    }
    if (!ready_or_raise(self)) return NULL;
    long start = PyLong_AsLong(args[0]);
    double time = PyFloat_AsDouble(args[1]);
    if (PyErr_Occurred()) return NULL;
    int index;
    Py_BEGIN_ALLOW_THREADS
    index = ck_step(self->member, self->n, self->jacobi, (int)start, time, self->timing,
                    self->watch, self->stop);
    Py_END_ALLOW_THREADS
    return PyLong_FromLong(index);
}

static PyObject *Members_steps(PyObject *self_, PyObject *args) {
    Members *self = (Members *)self_;
    double origin, stride, scale, budget;
    long long k0;
    int count;
    PyObject *log;
    if (!ready_or_raise(self)) return NULL;
    if (!PyArg_ParseTuple(args, "dddLidO", &origin, &stride, &scale, &k0, &count, &budget, &log))
        return NULL;
    /* a Log of this module: its type's dealloc is Log_dealloc */
    if (PyType_GetSlot(Py_TYPE(log), Py_tp_dealloc) != (void *)Log_dealloc ||
        ((Log *)log)->log == NULL) {
        PyErr_SetString(PyExc_TypeError, "steps(..., log): a made Log");
        return NULL;
    }
    ck_log *rows = ((Log *)log)->log;
    int index;
    Py_BEGIN_ALLOW_THREADS
    index = ck_steps(self->member, self->n, self->jacobi, origin, stride, scale, k0, count, budget,
                     self->timing, self->watch, self->stop, rows);
    Py_END_ALLOW_THREADS
    return PyLong_FromLong(index);
}

static PyObject *Members_last(PyObject *self_, PyObject *index_) {
    Members *self = (Members *)self_;
    if (!ready_or_raise(self)) return NULL;
    long index = PyLong_AsLong(index_);
    if (index == -1 && PyErr_Occurred()) return NULL;
    if (index < 0 || index >= self->n) {
        PyErr_SetString(PyExc_IndexError, "no such member");
        return NULL;
    }
    return PyFloat_FromDouble(self->member[index].last);
}

static void Members_dealloc(PyObject *self_) {
    Members *self = (Members *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    free(self->member);
    free(self->arrays);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyMethodDef Members_methods[] = {
    {"step", (PyCFunction)(void (*)(void))Members_step, METH_FASTCALL,
     "step(start, time) -> int: the members from `start` stepped at `time` (ck_step): CK_DONE, "
     "or the index of the member that stopped the step (the stop array says why)"},
    {"steps", Members_steps, METH_VARARGS,
     "steps(origin, stride, scale, k0, count, budget, log) -> int: base steps in one call, each "
     "logged (ck_steps)"},
    {"last", Members_last, METH_O,
     "last(index) -> float: the member's last successful time (fmi3DoStep's answer)"},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot Members_slots[] = {
    {Py_tp_init, Members_init},
    {Py_tp_new, PyType_GenericNew},
    {Py_tp_dealloc, Members_dealloc},
    {Py_tp_methods, Members_methods},
    {Py_tp_doc, "Members(members, timing, watch, stop, jacobi): the in-process FMUs of a run, "
                "as the native FMU step steps them (fmu_steps.h)"},
    {0, NULL},
};

static PyType_Spec Members_spec = {
    "coupler_native._fmu_steps.Members", sizeof(Members), 0, Py_TPFLAGS_DEFAULT, Members_slots,
};

/* --- the module ------------------------------------------------------------------------- */

static int exec_module(PyObject *module) {
    PyObject *log = PyType_FromSpec(&Log_spec);
    if (log == NULL) return -1;
    PyObject *members = PyType_FromSpec(&Members_spec);
    if (members == NULL) {
        Py_DECREF(log);
        return -1;
    }
    int result = PyModule_AddObjectRef(module, "Log", log);
    if (result == 0) result = PyModule_AddObjectRef(module, "Members", members);
    Py_DECREF(log);
    Py_DECREF(members);
    if (result < 0) return -1;
    static const struct {
        const char *name;
        int value;
    } constants[] = {
        {"CK_DONE", CK_DONE},
        {"CK_NO_MEMORY", CK_NO_MEMORY},
        {"CK_CLAIMED", CK_CLAIMED},
        {"CK_CALL_SET", CK_CALL_SET},
        {"CK_CALL_STEP", CK_CALL_STEP},
        {"CK_CALL_GET", CK_CALL_GET},
        {"CK_CALL_TERMINATE", CK_CALL_TERMINATE},
    };
    for (size_t i = 0; i < sizeof(constants) / sizeof(constants[0]); ++i)
        if (PyModule_AddIntConstant(module, constants[i].name, constants[i].value) < 0) return -1;
    return 0;
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, exec_module},
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "coupler_native._fmu_steps",
    "the native FMU step (csrc/fmu_steps.c, fmu_steps.h)", 0, NULL, module_slots, NULL, NULL,
    NULL,
};

PyMODINIT_FUNC PyInit__fmu_steps(void) { return PyModuleDef_Init(&module_def); }
