/* Helpers over the model's variable table; included by the wrappers after the model. */
#ifndef COUPLER_FMU_VARS_H
#define COUPLER_FMU_VARS_H

/* Free every string and binary buffer of d. */
static inline void core_free_data(ModelData *d) {
    size_t i;
    for (i = 0; i < MODEL_NVARS; i++) {
        const VarInfo *v = &MODEL_VARS[i];
        if (v->causality == VC_INDEPENDENT) continue;
        if (v->type == VT_STRING) {
            char **s = FIELD(d, v, char *);
            free(*s);
            *s = NULL;
        } else if (v->type == VT_BINARY) {
            Bytes *b = FIELD(d, v, Bytes);
            free(b->data);
            b->data = NULL;
            b->size = 0;
        }
    }
}

/* Find the variable with value reference vr and the given type; on failure write a message
 * naming the culprit into msg and return NULL. */
static inline const VarInfo *core_lookup(unsigned int vr, VarType type, char *msg, size_t msg_size) {
    size_t i;
    for (i = 0; i < MODEL_NVARS; i++) {
        if (MODEL_VARS[i].vr != vr) continue;
        if (MODEL_VARS[i].type != type) {
            snprintf(msg, msg_size, "value reference %u (%s) is %s, not %s", vr,
                     MODEL_VARS[i].name, core_type_name(MODEL_VARS[i].type),
                     core_type_name(type));
            return NULL;
        }
        return &MODEL_VARS[i];
    }
    snprintf(msg, msg_size, "unknown %s value reference %u", core_type_name(type), vr);
    return NULL;
}

/* Whether v may be set in mode; parameters are fixed after initialization. */
static inline bool core_can_set(const VarInfo *v, Mode mode, char *msg, size_t msg_size) {
    bool ok;
    if (v->causality == VC_PARAMETER) {
        ok = mode == MODE_INSTANTIATED || mode == MODE_INITIALIZATION;
    } else if (v->causality == VC_INPUT) {
        ok = mode != MODE_TERMINATED;
    } else {
        ok = false;
    }
    if (!ok) snprintf(msg, msg_size, "variable %s (value reference %u) cannot be set now",
                      v->name, v->vr);
    return ok;
}

/* Whether the model asked to end the simulation in the step just taken (MODEL_CAN_TERMINATE);
 * then *time is where it stopped and msg says so. */
static inline bool core_model_ends(const ModelData *d, double *time, char *msg, size_t msg_size) {
#ifdef MODEL_CAN_TERMINATE
    if (!model_ends(d, time)) return false;
    snprintf(msg, msg_size, "the model asks to end the simulation at t=%g", *time);
    return true;
#else
    (void)d;
    (void)time;
    (void)msg;
    (void)msg_size;
    return false;
#endif
}

#endif
