/* The native step channel's interface (step_streams.cc implements it; step_streams_module.c,
 * its Python face, calls it; no preprocessor lines here: the includer brings <stddef.h>).
 *
 * A remote member's StepStream, driven from the calling thread. A step is split in two, so
 * that the requests of every member are on the wire before any answer is awaited: cs_send()
 * writes a request and asks for the answer; cs_receive() waits for it (or for the stream's
 * end, or for the step's deadline, which cancels the stream). Every call returns at once or by
 * its deadline; none of them throws.
 *
 * The same interface drives a participant's step socket (docs/protocol.md "Step socket"): the
 * target `steps:/abs/path` opens a plain unix socket to it instead of a StepStream (`tls` and
 * `metadata` are not used: no token travels there), on which a request is a frame (a uint32
 * little-endian payload length, a uint8 kind 0, the serialized DoStepRequest) written with one
 * sendmsg from the caller's pieces, and an answer one read back into a buffer the stream keeps;
 * the participant's end frame (kind 1, a StepSocketEnd) is CS_FAILED with its code, and a frame
 * over `max_receive` ends the stream with RESOURCE_EXHAUSTED (8) naming both sizes.
 */

typedef struct cs_stream cs_stream;

enum { CS_OK = 0, CS_FAILED = 1, CS_TIMEOUT = 2 };

/* Opens the step stream to `target` (host:port or unix:PATH; steps:PATH: a step socket); with
 * `tls`, PEM texts (each may be empty) for the roots, the client's key and its chain. `metadata` holds `count` pairs
 * (key, value). Answers of up to `max_receive` bytes and requests of up to `max_send` travel
 * (gRPC's channel arguments); a larger answer ends the stream with RESOURCE_EXHAUSTED. Never NULL: cs_error()
 * is empty when the stream is open, else says why (the stream must still be closed). */
cs_stream *cs_open(const char *target, int tls, const char *roots, const char *key,
                   const char *chain, const char *const *metadata, int count, double timeout,
                   int max_receive, int max_send);

/* Why the stream failed (empty while it is fine); valid until the next call on it. */
const char *cs_error(cs_stream *s);

/* Writes one serialized DoStepRequest, given as `count` pieces whose concatenation is the
 * message, and asks for the answer; CS_FAILED when the stream has ended (cs_receive then tells
 * its status) or the previous answer was not received. The pieces are not copied: the caller
 * keeps them unchanged until its next cs_send() or cs_close() on this stream. */
int cs_send(cs_stream *s, const char *const *pieces, const size_t *sizes, int count);

/* Waits up to `timeout` seconds for the answer to cs_send(): CS_OK with the serialized
 * DoStepResponse in (*data, *size), valid until the next call on this stream; CS_FAILED with
 * the stream's final status (*code, and cs_error()); CS_TIMEOUT, the stream cancelled. */
int cs_receive(cs_stream *s, double timeout, const char **data, size_t *size, int *code);

/* Ends the stream, half-closing it and waiting up to `timeout` for the participant's status
 * (then cancelling it), and frees it. Safe in any state. Returns how many step answers came
 * after the half-close that no request had asked for (0 from a participant that answers each
 * request once: more means it answered a request twice and every later answer was read as the
 * step after's). */
int cs_close(cs_stream *s, double timeout);
