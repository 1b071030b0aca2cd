/* coupler_native._step_streams: the native step channel (step_streams.h, implemented by
 * step_streams.cc) as a CPython extension of the stable ABI (Python 3.11 on).
 *
 * One type, Stream: a remote member's step stream (or step socket), opened by its constructor
 * and driven from the calling thread. Every call into the channel runs without the GIL (the
 * master's watchdog and the event loop's other threads go on while a step is awaited). The
 * pieces a request is sent from are held (their buffers, not copies) until the next send or
 * the stream's end; an answer is a read-only memoryview of the channel's buffer, valid until
 * the next call on the stream.
 *
 *   Stream(target, tls, roots, key, chain, metadata, timeout, max_receive, max_send)
 *   .error -> str              why the stream failed ("" while it is fine)
 *   .send(pieces) -> bool      False: the stream has ended, or the last answer was not taken
 *   .receive(timeout) -> memoryview | None   None: .failure says (CS_FAILED | CS_TIMEOUT, code)
 *   .close(timeout) -> int     answers no request asked for (step_streams.h cs_close)
 */
#define Py_LIMITED_API 0x030B0000
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "step_streams.h"

typedef struct {
    PyObject_HEAD
    cs_stream *stream;
    Py_buffer *held; /* the pieces of the request under way */
    const char **pieces;
    size_t *sizes;
    int count, capacity;
    int result, code; /* the last receive's, when it failed */
} Stream;

static void release_pieces(Stream *self) {
    for (int i = 0; i < self->count; ++i) PyBuffer_Release(&self->held[i]);
    self->count = 0;
}

static int Stream_init(PyObject *self_, PyObject *args, PyObject *kwargs) {
    Stream *self = (Stream *)self_;
    const char *target, *roots, *key, *chain;
    int tls, max_receive, max_send;
    double timeout;
    PyObject *metadata;
    if (kwargs != NULL && PyObject_Length(kwargs) > 0) {
        PyErr_SetString(PyExc_TypeError, "Stream takes no keyword arguments");
        return -1;
    }
    if (self->stream != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Stream is open already");
        return -1;
    }
    if (!PyArg_ParseTuple(args, "ypyyyOdii", &target, &tls, &roots, &key, &chain, &metadata,
                          &timeout, &max_receive, &max_send))
        return -1;
    PyObject *pairs = PySequence_Fast(metadata, "metadata: a sequence of (key, value)");
    if (pairs == NULL) return -1;
    Py_ssize_t count = PySequence_Size(pairs);
    const char **texts = calloc((size_t)(2 * count + 1), sizeof(char *));
    PyObject **encoded = calloc((size_t)(2 * count + 1), sizeof(PyObject *));
    int failed = texts == NULL || encoded == NULL;
    if (failed) PyErr_NoMemory();
    for (Py_ssize_t i = 0; !failed && i < count; ++i) {
        PyObject *pair = PySequence_GetItem(pairs, i);
        for (int j = 0; !failed && j < 2; ++j) {
            PyObject *text = pair == NULL ? NULL : PySequence_GetItem(pair, j);
            encoded[2 * i + j] = text == NULL ? NULL : PyUnicode_AsUTF8String(text);
            Py_XDECREF(text);
            if (encoded[2 * i + j] == NULL) failed = 1;
            else texts[2 * i + j] = PyBytes_AsString(encoded[2 * i + j]);
        }
        Py_XDECREF(pair);
    }
    if (!failed) {
        cs_stream *opened;
        Py_BEGIN_ALLOW_THREADS
        opened = cs_open(target, tls, roots, key, chain, texts, (int)count, timeout, max_receive,
                         max_send);
        Py_END_ALLOW_THREADS
        self->stream = opened;
    }
    for (Py_ssize_t i = 0; encoded != NULL && i < 2 * count; ++i) Py_XDECREF(encoded[i]);
    free(encoded);
    free(texts);
    Py_DECREF(pairs);
    return failed ? -1 : 0;
}

static int open_or_raise(Stream *self) {
    if (self->stream != NULL) return 1;
    PyErr_SetString(PyExc_ValueError, "the stream is closed");
    return 0;
}

static PyObject *Stream_error(PyObject *self_, void *closure) {
    (void)closure;
    Stream *self = (Stream *)self_;
    if (!open_or_raise(self)) return NULL;
    return PyUnicode_DecodeUTF8(cs_error(self->stream), (Py_ssize_t)strlen(cs_error(self->stream)),
                                "replace");
}

static PyObject *Stream_failure(PyObject *self_, void *closure) {
    (void)closure;
    Stream *self = (Stream *)self_;
    return Py_BuildValue("(ii)", self->result, self->code);
}

static PyObject *Stream_send(PyObject *self_, PyObject *pieces) {
    Stream *self = (Stream *)self_;
    if (!open_or_raise(self)) return NULL;
    PyObject *fast = PySequence_Fast(pieces, "pieces: a sequence of bytes-like objects");
    if (fast == NULL) return NULL;
    release_pieces(self);
    Py_ssize_t count = PySequence_Size(fast);
    if (count > self->capacity) {
        int capacity = (int)count;
        Py_buffer *held = realloc(self->held, (size_t)capacity * sizeof(Py_buffer));
        if (held != NULL) self->held = held;
        const char **made = realloc(self->pieces, (size_t)capacity * sizeof(char *));
        if (made != NULL) self->pieces = made;
        size_t *sizes = realloc(self->sizes, (size_t)capacity * sizeof(size_t));
        if (sizes != NULL) self->sizes = sizes;
        if (held == NULL || made == NULL || sizes == NULL) {
            Py_DECREF(fast);
            return PyErr_NoMemory();
        }
        self->capacity = capacity;
    }
    for (Py_ssize_t i = 0; i < count; ++i) {
        PyObject *piece = PySequence_GetItem(fast, i);
        int got = piece == NULL ? -1 : PyObject_GetBuffer(piece, &self->held[i], PyBUF_SIMPLE);
        Py_XDECREF(piece); /* the buffer holds the object */
        if (got < 0) {
            release_pieces(self);
            Py_DECREF(fast);
            return NULL;
        }
        self->count = (int)i + 1;
        self->pieces[i] = self->held[i].buf;
        self->sizes[i] = (size_t)self->held[i].len;
    }
    Py_DECREF(fast);
    int sent;
    Py_BEGIN_ALLOW_THREADS
    sent = cs_send(self->stream, self->pieces, self->sizes, (int)count);
    Py_END_ALLOW_THREADS
    return PyBool_FromLong(sent == CS_OK);
}

static PyObject *Stream_receive(PyObject *self_, PyObject *timeout_) {
    Stream *self = (Stream *)self_;
    if (!open_or_raise(self)) return NULL;
    double timeout = PyFloat_AsDouble(timeout_);
    if (timeout == -1.0 && PyErr_Occurred()) return NULL;
    const char *data = NULL;
    size_t size = 0;
    int code = 0, result;
    Py_BEGIN_ALLOW_THREADS
    result = cs_receive(self->stream, timeout, &data, &size, &code);
    Py_END_ALLOW_THREADS
    if (result == CS_OK) return PyMemoryView_FromMemory((char *)data, (Py_ssize_t)size, PyBUF_READ);
    self->result = result;
    self->code = code;
    Py_RETURN_NONE;
}

static PyObject *Stream_close(PyObject *self_, PyObject *timeout_) {
    Stream *self = (Stream *)self_;
    double timeout = PyFloat_AsDouble(timeout_);
    if (timeout == -1.0 && PyErr_Occurred()) return NULL;
    cs_stream *stream = self->stream;
    self->stream = NULL;
    int unasked = 0;
    if (stream != NULL) {
        Py_BEGIN_ALLOW_THREADS
        unasked = cs_close(stream, timeout);
        Py_END_ALLOW_THREADS
    }
    release_pieces(self); /* after the channel is done with them */
    return PyLong_FromLong(unasked);
}

static void Stream_dealloc(PyObject *self_) {
    Stream *self = (Stream *)self_;
    PyTypeObject *type = Py_TYPE(self_);
    if (self->stream != NULL) {
        cs_stream *stream = self->stream;
        self->stream = NULL;
        Py_BEGIN_ALLOW_THREADS
        cs_close(stream, 0.0);
        Py_END_ALLOW_THREADS
    }
    release_pieces(self);
    free(self->held);
    free(self->pieces);
    free(self->sizes);
    freefunc release = (freefunc)PyType_GetSlot(type, Py_tp_free);
    release(self_);
    Py_DECREF(type);
}

static PyMethodDef Stream_methods[] = {
    {"send", Stream_send, METH_O,
     "send(pieces) -> bool: a serialized DoStepRequest, given as pieces whose concatenation is "
     "the message (held, not copied, until the next send or close), on its way; False when the "
     "stream has ended or the last answer was not received"},
    {"receive", Stream_receive, METH_O,
     "receive(timeout) -> memoryview | None: the answer (valid until the next call on the "
     "stream); None when the stream ended or timed out (failure says which)"},
    {"close", Stream_close, METH_O,
     "close(timeout) -> int: half-close, wait up to timeout for the participant's status, free; "
     "how many answers came that no request asked for"},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef Stream_getset[] = {
    {"error", Stream_error, NULL, "why the stream failed (empty while it is fine)", NULL},
    {"failure", Stream_failure, NULL,
     "(CS_FAILED or CS_TIMEOUT, the gRPC status code) of the last receive that gave None", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PyType_Slot Stream_slots[] = {
    {Py_tp_init, Stream_init},
    {Py_tp_new, PyType_GenericNew},
    {Py_tp_dealloc, Stream_dealloc},
    {Py_tp_methods, Stream_methods},
    {Py_tp_getset, Stream_getset},
    {Py_tp_doc, "Stream(target, tls, roots, key, chain, metadata, timeout, max_receive, max_send):"
                " a remote member's step stream or step socket (step_streams.h)"},
    {0, NULL},
};

static PyType_Spec Stream_spec = {
    "coupler_native._step_streams.Stream", sizeof(Stream), 0, Py_TPFLAGS_DEFAULT, Stream_slots,
};

static int exec_module(PyObject *module) {
    PyObject *type = PyType_FromSpec(&Stream_spec);
    if (type == NULL) return -1;
    int result = PyModule_AddObjectRef(module, "Stream", type);
    Py_DECREF(type);
    if (result < 0 || PyModule_AddIntConstant(module, "CS_OK", CS_OK) < 0 ||
        PyModule_AddIntConstant(module, "CS_FAILED", CS_FAILED) < 0 ||
        PyModule_AddIntConstant(module, "CS_TIMEOUT", CS_TIMEOUT) < 0)
        return -1;
    return 0;
}

static PyModuleDef_Slot module_slots[] = {
    {Py_mod_exec, exec_module},
    {0, NULL},
};

static struct PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT, "coupler_native._step_streams",
    "the native step channel (csrc/step_streams.cc, step_streams.h)", 0, NULL, module_slots,
    NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__step_streams(void) { return PyModuleDef_Init(&module_def); }
