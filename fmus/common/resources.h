/* Optional resource loading for models that read files from the FMU's resources/ folder.
 *
 * A model that defines MODEL_USES_RESOURCES (before including a wrapper) also defines:
 *   - model_load_resources(d, dir, msg, msg_size)  called once at instantiation, after
 *     model_defaults, with the resources folder as a plain directory path (no trailing
 *     separator); returns false with a message naming the culprit in msg to fail
 *     instantiation (the wrapper passes the message to the logger callback);
 *   - model_free_resources(d)  called when the instance is freed (also after a failed load).
 * The wrappers turn FMI 2.0's fmuResourceLocation (a file:// URI) and FMI 3.0's resourcePath
 * (a path, usually with a trailing separator) into that directory with core_resource_dir.
 * Models that do not define MODEL_USES_RESOURCES are unaffected.
 */
#ifndef COUPLER_FMU_RESOURCES_H
#define COUPLER_FMU_RESOURCES_H

#include <errno.h>

#include "core.h"

static inline int core_hex_digit(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* The directory named by location, a file:// URI (file:///p, file://localhost/p, file:/p;
 * percent-encoded) or a plain path, without trailing separators, into out. */
static inline bool core_resource_dir(const char *location, char *out, size_t out_size, char *msg,
                                     size_t msg_size) {
    const char *p = location;
    bool uri = false;
    size_t n = 0;
    if (location == NULL || location[0] == '\0') {
        snprintf(msg, msg_size, "no resource location given: the FMU's resources/ folder "
                                "(with track.csv and balises.csv) cannot be found");
        return false;
    }
    if (strncmp(p, "file://", 7) == 0) {
        uri = true;
        p += 7;
        if (strncmp(p, "localhost/", 10) == 0) p += 9;
        if (p[0] != '/') {
            snprintf(msg, msg_size, "resource location '%.600s' names a remote host; only local "
                                    "file:// URIs are supported", location);
            return false;
        }
    } else if (strncmp(p, "file:", 5) == 0) {
        uri = true;
        p += 5;
    }
    for (; *p != '\0'; p++) {
        char c = *p;
        if (uri && c == '%') {
            int hi = core_hex_digit(p[1]);
            int lo = hi < 0 ? -1 : core_hex_digit(p[2]);
            if (lo < 0) {
                snprintf(msg, msg_size, "resource location '%.600s': bad percent escape", location);
                return false;
            }
            c = (char)(hi * 16 + lo);
            p += 2;
        }
        if (n + 1 >= out_size) {
            snprintf(msg, msg_size, "resource location '%.600s' is too long", location);
            return false;
        }
        out[n++] = c;
    }
    while (n > 1 && (out[n - 1] == '/' || out[n - 1] == '\\')) n--;
    out[n] = '\0';
    return true;
}

/* The whole file dir/name as a NUL-terminated string the caller frees; NULL with a message
 * naming the file on failure. */
static inline char *core_read_resource(const char *dir, const char *name, char *msg,
                                       size_t msg_size) {
    char path[4096];
    FILE *f;
    char *text = NULL;
    size_t size = 0, cap = 0, got;
    if ((size_t)snprintf(path, sizeof path, "%s/%s", dir, name) >= sizeof path) {
        snprintf(msg, msg_size, "resource path %.600s/%.100s is too long", dir, name);
        return NULL;
    }
    f = fopen(path, "rb");
    if (f == NULL) {
        snprintf(msg, msg_size, "cannot open resource file %.600s: %.100s (the FMU must carry "
                                "resources/%.100s)", path, strerror(errno), name);
        return NULL;
    }
    do {
        if (size + 4096 + 1 > cap) {
            char *bigger;
            cap = 2 * cap + 4096 + 1;
            bigger = (char *)realloc(text, cap);
            if (bigger == NULL) {
                free(text);
                fclose(f);
                snprintf(msg, msg_size, "out of memory reading %.600s", path);
                return NULL;
            }
            text = bigger;
        }
        got = fread(text + size, 1, 4096, f);
        size += got;
    } while (got > 0);
    if (ferror(f)) {
        free(text);
        fclose(f);
        snprintf(msg, msg_size, "cannot read resource file %.600s", path);
        return NULL;
    }
    fclose(f);
    text[size] = '\0';
    return text;
}

#endif
