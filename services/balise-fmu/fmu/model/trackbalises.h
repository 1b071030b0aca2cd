/* TrackBalises: which balises a train's antenna passes, and where the train is, from its
 * position along the track. The model behind TrackBalises (FMI 2.0) and TrackBalises3 (FMI 3.0);
 * see fmus/common/core.h for the model interface and the wrappers.
 *
 * Resources (written by coupler_railway.write_fmu_resources, read at instantiation):
 *   resources/track.csv    distance_m,latitude_deg,longitude_deg  (distance strictly increasing)
 *   resources/balises.csv  balise_id,group_id,position_in_group,distance_m  (sorted by distance)
 *
 * Semantics. The antenna is at a = position + antenna_offset. A balise at distance b is
 * "behind" the antenna when a >= b; every change of that is one pass, in either direction of
 * travel. doStep(t, h) moves the antenna from where the previous step (or the end of
 * initialization) left it to the position input set before the step: moving forward from
 * a_prev to a_new passes the balises with b in (a_prev, a_new], in increasing distance;
 * moving backward passes those with b in (a_new, a_prev], in decreasing distance. So a jump
 * over a whole group in one step reports every balise of it: balises_passed grows by the
 * number crossed, last_* describe the last one crossed in travel order and passed_in_step lists
 * all of them as "id:group:distance;..." (distance as %.17g, which reads back exactly; empty
 * when the step crossed none). Nothing is passed at initialization.
 * latitude/longitude: the train's position (not the antenna's), linear interpolation between
 * the track samples, clamped to the track's ends. A non-finite position is ignored for
 * passing (the antenna stays where it was).
 */
#define MODEL_USES_RESOURCES
#include "../../../../fmus/common/core.h"
#include "../../../../fmus/common/resources.h"

#define TRACK_HEADER "distance_m,latitude_deg,longitude_deg"
#define BALISES_HEADER "balise_id,group_id,position_in_group,distance_m"

typedef struct {
    int id;
    int group;
    int rank;
    double distance;
} BaliseRow;

typedef struct {
    double antenna_offset;
    double position;
    int last_balise_id;
    int last_group_id;
    double last_balise_distance;
    int balises_passed;
    double latitude;
    double longitude;
    char *passed_in_step;
    /* state: where the antenna was at the end of the previous step */
    double antenna;
    /* resources */
    size_t n_track;
    double *track; /* n_track rows of distance, latitude, longitude */
    size_t n_balises;
    BaliseRow *balises;
} ModelData;

static const VarInfo MODEL_VARS[] = {
    {0, VT_REAL, VC_INDEPENDENT, 0, "time", 0},
    VAR(1, VT_REAL, VC_PARAMETER, antenna_offset),
    VAR(2, VT_REAL, VC_INPUT, position),
    VAR(3, VT_INTEGER, VC_OUTPUT, last_balise_id),
    VAR(4, VT_INTEGER, VC_OUTPUT, last_group_id),
    VAR(5, VT_REAL, VC_OUTPUT, last_balise_distance),
    VAR(6, VT_INTEGER, VC_OUTPUT, balises_passed),
    VAR(7, VT_REAL, VC_OUTPUT, latitude),
    VAR(8, VT_REAL, VC_OUTPUT, longitude),
    VAR(9, VT_STRING, VC_OUTPUT, passed_in_step),
};
#define MODEL_NVARS (sizeof(MODEL_VARS) / sizeof(MODEL_VARS[0]))

/* --- resources ---------------------------------------------------------------------------- */

/* Next line of *cursor (NUL-terminated in place, "\r" stripped); NULL at the end. */
static char *tb_next_line(char **cursor, int *line_no) {
    char *line = *cursor, *end;
    size_t n;
    if (line == NULL || *line == '\0') return NULL;
    end = strchr(line, '\n');
    if (end != NULL) {
        *end = '\0';
        *cursor = end + 1;
    } else {
        *cursor = line + strlen(line);
    }
    n = strlen(line);
    if (n > 0 && line[n - 1] == '\r') line[n - 1] = '\0';
    *line_no += 1;
    return line;
}

static bool tb_blank(const char *line) {
    for (; *line != '\0'; line++)
        if (*line != ' ' && *line != '\t') return false;
    return true;
}

/* Parse exactly n comma-separated fields of line into values (numbers); false if malformed. */
static bool tb_fields(char *line, double *values, size_t n) {
    size_t i;
    char *p = line, *end;
    for (i = 0; i < n; i++) {
        while (*p == ' ' || *p == '\t') p++;
        values[i] = strtod(p, &end);
        if (end == p || !isfinite(values[i])) return false;
        p = end;
        while (*p == ' ' || *p == '\t') p++;
        if (i + 1 < n) {
            if (*p != ',') return false;
            p++;
        }
    }
    return *p == '\0';
}

static bool tb_is_int32(double x) {
    return x == floor(x) && x >= -2147483648.0 && x <= 2147483647.0;
}

/* Read the header of file name and check it; cursor then points at the first data row. */
static bool tb_header(char **cursor, int *line_no, const char *dir, const char *name,
                      const char *expected, char *msg, size_t msg_size) {
    char *line = tb_next_line(cursor, line_no);
    if (line == NULL || strcmp(line, expected) != 0) {
        snprintf(msg, msg_size, "%.600s/%.100s line 1: header is '%.80s', expected '%s'", dir, name,
                 line ? line : "(empty file)", expected);
        return false;
    }
    return true;
}

static bool tb_load_track(ModelData *d, const char *dir, char *msg, size_t msg_size) {
    char *text = core_read_resource(dir, "track.csv", msg, msg_size);
    char *cursor = text, *line;
    int line_no = 0;
    size_t cap = 0;
    bool ok = false;
    if (text == NULL) return false;
    if (!tb_header(&cursor, &line_no, dir, "track.csv", TRACK_HEADER, msg, msg_size)) goto done;
    while ((line = tb_next_line(&cursor, &line_no)) != NULL) {
        double row[3];
        if (tb_blank(line)) continue;
        if (!tb_fields(line, row, 3)) {
            snprintf(msg, msg_size, "%.600s/track.csv line %d: '%.80s' is not three numbers %s",
                     dir, line_no, line, TRACK_HEADER);
            goto done;
        }
        if (d->n_track > 0 && !(row[0] > d->track[3 * (d->n_track - 1)])) {
            snprintf(msg, msg_size, "%.600s/track.csv line %d: distance_m %.17g does not increase "
                     "(previous row %.17g)", dir, line_no, row[0], d->track[3 * (d->n_track - 1)]);
            goto done;
        }
        if (d->n_track == cap) {
            double *bigger;
            cap = cap ? 2 * cap : 256;
            bigger = (double *)realloc(d->track, 3 * cap * sizeof(double));
            if (bigger == NULL) {
                snprintf(msg, msg_size, "out of memory reading %.600s/track.csv", dir);
                goto done;
            }
            d->track = bigger;
        }
        memcpy(&d->track[3 * d->n_track], row, sizeof row);
        d->n_track++;
    }
    if (d->n_track < 2) {
        snprintf(msg, msg_size, "%.600s/track.csv: %zu track samples, at least 2 are needed", dir,
                 d->n_track);
        goto done;
    }
    ok = true;
done:
    free(text);
    return ok;
}

static bool tb_load_balises(ModelData *d, const char *dir, char *msg, size_t msg_size) {
    char *text = core_read_resource(dir, "balises.csv", msg, msg_size);
    char *cursor = text, *line;
    int line_no = 0;
    size_t cap = 0;
    bool ok = false;
    if (text == NULL) return false;
    if (!tb_header(&cursor, &line_no, dir, "balises.csv", BALISES_HEADER, msg, msg_size))
        goto done;
    while ((line = tb_next_line(&cursor, &line_no)) != NULL) {
        double row[4];
        if (tb_blank(line)) continue;
        if (!tb_fields(line, row, 4) || !tb_is_int32(row[0]) || !tb_is_int32(row[1]) ||
            !tb_is_int32(row[2])) {
            snprintf(msg, msg_size, "%.600s/balises.csv line %d: '%.80s' is not three integers and "
                     "a number %s", dir, line_no, line, BALISES_HEADER);
            goto done;
        }
        if (d->n_balises > 0 && row[3] < d->balises[d->n_balises - 1].distance) {
            snprintf(msg, msg_size, "%.600s/balises.csv line %d: distance_m %.17g is less than the "
                     "previous row's %.17g; rows must be sorted by distance_m", dir, line_no,
                     row[3], d->balises[d->n_balises - 1].distance);
            goto done;
        }
        if (d->n_balises == cap) {
            BaliseRow *bigger;
            cap = cap ? 2 * cap : 64;
            bigger = (BaliseRow *)realloc(d->balises, cap * sizeof(BaliseRow));
            if (bigger == NULL) {
                snprintf(msg, msg_size, "out of memory reading %.600s/balises.csv", dir);
                goto done;
            }
            d->balises = bigger;
        }
        d->balises[d->n_balises].id = (int)row[0];
        d->balises[d->n_balises].group = (int)row[1];
        d->balises[d->n_balises].rank = (int)row[2];
        d->balises[d->n_balises].distance = row[3];
        d->n_balises++;
    }
    ok = true;
done:
    free(text);
    return ok;
}

static bool model_load_resources(ModelData *d, const char *dir, char *msg, size_t msg_size) {
    return tb_load_track(d, dir, msg, msg_size) && tb_load_balises(d, dir, msg, msg_size);
}

static void model_free_resources(ModelData *d) {
    free(d->track);
    d->track = NULL;
    d->n_track = 0;
    free(d->balises);
    d->balises = NULL;
    d->n_balises = 0;
}

/* --- the model ---------------------------------------------------------------------------- */

static void model_defaults(ModelData *d) {
    d->antenna_offset = 0.0;
    d->position = 0.0;
    d->last_balise_id = 0;
    d->last_group_id = 0;
    d->last_balise_distance = 0.0;
    d->balises_passed = 0;
    d->latitude = 0.0;
    d->longitude = 0.0;
    core_set_string(&d->passed_in_step, "");
    d->antenna = 0.0;
}

/* Latitude and longitude at distance s: linear between the samples around s (binary search). */
static void tb_locate(const ModelData *d, double s, double *lat, double *lon) {
    const double *t = d->track;
    size_t lo = 0, hi = d->n_track - 1;
    double f;
    if (d->n_track == 0) return;
    if (!(s > t[0])) { /* also NaN */
        *lat = t[1];
        *lon = t[2];
        return;
    }
    if (s >= t[3 * hi]) {
        *lat = t[3 * hi + 1];
        *lon = t[3 * hi + 2];
        return;
    }
    while (hi - lo > 1) { /* invariant: t[lo] < s < t[hi] or s == t[lo] */
        size_t mid = lo + (hi - lo) / 2;
        if (t[3 * mid] <= s) lo = mid;
        else hi = mid;
    }
    f = (s - t[3 * lo]) / (t[3 * hi] - t[3 * lo]);
    *lat = t[3 * lo + 1] + f * (t[3 * hi + 1] - t[3 * lo + 1]);
    *lon = t[3 * lo + 2] + f * (t[3 * hi + 2] - t[3 * lo + 2]);
}

static void model_calculate(ModelData *d, double t, bool initializing) {
    (void)t;
    (void)initializing;
    tb_locate(d, d->position, &d->latitude, &d->longitude);
}

static void model_start(ModelData *d) {
    d->antenna = d->position + d->antenna_offset;
    d->last_balise_id = 0;
    d->last_group_id = 0;
    d->last_balise_distance = 0.0;
    d->balises_passed = 0;
    core_set_string(&d->passed_in_step, "");
}

/* Index of the first balise with distance > a (n_balises when none). */
static size_t tb_first_beyond(const ModelData *d, double a) {
    size_t lo = 0, hi = d->n_balises;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (d->balises[mid].distance <= a) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Append one reading to buf (which has room: 80 bytes per balise) and update the outputs. */
static size_t tb_pass(ModelData *d, const BaliseRow *b, char *buf, size_t used, size_t size) {
    int n = snprintf(buf + used, size - used, "%s%d:%d:%.17g", used > 0 ? ";" : "", b->id,
                     b->group, b->distance);
    d->last_balise_id = b->id;
    d->last_group_id = b->group;
    d->last_balise_distance = b->distance;
    d->balises_passed += 1;
    return n > 0 ? used + (size_t)n : used;
}

static void model_step(ModelData *d, double t, double h) {
    double a_new = d->position + d->antenna_offset, a_old = d->antenna;
    size_t from, to, size, used = 0;
    char *buf;
    (void)t;
    (void)h;
    if (!isfinite(a_new)) a_new = a_old;
    from = tb_first_beyond(d, a_new < a_old ? a_new : a_old);
    to = tb_first_beyond(d, a_new < a_old ? a_old : a_new);
    /* crossed: balises[from .. to-1], i.e. distance in (min, max] */
    size = (to - from) * 80 + 1;
    buf = (char *)malloc(size);
    if (buf == NULL) return; /* out of memory: nothing reported, state kept */
    buf[0] = '\0';
    if (a_new > a_old) {
        size_t i;
        for (i = from; i < to; i++) used = tb_pass(d, &d->balises[i], buf, used, size);
    } else if (a_new < a_old) {
        size_t i;
        for (i = to; i > from; i--) used = tb_pass(d, &d->balises[i - 1], buf, used, size);
    }
    free(d->passed_in_step);
    d->passed_in_step = buf;
    d->antenna = a_new;
}
