/*
 * The protocol engine's CONFIG (proto_int.h lists the engine's parts; docs/protocol.md, CONFIG): every
 * field within the protocol's range (the generated table of wm_protocol.h), then within the device's
 * capabilities; a good CONFIG starts a session (RECEIVING).
 */
#include "proto_int.h"

/* CONFIG's field ranges (host/wavemesh/device/protocol.py, CONFIG: the ones the host checks before sending) */
typedef struct config_range {
    uint8_t off, bytes;
    uint64_t lo, hi;
} config_range;

static const config_range config_ranges[WM_PROTO_CONFIG_RANGES] = WM_PROTO_CONFIG_RANGE_TABLE;

/* A CONFIG field of `bytes` bytes at c, little-endian. */
static uint64_t field_value(const uint8_t *c, int bytes)
{
    return bytes == 8 ? get64(c) : bytes == 4 ? get32(c) : bytes == 2 ? get16(c) : c[0];
}

/* CONFIG's fields, checked one by one: 0, or the error code with *detail. */
static int parse_config(wm_proto *p, wm_proto_job *j, uint32_t *detail)
{
    const uint8_t *c = p->f_pay;
    const wm_proto_caps *cap = &p->caps;
    uint32_t w = get16(c + WM_PROTO_CONFIG_WIDTH), h = get16(c + WM_PROTO_CONFIG_HEIGHT);
    uint32_t levels = c[WM_PROTO_CONFIG_LEVELS];
    uint32_t flags = get32(c + WM_PROTO_CONFIG_FLAGS), tau = get32(c + WM_PROTO_CONFIG_TAU);
    uint32_t budget = get32(c + WM_PROTO_CONFIG_MAX_TRIANGLES), cap_tri = get32(c + WM_PROTO_CONFIG_CAPACITY);
#define BAD(field)                         \
    do {                                   \
        *detail = WM_PROTO_CONFIG_##field; \
        return WM_PROTO_E_BAD_VALUE;       \
    } while (0)
    /* every field within the protocol's range (the first one out of it is named), ... */
    for (int i = 0; i < WM_PROTO_CONFIG_RANGES; i++) {
        const config_range *r = &config_ranges[i];
        uint64_t v = field_value(c + r->off, r->bytes);
        if (v < r->lo || v > r->hi) {
            *detail = r->off;
            return WM_PROTO_E_BAD_VALUE;
        }
    }
    /* ... then within this device's capabilities */
    if (w > cap->max_width || h > cap->max_height || w * h > cap->max_samples) {
        *detail = w << 16 | h;
        return WM_PROTO_E_TOO_LARGE;
    }
    if (levels > cap->max_levels) BAD(LEVELS);
    if ((flags & WM_PROTO_CONFIG_INITIAL_ONLY) && !(cap->features & WM_PROTO_FEATURE_INITIAL_ONLY)) BAD(FLAGS);
    if ((flags & WM_PROTO_CONFIG_SPLINE) && !(cap->features & WM_PROTO_FEATURE_SPLINE)) BAD(FLAGS);
    if ((flags & WM_PROTO_CONFIG_MASK) &&
        (!(cap->features & WM_PROTO_FEATURE_HOLES) || p->mask == NULL || 2 * ((w * h + 15) / 16) > p->mask_bytes))
        BAD(FLAGS);
    if (cap_tri == 0) cap_tri = cap->tri_capacity;
    if (cap_tri < 2 || cap_tri > cap->tri_capacity) BAD(CAPACITY);
    if (budget != 0 && (budget < 2 || budget >= cap_tri)) BAD(MAX_TRIANGLES);
#undef BAD
    j->width = (int32_t)w;
    j->height = (int32_t)h;
    j->levels = (int32_t)levels;
    j->tau = tau;
    j->flags = flags;
    j->capacity = (int32_t)cap_tri;
    /* the refiner's parameters: every CONFIG field that is a wm_params member (wm_protocol.h's list) */
#define COPY(member, off, bytes, type) j->params.member = (type)field_value(c + (off), (bytes));
    WM_PROTO_CONFIG_PARAMS(COPY)
#undef COPY
    j->params.flags = (flags >> WM_PROTO_CONFIG_REFINER_SHIFT) & WM_FLAG_ALL; /* WM_FLAG_* */
    j->delta_lambda = j->params.delta_lambda;
    j->delta_c = j->params.delta_c;
    j->heights = p->heights;
    j->mask = (flags & WM_PROTO_CONFIG_MASK) ? p->mask : NULL;
    if (wm_params_check(&j->params) != WM_OK) { /* cannot happen after the checks above */
        *detail = WM_PROTO_CONFIG_ZETA;
        return WM_PROTO_E_BAD_VALUE;
    }
    return 0;
}

void wm_proto_do_config(wm_proto *p)
{
    uint32_t detail = 0;
    int code;
    if (wm_proto_duplicate(p)) return;
    if (p->f_len != WM_PROTO_CONFIG_BYTES) {
        wm_proto_reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    wm_proto_session_end(p); /* a new CONFIG replaces the session */
    code = parse_config(p, &p->job, &detail);
    if (code) {
        wm_proto_reply_error(p, (uint8_t)code, detail);
        return;
    }
    p->total = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (p->job.mask) p->total += (p->total + 15) / 16; /* the mask's words follow the samples */
    p->next = 0;
    p->nak_sent = 0;
    p->state = WM_PROTO_STATE_RECEIVING;
    p->session_id++; /* a transport that stores DATA itself starts afresh (proto_slip.c) */
    for (int s = 0; s < WM_PROTO_STAGE_COUNT; s++) p->cycles[s] = 0;
    p->link = 0;
    p->link_depth = 0;
    p->stage = -1;
    stage_enter(p, WM_PROTO_STAGE_RECEIVE);
    wm_proto_reply_ok(p);
}
