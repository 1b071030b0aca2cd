/* The native CSV row: a results.csv line made in one pass over a row, in C; and the row
 * itself read in one pass from the native FMU step's arrays (RowRead, below). Where the native
 * FMU step took several base steps in one call, their rows are read from its row log (RowLog,
 * fmu_steps.h's ck_log) and their lines made from it in one call (RowFormat.lines: the cells
 * line() makes of the Values RowLog reads). log_buckets counts step latencies into the
 * histogram of coupler_orchestrator.outputs.latency.
 *
 * coupler_orchestrator.outputs.csv makes one RowFormat per run (the picked columns' indices in
 * a row, a kind per column and, for the columns C does not format, a Python formatter) and
 * calls its `line(time, row)` for every recorded row. The cells are exactly the ones Python's
 * formatters make (tests/test_csv_rows.py compares them):
 *
 *   'r' Real         repr: a float through PyOS_double_to_string(x, 'r', 0, Py_DTSF_ADD_DOT_0),
 *                    what float.__repr__ calls (the shortest text that reads back to the same
 *                    double); any other object through its repr
 *   'i' Integer, Enumeration, UInt64
 *                    str: an int in a long long by snprintf, any other object through str
 *   'b' Boolean      "1" or "0" by the value's truth
 *   's' String       a str as it is, quoted as the csv module quotes a field (when it holds a
 *                    comma, a quote or a newline); any other object through the formatter
 *   'o' other        the column's Python formatter (binary values, frames), whose str is
 *                    written as it is
 *
 * A Real or Integer cell whose value is the one of the row before (the same bits) reuses its
 * text: constant outputs cost a comparison. The time (the first cell) is a Real. A CPython
 * extension of the stable ABI (Python 3.11 on).
 */
#define Py_LIMITED_API 0x030B0000
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <string.h>

#include "fmu_steps.h"

/* A cell's last number and its text. */
typedef struct {
    union {
        double real;
        long long integer;
    } last;
    int size; /* of text; 0: nothing yet */
    char text[40];
} Last;

typedef struct {
    PyObject_HEAD
    Py_ssize_t count;
    Py_ssize_t *index;    /* each cell's index in a row */
    char *kind;           /* each cell's kind */
    Last *last;           /* each cell's last number, for kinds 'r' and 'i' */
    PyObject *formatters; /* a tuple: each cell's formatter, None for kinds 'r', 'i', 'b' */
} RowFormat;

/* A growing text; `stack` first, the heap once it is full. */
typedef struct {
    char *text;
    Py_ssize_t size, capacity;
    char stack[2048];
} Text;

static int reserve(Text *t, Py_ssize_t more) {
    if (t->size + more <= t->capacity) return 0;
    Py_ssize_t capacity = t->capacity;
    while (capacity < t->size + more) capacity *= 2;
    char *grown;
    if (t->text == t->stack) {
        grown = PyMem_Malloc((size_t)capacity);
        if (grown != NULL) memcpy(grown, t->text, (size_t)t->size);
    } else {
        grown = PyMem_Realloc(t->text, (size_t)capacity);
    }
    if (grown == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    t->text = grown, t->capacity = capacity;
    return 0;
}

static int append(Text *t, const char *text, Py_ssize_t size) {
    if (reserve(t, size + 1) < 0) return -1;
    memcpy(t->text + t->size, text, (size_t)size);
    t->size += size;
    return 0;
}

/* The str of an object (repr with `repr`), appended. */
static int append_text_of(Text *t, PyObject *value, int repr) {
    PyObject *text = repr ? PyObject_Repr(value) : PyObject_Str(value);
    if (text == NULL) return -1;
    Py_ssize_t size;
    const char *utf8 = PyUnicode_AsUTF8AndSize(text, &size);
    int result = utf8 == NULL ? -1 : append(t, utf8, size);
    Py_DECREF(text);
    return result;
}

/* A double's repr (the text float.__repr__ makes), appended. */
static int append_double(Text *t, double number, Last *last) {
    if (last != NULL && last->size && memcmp(&last->last.real, &number, sizeof number) == 0)
        return append(t, last->text, last->size);
    char *text = PyOS_double_to_string(number, 'r', 0, Py_DTSF_ADD_DOT_0, NULL);
    if (text == NULL) return -1;
    Py_ssize_t size = (Py_ssize_t)strlen(text);
    int result = append(t, text, size);
    if (last != NULL && size < (Py_ssize_t)sizeof last->text) {
        memcpy(last->text, text, (size_t)size);
        last->last.real = number, last->size = (int)size;
    }
    PyMem_Free(text);
    return result;
}

static int append_real(Text *t, PyObject *value, Last *last) {
    if (!PyFloat_CheckExact(value)) return append_text_of(t, value, 1);
    return append_double(t, PyFloat_AsDouble(value), last);
}

/* A long long's digits (str of the int), appended. */
static int append_long(Text *t, long long number, Last *last) {
    if (last->size && last->last.integer == number) return append(t, last->text, last->size);
    /* the digits from the right, then the sign */
    char digits[24];
    char *at = digits + sizeof digits;
    unsigned long long rest =
        number < 0 ? 0ULL - (unsigned long long)number : (unsigned long long)number;
    do {
        *--at = (char)('0' + rest % 10);
        rest /= 10;
    } while (rest);
    if (number < 0) *--at = '-';
    last->size = (int)(digits + sizeof digits - at);
    memcpy(last->text, at, (size_t)last->size);
    last->last.integer = number;
    return append(t, at, last->size);
}

static int append_integer(Text *t, PyObject *value, Last *last) {
    if (PyLong_CheckExact(value)) {
        int overflow = 0;
        long long number = PyLong_AsLongLongAndOverflow(value, &overflow);
        if (!overflow) {
            if (number == -1 && PyErr_Occurred()) return -1;
            return append_long(t, number, last);
        }
    }
    return append_text_of(t, value, 0);
}

/* UTF-8 text as a CSV field: quoted, its quotes doubled, when it holds a comma, a quote or a
 * newline (what outputs.csv.csv_field and the csv module write). */
static int append_field_text(Text *t, const char *text, Py_ssize_t size) {
    Py_ssize_t quotes = 0;
    bool plain = true;
    for (Py_ssize_t i = 0; i < size; i++) {
        char c = text[i];
        if (c == '"') quotes++;
        if (c == ',' || c == '"' || c == '\n') plain = false;
    }
    if (plain) return append(t, text, size);
    if (reserve(t, size + quotes + 3) < 0) return -1;
    t->text[t->size++] = '"';
    for (Py_ssize_t i = 0; i < size; i++) {
        if (text[i] == '"') t->text[t->size++] = '"';
        t->text[t->size++] = text[i];
    }
    t->text[t->size++] = '"';
    return 0;
}

/* A str as a CSV field. */
static int append_field(Text *t, PyObject *value) {
    Py_ssize_t size;
    const char *text = PyUnicode_AsUTF8AndSize(value, &size);
    if (text == NULL) return -1;
    return append_field_text(t, text, size);
}

/* The text the cell's Python formatter makes of it, appended. */
static int append_formatted(Text *t, PyObject *value, PyObject *formatter) {
    PyObject *text = PyObject_CallFunctionObjArgs(formatter, value, NULL);
    if (text == NULL) return -1;
    int result = -1;
    if (!PyUnicode_Check(text)) {
        PyErr_SetString(PyExc_TypeError, "a cell's formatter returned something not a str");
    } else {
        Py_ssize_t size;
        const char *utf8 = PyUnicode_AsUTF8AndSize(text, &size);
        if (utf8 != NULL) result = append(t, utf8, size);
    }
    Py_DECREF(text);
    return result;
}

static int append_cell(Text *t, char kind, PyObject *value, PyObject *formatter, Last *last) {
    switch (kind) {
    case 'r':
        return append_real(t, value, last);
    case 'i':
        return append_integer(t, value, last);
    case 'b': {
        int truth = PyObject_IsTrue(value);
        return truth < 0 ? -1 : append(t, truth ? "1" : "0", 1);
    }
    case 's':
        if (PyUnicode_CheckExact(value)) return append_field(t, value);
        return append_formatted(t, value, formatter);
    default:
        return append_formatted(t, value, formatter);
    }
}

/* row[index]: a new reference (lists and tuples without PySequence's detour). */
static PyObject *item(PyObject *row, Py_ssize_t index) {
    PyObject *found;
    if (PyList_CheckExact(row))
        found = PyList_GetItem(row, index);
    else if (PyTuple_CheckExact(row))
        found = PyTuple_GetItem(row, index);
    else
        return PySequence_GetItem(row, index);
    Py_XINCREF(found);
    return found;
}

static PyObject *RowFormat_line(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    RowFormat *self = (RowFormat *)self_;
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "line(time, row) takes two arguments");
        return NULL;
    }
    Text t;
    t.text = t.stack, t.size = 0, t.capacity = sizeof t.stack;
    PyObject *line = NULL;
    if (append_real(&t, args[0], NULL) < 0) goto done;
    for (Py_ssize_t i = 0; i < self->count; i++) {
        PyObject *value = item(args[1], self->index[i]);
        if (value == NULL) goto done;
        int result = append(&t, ",", 1);
        if (result == 0)
            result = append_cell(&t, self->kind[i], value, PyTuple_GetItem(self->formatters, i),
                                 &self->last[i]);
        Py_DECREF(value);
        if (result < 0) goto done;
    }
    if (append(&t, "\n", 1) < 0) goto done;
    line = PyUnicode_FromStringAndSize(t.text, t.size);
done:
    if (t.text != t.stack) PyMem_Free(t.text);
    return line;
}

static void RowFormat_dealloc(PyObject *self_) {
    RowFormat *self = (RowFormat *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    PyMem_Free(self->index);
    PyMem_Free(self->kind);
    PyMem_Free(self->last);
    Py_XDECREF(self->formatters);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

/* RowFormat(indices, kinds, formatters): sequences of one entry per cell after the time. */
static PyObject *RowFormat_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    PyObject *indices, *kinds, *formatters;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "RowFormat takes no keyword arguments");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OUO!", &indices, &kinds, &PyTuple_Type, &formatters))
        return NULL;
    Py_ssize_t count = PyObject_Length(indices);
    if (count < 0) return NULL;
    Py_ssize_t size;
    const char *kind = PyUnicode_AsUTF8AndSize(kinds, &size);
    if (kind == NULL) return NULL;
    if (size != count || PyTuple_Size(formatters) != count) {
        PyErr_SetString(PyExc_ValueError, "one index, kind and formatter per cell");
        return NULL;
    }
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    RowFormat *self = (RowFormat *)alloc(type, 0);
    if (self == NULL) return NULL;
    self->count = count;
    self->index = PyMem_Malloc(sizeof(Py_ssize_t) * (size_t)(count ? count : 1));
    self->kind = PyMem_Malloc((size_t)(count ? count : 1));
    self->last = PyMem_Calloc((size_t)(count ? count : 1), sizeof(Last));
    Py_INCREF(formatters);
    self->formatters = formatters;
    if (self->index == NULL || self->kind == NULL || self->last == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    memcpy(self->kind, kind, (size_t)count);
    for (Py_ssize_t i = 0; i < count; i++) {
        if (strchr("rib", kind[i]) == NULL &&
            !PyCallable_Check(PyTuple_GetItem(formatters, i))) {
            PyErr_SetString(PyExc_TypeError, "a cell of kind 's' or 'o' needs a formatter");
            Py_DECREF(self);
            return NULL;
        }
        PyObject *number = PySequence_GetItem(indices, i);
        if (number == NULL) {
            Py_DECREF(self);
            return NULL;
        }
        self->index[i] = PyLong_AsSsize_t(number);
        Py_DECREF(number);
        if (self->index[i] == -1 && PyErr_Occurred()) {
            Py_DECREF(self);
            return NULL;
        }
    }
    return (PyObject *)self;
}

static PyObject *RowFormat_lines(PyObject *self_, PyObject *const *args, Py_ssize_t nargs);

static PyMethodDef RowFormat_methods[] = {
    {"line", (PyCFunction)(void (*)(void))RowFormat_line, METH_FASTCALL,
     "line(time, row) -> str: the CSV line of the picked cells of row, with its newline"},
    {"lines", (PyCFunction)(void (*)(void))RowFormat_lines, METH_FASTCALL,
     "lines(log, first, every) -> str | None: the lines of the log's rows first, first + every, "
     "...; None when a cell's kind cannot be made from its column's C type"},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot RowFormat_slots[] = {
    {Py_tp_new, RowFormat_new},
    {Py_tp_dealloc, RowFormat_dealloc},
    {Py_tp_methods, RowFormat_methods},
    {Py_tp_doc, "RowFormat(indices, kinds, formatters): results.csv lines of a run's rows"},
    {0, NULL},
};

static PyType_Spec RowFormat_spec = {
    "coupler_native._rows.RowFormat", sizeof(RowFormat), 0, Py_TPFLAGS_DEFAULT, RowFormat_slots,
};

/* --- RowRead: a row of Values from the native FMU step's output arrays ------------------- */

/* RowRead(addresses, codes): per column, the address of its output's slot in the native FMU
 * step's arrays (coupler_orchestrator.master.native_fmu_step) and its C type:
 *   'd' double -> float          'i' int (32 bits) -> int      'q' int64 -> int
 *   'b' int (32 bits) -> bool    '?' bool -> bool
 *   's' char * -> str (UTF-8, errors replaced; NULL or "" -> "")
 * `row()` makes the list the arrays' slices, converted and picked in column order, made in
 * Python. The arrays belong to whoever made it (the kernel), which keeps them alive. */
typedef struct {
    PyObject_HEAD
    Py_ssize_t count;
    const void **address;
    char *code;
} RowRead;

static PyObject *value_at(char code, const void *at) {
    switch (code) {
    case 'd':
        return PyFloat_FromDouble(*(const double *)at);
    case 'i':
        return PyLong_FromLong(*(const int *)at);
    case 'q':
        return PyLong_FromLongLong(*(const long long *)at);
    case 'b':
        return PyBool_FromLong(*(const int *)at != 0);
    case '?':
        return PyBool_FromLong(*(const bool *)at);
    default: {
        const char *text = *(const char *const *)at;
        if (text == NULL || text[0] == '\0') return PyUnicode_FromStringAndSize("", 0);
        return PyUnicode_DecodeUTF8(text, (Py_ssize_t)strlen(text), "replace");
    }
    }
}

static PyObject *RowRead_row(PyObject *self_, PyObject *unused) {
    (void)unused;
    RowRead *self = (RowRead *)self_;
    PyObject *row = PyList_New(self->count);
    if (row == NULL) return NULL;
    for (Py_ssize_t i = 0; i < self->count; i++) {
        PyObject *value = value_at(self->code[i], self->address[i]);
        if (value == NULL || PyList_SetItem(row, i, value) < 0) {
            Py_DECREF(row);
            return NULL;
        }
    }
    return row;
}

static void RowRead_dealloc(PyObject *self_) {
    RowRead *self = (RowRead *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    PyMem_Free(self->address);
    PyMem_Free(self->code);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyObject *RowRead_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    PyObject *addresses, *codes;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "RowRead takes no keyword arguments");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OU", &addresses, &codes)) return NULL;
    Py_ssize_t count = PyObject_Length(addresses);
    if (count < 0) return NULL;
    Py_ssize_t size;
    const char *code = PyUnicode_AsUTF8AndSize(codes, &size);
    if (code == NULL) return NULL;
    if (size != count) {
        PyErr_SetString(PyExc_ValueError, "one address and one code per column");
        return NULL;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        if (strchr("diqb?s", code[i]) == NULL || code[i] == '\0') {
            PyErr_Format(PyExc_ValueError, "no C type %c", code[i]);
            return NULL;
        }
    }
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    RowRead *self = (RowRead *)alloc(type, 0);
    if (self == NULL) return NULL;
    self->count = count;
    self->address = PyMem_Malloc(sizeof(void *) * (size_t)(count ? count : 1));
    self->code = PyMem_Malloc((size_t)(count ? count : 1));
    if (self->address == NULL || self->code == NULL) {
        Py_DECREF(self);
        return PyErr_NoMemory();
    }
    memcpy(self->code, code, (size_t)count);
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *number = PySequence_GetItem(addresses, i);
        if (number == NULL) {
            Py_DECREF(self);
            return NULL;
        }
        self->address[i] = PyLong_AsVoidPtr(number);
        Py_DECREF(number);
        if (PyErr_Occurred()) {
            Py_DECREF(self);
            return NULL;
        }
    }
    return (PyObject *)self;
}

static PyMethodDef RowRead_methods[] = {
    {"row", RowRead_row, METH_NOARGS, "row() -> list: the columns' values as they are now"},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot RowRead_slots[] = {
    {Py_tp_new, RowRead_new},
    {Py_tp_dealloc, RowRead_dealloc},
    {Py_tp_methods, RowRead_methods},
    {Py_tp_doc, "RowRead(addresses, codes): rows of Values from the native FMU step's arrays"},
    {0, NULL},
};

static PyType_Spec RowRead_spec = {
    "coupler_native._rows.RowRead", sizeof(RowRead), 0, Py_TPFLAGS_DEFAULT, RowRead_slots,
};

/* --- RowLog: the rows of several base steps, logged by the native FMU step ---------------- */

/* RowLog(address, owner): the ck_log at `address` (fmu_steps.h: ck_steps fills it), read while
 * `owner` (the cffi object that frees it) is kept alive. Its rows are the Values RowRead would
 * have read after each of the steps; `lines` of a RowFormat makes results.csv's lines from it. */
typedef struct {
    PyObject_HEAD
    const ck_log *log;
    PyObject *owner;
} RowLog;

static PyObject *RowLog_type; /* set when the module is executed */

/* A logged string's Value: what value_at makes of the char * it was copied from. */
static PyObject *logged_text(const ck_log *log, long long at) {
    const char *text = at < 0 ? NULL : log->text + at;
    if (text == NULL || text[0] == '\0') return PyUnicode_FromStringAndSize("", 0);
    return PyUnicode_DecodeUTF8(text, (Py_ssize_t)strlen(text), "replace");
}

static PyObject *logged_value(const ck_log *log, char code, const ck_value *value) {
    switch (code) {
    case 'd':
        return PyFloat_FromDouble(value->real);
    case 'i':
    case 'q':
        return PyLong_FromLongLong(value->integer);
    case 'b':
    case '?':
        return PyBool_FromLong(value->integer != 0);
    default:
        return logged_text(log, value->integer);
    }
}

/* A list of `count` floats, values[0], values[stride], ... */
static PyObject *floats(const double *values, Py_ssize_t count, Py_ssize_t stride) {
    PyObject *list = PyList_New(count);
    if (list == NULL) return NULL;
    for (Py_ssize_t j = 0; j < count; j++) {
        PyObject *number = PyFloat_FromDouble(values[j * stride]);
        if (number == NULL || PyList_SetItem(list, j, number) < 0) {
            Py_DECREF(list);
            return NULL;
        }
    }
    return list;
}

/* The index argument of a method, checked against `count`. */
static int index_of(PyObject *const *args, Py_ssize_t nargs, Py_ssize_t count, Py_ssize_t *j) {
    if (nargs != 1) {
        PyErr_SetString(PyExc_TypeError, "takes one index");
        return -1;
    }
    *j = PyLong_AsSsize_t(args[0]);
    if (*j == -1 && PyErr_Occurred()) return -1;
    if (*j < 0) *j += count;
    if (*j < 0 || *j >= count) {
        PyErr_SetString(PyExc_IndexError, "no such row or member in the log");
        return -1;
    }
    return 0;
}

static PyObject *RowLog_times(PyObject *self_, PyObject *unused) {
    (void)unused;
    const ck_log *log = ((RowLog *)self_)->log;
    return floats(log->time, log->count, 1);
}

static PyObject *RowLog_row(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    const ck_log *log = ((RowLog *)self_)->log;
    Py_ssize_t j;
    if (index_of(args, nargs, log->count, &j) < 0) return NULL;
    const ck_value *values = log->value + j * log->cells;
    PyObject *row = PyList_New(log->cells);
    if (row == NULL) return NULL;
    for (Py_ssize_t c = 0; c < log->cells; c++) {
        PyObject *value = logged_value(log, log->cell[c].code, &values[c]);
        if (value == NULL || PyList_SetItem(row, c, value) < 0) {
            Py_DECREF(row);
            return NULL;
        }
    }
    return row;
}

static PyObject *RowLog_seconds(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    const ck_log *log = ((RowLog *)self_)->log;
    Py_ssize_t j;
    if (index_of(args, nargs, log->count, &j) < 0) return NULL;
    return floats(log->timing + j * log->slots, log->slots, 1);
}

static PyObject *RowLog_samples(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    const ck_log *log = ((RowLog *)self_)->log;
    Py_ssize_t slot;
    if (index_of(args, nargs, log->slots, &slot) < 0) return NULL;
    return floats(log->timing + slot, log->count, log->slots);
}

static Py_ssize_t RowLog_length(PyObject *self_) { return ((RowLog *)self_)->log->count; }

static void RowLog_dealloc(PyObject *self_) {
    RowLog *self = (RowLog *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    Py_XDECREF(self->owner);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyObject *RowLog_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    PyObject *address, *owner;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "RowLog takes no keyword arguments");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OO", &address, &owner)) return NULL;
    const ck_log *log = PyLong_AsVoidPtr(address);
    if (log == NULL) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "RowLog of a NULL log");
        return NULL;
    }
    for (int c = 0; c < log->cells; c++) {
        if (strchr("diqb?s", log->cell[c].code) == NULL || log->cell[c].code == '\0') {
            PyErr_Format(PyExc_ValueError, "no C type %c", log->cell[c].code);
            return NULL;
        }
    }
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    RowLog *self = (RowLog *)alloc(type, 0);
    if (self == NULL) return NULL;
    self->log = log;
    Py_INCREF(owner);
    self->owner = owner;
    return (PyObject *)self;
}

static PyMethodDef RowLog_methods[] = {
    {"times", RowLog_times, METH_NOARGS, "times() -> list: each logged row's time"},
    {"row", (PyCFunction)(void (*)(void))RowLog_row, METH_FASTCALL,
     "row(j) -> list: the values of row j, as RowRead read them then"},
    {"seconds", (PyCFunction)(void (*)(void))RowLog_seconds, METH_FASTCALL,
     "seconds(j) -> list: each member's wall time of step j [s]"},
    {"samples", (PyCFunction)(void (*)(void))RowLog_samples, METH_FASTCALL,
     "samples(member) -> list: the member's wall time of each logged step [s]"},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot RowLog_slots[] = {
    {Py_tp_new, RowLog_new},
    {Py_tp_dealloc, RowLog_dealloc},
    {Py_tp_methods, RowLog_methods},
    {Py_sq_length, RowLog_length},
    {Py_tp_doc, "RowLog(address, owner): the rows of the native FMU step's ck_log"},
    {0, NULL},
};

static PyType_Spec RowLog_spec = {
    "coupler_native._rows.RowLog", sizeof(RowLog), 0, Py_TPFLAGS_DEFAULT, RowLog_slots,
};

/* Whether a cell of `kind` is made from a logged value of C type `code` (as line() makes it
 * of the Value RowRead reads from that type). */
static bool makes(char kind, char code) {
    switch (kind) {
    case 'r':
        return code == 'd';
    case 'i':
        return code == 'i' || code == 'q';
    case 'b':
        return code == 'b' || code == '?';
    case 's':
        return code == 's';
    default:
        return false;
    }
}

/* A logged string's cell: the text itself when it is ASCII (what decoding it gives), else
 * through the str RowRead would have made of it. */
static int append_logged_text(Text *t, const ck_log *log, long long at) {
    const char *text = at < 0 ? "" : log->text + at;
    Py_ssize_t size = (Py_ssize_t)strlen(text);
    for (Py_ssize_t i = 0; i < size; i++) {
        if ((unsigned char)text[i] >= 0x80) {
            PyObject *value = logged_text(log, at);
            if (value == NULL) return -1;
            int result = append_field(t, value);
            Py_DECREF(value);
            return result;
        }
    }
    return append_field_text(t, text, size);
}

static PyObject *RowFormat_lines(PyObject *self_, PyObject *const *args, Py_ssize_t nargs) {
    RowFormat *self = (RowFormat *)self_;
    if (nargs != 3 || !PyObject_TypeCheck(args[0], (PyTypeObject *)RowLog_type)) {
        PyErr_SetString(PyExc_TypeError, "lines(log, first, every) takes a RowLog and two ints");
        return NULL;
    }
    const ck_log *log = ((RowLog *)args[0])->log;
    Py_ssize_t first = PyLong_AsSsize_t(args[1]), every = PyLong_AsSsize_t(args[2]);
    if (PyErr_Occurred()) return NULL;
    if (first < 0 || every < 1) {
        PyErr_SetString(PyExc_ValueError, "lines: first >= 0 and every >= 1");
        return NULL;
    }
    for (Py_ssize_t i = 0; i < self->count; i++) {
        if (self->index[i] < 0 || self->index[i] >= log->cells) {
            PyErr_SetString(PyExc_IndexError, "a cell's index is not a column of the log");
            return NULL;
        }
        if (!makes(self->kind[i], log->cell[self->index[i]].code)) Py_RETURN_NONE;
    }
    Text t;
    t.text = t.stack, t.size = 0, t.capacity = sizeof t.stack;
    PyObject *lines = NULL;
    for (Py_ssize_t j = first; j < log->count; j += every) {
        const ck_value *values = log->value + j * log->cells;
        if (append_double(&t, log->time[j], NULL) < 0) goto done;
        for (Py_ssize_t i = 0; i < self->count; i++) {
            const ck_value *value = &values[self->index[i]];
            int result = append(&t, ",", 1);
            if (result < 0) goto done;
            switch (self->kind[i]) {
            case 'r':
                result = append_double(&t, value->real, &self->last[i]);
                break;
            case 'i':
                result = append_long(&t, value->integer, &self->last[i]);
                break;
            case 'b':
                result = append(&t, value->integer ? "1" : "0", 1);
                break;
            default:
                result = append_logged_text(&t, log, value->integer);
            }
            if (result < 0) goto done;
        }
        if (append(&t, "\n", 1) < 0) goto done;
    }
    lines = PyUnicode_FromStringAndSize(t.text, t.size);
done:
    if (t.text != t.stack) PyMem_Free(t.text);
    return lines;
}

/* --- log_buckets: step latencies counted into a histogram -------------------------------- */

/* log_buckets(samples, floor, per_bucket, base) -> (total, maximum, {bucket: count}): what
 * outputs.latency.LatencyStats counts of a batch of samples, each sample's bucket
 * int((log(s) - floor) * per_bucket) if s > base else 0 (the same libm log Python's math.log
 * calls), the total summed in order. */
static PyObject *log_buckets(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    (void)module;
    if (nargs != 4 || !PyList_CheckExact(args[0])) {
        PyErr_SetString(PyExc_TypeError, "log_buckets(samples: list, floor, per_bucket, base)");
        return NULL;
    }
    double floor = PyFloat_AsDouble(args[1]), per_bucket = PyFloat_AsDouble(args[2]),
           base = PyFloat_AsDouble(args[3]);
    if (PyErr_Occurred()) return NULL;
    PyObject *samples = args[0];
    Py_ssize_t count = PyList_Size(samples);
    if (count == 0) {
        PyErr_SetString(PyExc_ValueError, "log_buckets of no samples");
        return NULL;
    }
    PyObject *counts = PyDict_New();
    if (counts == NULL) return NULL;
    double total = 0.0, maximum = 0.0;
    long long bucket = -1, run = 0; /* the bucket of the samples before, and how many */
    for (Py_ssize_t j = 0; j <= count; j++) {
        long long here = -1;
        if (j < count) {
            double s = PyFloat_AsDouble(PyList_GetItem(samples, j));
            if (s == -1.0 && PyErr_Occurred()) goto failed;
            if (!isfinite(s)) {
                PyErr_SetString(PyExc_ValueError, "log_buckets: a sample is not finite");
                goto failed;
            }
            total += s;
            if (j == 0 || s > maximum) maximum = s;
            here = s > base ? (long long)((log(s) - floor) * per_bucket) : 0;
            if (here == bucket) {
                run++;
                continue;
            }
        }
        if (run) { /* the samples of one bucket before this one, counted */
            PyObject *key = PyLong_FromLongLong(bucket);
            if (key == NULL) goto failed;
            PyObject *had = PyDict_GetItemWithError(counts, key);
            long long before = had == NULL ? 0 : PyLong_AsLongLong(had);
            PyObject *now = PyErr_Occurred() ? NULL : PyLong_FromLongLong(before + run);
            int result = now == NULL ? -1 : PyDict_SetItem(counts, key, now);
            Py_DECREF(key);
            Py_XDECREF(now);
            if (result < 0) goto failed;
        }
        bucket = here, run = 1;
    }
    return Py_BuildValue("ddN", total, maximum, counts);
failed:
    Py_DECREF(counts);
    return NULL;
}

static PyMethodDef module_methods[] = {
    {"log_buckets", (PyCFunction)(void (*)(void))log_buckets, METH_FASTCALL,
     "log_buckets(samples, floor, per_bucket, base) -> (total, maximum, {bucket: count})"},
    {NULL, NULL, 0, NULL},
};

static int add_type(PyObject *module, PyType_Spec *spec, const char *name) {
    PyObject *type = PyType_FromSpec(spec);
    if (type == NULL) return -1;
    int result = PyModule_AddObjectRef(module, name, type);
    Py_DECREF(type);
    return result;
}

static int exec_module(PyObject *module) {
    if (add_type(module, &RowFormat_spec, "RowFormat") < 0) return -1;
    if (add_type(module, &RowRead_spec, "RowRead") < 0) return -1;
    if (add_type(module, &RowLog_spec, "RowLog") < 0) return -1;
    RowLog_type = PyObject_GetAttrString(module, "RowLog"); /* held for the process's life */
    return RowLog_type == NULL ? -1 : 0;
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, exec_module},
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "coupler_native._rows",
    "results.csv's rows made, and the native FMU step's rows read, in C (csrc/rows.c)", 0,
    module_methods, module_slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__rows(void) { return PyModuleDef_Init(&module_def); }
