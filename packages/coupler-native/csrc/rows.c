/* The native CSV row: a results.csv line made in one pass over a row, in C; and the row
 * itself read in one pass from the native FMU step's arrays (RowRead, below).
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

#include <stdbool.h>
#include <string.h>

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

static int append_real(Text *t, PyObject *value, Last *last) {
    if (!PyFloat_CheckExact(value)) return append_text_of(t, value, 1);
    double number = PyFloat_AsDouble(value);
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

static int append_integer(Text *t, PyObject *value, Last *last) {
    if (PyLong_CheckExact(value)) {
        int overflow = 0;
        long long number = PyLong_AsLongLongAndOverflow(value, &overflow);
        if (!overflow) {
            if (number == -1 && PyErr_Occurred()) return -1;
            if (last->size && last->last.integer == number)
                return append(t, last->text, last->size);
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
    }
    return append_text_of(t, value, 0);
}

/* A str as a CSV field: quoted, its quotes doubled, when it holds a comma, a quote or a
 * newline (what outputs.csv.csv_field and the csv module write). */
static int append_field(Text *t, PyObject *value) {
    Py_ssize_t size;
    const char *text = PyUnicode_AsUTF8AndSize(value, &size);
    if (text == NULL) return -1;
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

static PyMethodDef RowFormat_methods[] = {
    {"line", (PyCFunction)(void (*)(void))RowFormat_line, METH_FASTCALL,
     "line(time, row) -> str: the CSV line of the picked cells of row, with its newline"},
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

static int add_type(PyObject *module, PyType_Spec *spec, const char *name) {
    PyObject *type = PyType_FromSpec(spec);
    if (type == NULL) return -1;
    int result = PyModule_AddObjectRef(module, name, type);
    Py_DECREF(type);
    return result;
}

static int exec_module(PyObject *module) {
    if (add_type(module, &RowFormat_spec, "RowFormat") < 0) return -1;
    return add_type(module, &RowRead_spec, "RowRead");
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, exec_module},
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "coupler_native._rows",
    "results.csv's rows made, and the native FMU step's rows read, in C (csrc/rows.c)", 0, NULL,
    module_slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__rows(void) { return PyModuleDef_Init(&module_def); }
