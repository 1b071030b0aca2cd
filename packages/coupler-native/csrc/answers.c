/* A step's answer read in C: the outputs of a serialized DoStepResponse (proto/coupler/v1/
 * component.proto) as the dict coupler.wire.Codec.decode makes of them, without building the
 * protobuf message first.
 *
 * coupler_orchestrator.master.native_step_channel makes one AnswerRead per remote participant
 * (`fields`: each output channel -> (its VariableBinding field number, the weight of a value's
 * length in a message's size, whether a Real must be finite), from Codec.answer_fields;
 * `max_bytes`: the size the codec allows its values) and calls `read(data)` with each
 * answer's bytes: (outputs, step_seconds, waited_seconds), the step's cost as the participant
 * reported it (0.0 where the answer does not say).
 *
 * It reads only the plain form every protobuf library writes: the message holds `outputs` and,
 * anywhere among them, at most `step_seconds` and `waited_seconds` (doubles), nothing else (no
 * `terminate`), each binding its `channel` and then one value, each of the field and wire type
 * its channel expects, every string valid UTF-8, every Real finite where it must be, the values
 * within max_bytes. Anything else answers None, and the caller reads the bytes through protobuf
 * and the codec, which read it or say what is wrong with it: the values are the same either way
 * (tests/test_answers.py compares them).
 *
 *   2 real     fixed64 -> float           3 integer  varint -> int (int32, as protobuf cuts it)
 *   4 boolean  varint -> bool (not 0)     5 text     bytes -> str      6 binary  bytes -> bytes
 *
 * A CPython extension of the stable ABI (Python 3.11 on).
 */
#define Py_LIMITED_API 0x030B0000
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <string.h>

#if __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "a Real is read as protobuf writes it: little-endian"
#endif

enum { VARINT = 0, FIXED64 = 1, LEN = 2 };
enum { CHANNEL = 1, REAL = 2, INTEGER = 3, BOOLEAN = 4, TEXT = 5, BINARY = 6 };
enum { OUTPUTS = 1, STEP_SECONDS = 4, WAITED_SECONDS = 5 };

typedef struct {
    PyObject_HEAD
    PyObject *fields; /* dict: channel -> its field number | weight << 8 | finite << 7 */
    Py_ssize_t max_bytes;
} AnswerRead;

/* A varint at *at (before end); false when it is cut short or longer than 10 bytes. */
static int varint(const unsigned char **at, const unsigned char *end, uint64_t *value) {
    uint64_t result = 0;
    for (int shift = 0; shift < 70 && *at < end; shift += 7) {
        unsigned char byte = *(*at)++;
        result |= (uint64_t)(byte & 0x7F) << shift;
        if (byte < 0x80) {
            *value = result;
            return 1;
        }
    }
    return 0;
}

/* A length-delimited field's body at *at: its start and size; false when it does not fit. */
static int body(const unsigned char **at, const unsigned char *end, const unsigned char **start,
                Py_ssize_t *size) {
    uint64_t length;
    if (!varint(at, end, &length) || length > (uint64_t)(end - *at)) return 0;
    *start = *at, *size = (Py_ssize_t)length;
    *at += length;
    return 1;
}

/* Reads one binding into `values`: 1 read, 0 not in the plain form, -1 a Python error. */
static int binding(AnswerRead *self, const unsigned char *at, const unsigned char *end,
                   PyObject *values, Py_ssize_t *size) {
    uint64_t key;
    const unsigned char *text;
    Py_ssize_t length;
    if (!varint(&at, end, &key) || key != (CHANNEL << 3 | LEN) || !body(&at, end, &text, &length))
        return 0;
    PyObject *name = PyUnicode_DecodeUTF8((const char *)text, length, NULL);
    if (name == NULL) {
        PyErr_Clear(); /* not UTF-8: protobuf says so */
        return 0;
    }
    int result = 0;
    PyObject *value = NULL;
    PyObject *field = PyDict_GetItemWithError(self->fields, name); /* borrowed */
    if (field == NULL || !varint(&at, end, &key)) goto done;
    long packed = PyLong_AsLong(field);
    long number = packed & 0x7F, finite = packed >> 7 & 1, weight = packed >> 8;
    if ((long)(key >> 3) != number) goto done;
    switch (number) {
    case REAL: {
        double real;
        if ((key & 7) != FIXED64 || end - at != 8) goto done;
        memcpy(&real, at, 8); /* little-endian, as protobuf writes it (x86_64) */
        if (finite && !isfinite(real)) goto done;
        value = PyFloat_FromDouble(real);
        break;
    }
    case INTEGER:
    case BOOLEAN: {
        uint64_t raw;
        if ((key & 7) != VARINT || !varint(&at, end, &raw) || at != end) goto done;
        value = number == INTEGER ? PyLong_FromLong((int32_t)(uint32_t)raw)
                                  : PyBool_FromLong(raw != 0);
        break;
    }
    case TEXT:
    case BINARY:
        if ((key & 7) != LEN || !body(&at, end, &text, &length) || at != end) goto done;
        if (number == BINARY) {
            value = PyBytes_FromStringAndSize((const char *)text, length);
        } else {
            value = PyUnicode_DecodeUTF8((const char *)text, length, NULL);
            if (value == NULL) {
                PyErr_Clear();
                goto done;
            }
            length = PyUnicode_GetLength(value);
        }
        *size += length * weight;
        break;
    default:
        goto done;
    }
    result = value == NULL || PyDict_SetItem(values, name, value) < 0 ? -1 : 1;
done:
    if (result == 0 && PyErr_Occurred()) result = -1;
    Py_XDECREF(value);
    Py_DECREF(name);
    return result;
}

static PyObject *AnswerRead_read(PyObject *self_, PyObject *data) {
    AnswerRead *self = (AnswerRead *)self_;
    Py_buffer view;
    if (PyObject_GetBuffer(data, &view, PyBUF_SIMPLE) < 0) return NULL;
    const unsigned char *at = view.buf, *end = at + view.len;
    PyObject *values = PyDict_New();
    Py_ssize_t size = 0;
    double cost[2] = {0.0, 0.0}; /* step_seconds, waited_seconds: the last of each counts */
    int read = values != NULL;
    while (read > 0 && at < end) {
        uint64_t key;
        const unsigned char *start;
        Py_ssize_t length;
        if (!varint(&at, end, &key)) {
            read = 0;
        } else if (key == (STEP_SECONDS << 3 | FIXED64) || key == (WAITED_SECONDS << 3 | FIXED64)) {
            if (end - at < 8) {
                read = 0;
            } else {
                memcpy(&cost[(key >> 3) - STEP_SECONDS], at, 8); /* little-endian, as written */
                at += 8;
            }
        } else if (key != (OUTPUTS << 3 | LEN) || !body(&at, end, &start, &length)) {
            read = 0;
        } else {
            read = binding(self, start, start + length, values, &size);
        }
    }
    PyBuffer_Release(&view);
    if (read < 0) {
        Py_XDECREF(values);
        return NULL;
    }
    if (read == 0 || size > self->max_bytes) {
        Py_DECREF(values);
        Py_RETURN_NONE;
    }
    return Py_BuildValue("(Ndd)", values, cost[0], cost[1]); /* takes `values` */
}

static void AnswerRead_dealloc(PyObject *self_) {
    AnswerRead *self = (AnswerRead *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    Py_XDECREF(self->fields);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyObject *AnswerRead_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    PyObject *fields;
    Py_ssize_t max_bytes;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "AnswerRead takes no keyword arguments");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "O!n", &PyDict_Type, &fields, &max_bytes)) return NULL;
    allocfunc alloc = (allocfunc)PyType_GetSlot(type, Py_tp_alloc);
    AnswerRead *self = (AnswerRead *)alloc(type, 0);
    if (self == NULL) return NULL;
    self->max_bytes = max_bytes;
    self->fields = PyDict_New();
    if (self->fields == NULL) {
        Py_DECREF(self);
        return NULL;
    }
    PyObject *name, *field;
    Py_ssize_t position = 0;
    while (PyDict_Next(fields, &position, &name, &field)) {
        long number, weight;
        int finite;
        if (!PyArg_ParseTuple(field, "llp", &number, &weight, &finite)) {
            Py_DECREF(self);
            return NULL;
        }
        if (number < REAL || number > BINARY || weight < 0 || weight > 255) {
            PyErr_SetString(PyExc_ValueError, "a field number from 2 to 6, a weight to 255");
            Py_DECREF(self);
            return NULL;
        }
        PyObject *packed = PyLong_FromLong(number | (long)finite << 7 | weight << 8);
        int result = packed == NULL ? -1 : PyDict_SetItem(self->fields, name, packed);
        Py_XDECREF(packed);
        if (result < 0) {
            Py_DECREF(self);
            return NULL;
        }
    }
    return (PyObject *)self;
}

static PyMethodDef AnswerRead_methods[] = {
    {"read", AnswerRead_read, METH_O,
     "read(data) -> (outputs, step_seconds, waited_seconds) | None: a serialized DoStepResponse "
     "in its plain form (its outputs as a dict, the step's cost as reported, 0.0 where not), "
     "else None"},
    {NULL, NULL, 0, NULL},
};

static PyType_Slot AnswerRead_slots[] = {
    {Py_tp_new, AnswerRead_new},
    {Py_tp_dealloc, AnswerRead_dealloc},
    {Py_tp_methods, AnswerRead_methods},
    {Py_tp_doc, "AnswerRead(fields, max_bytes): a participant's step answers read in C"},
    {0, NULL},
};

static PyType_Spec AnswerRead_spec = {
    "coupler_native._answers.AnswerRead", sizeof(AnswerRead), 0, Py_TPFLAGS_DEFAULT,
    AnswerRead_slots,
};

static int exec_module(PyObject *module) {
    PyObject *type = PyType_FromSpec(&AnswerRead_spec);
    if (type == NULL) return -1;
    int result = PyModule_AddObjectRef(module, "AnswerRead", type);
    Py_DECREF(type);
    return result;
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, exec_module},
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "coupler_native._answers",
    "a step's answer read in C (csrc/answers.c)", 0, NULL, module_slots, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__answers(void) { return PyModuleDef_Init(&module_def); }
