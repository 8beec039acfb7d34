/*
 * The protocol engine's mesh emission (proto_int.h lists the engine's parts; docs/protocol.md, "Level
 * stream"): each level's stream (LEVEL_HEADER, vertex slots, triangles; delta-coded when that is
 * shorter) in MESH frames, then LEVEL_END, resent from where the host's ACK says until it has all of it.
 * Building the stream once is the EMIT stage's work; framing, writing and waiting are link I/O.
 */
#include "proto_int.h"
#include "wm_inline.h"

/* --- the level stream: LEVEL_HEADER, vertex slots, triangles --- */

/* The k-th live triangle's slot (sequential calls are O(1) each). */
static int32_t tri_slot(wm_proto *p, int32_t k)
{
    const wm_mesh *m = p->lm;
    if (k < p->cur_k) {
        p->cur_k = 0;
        p->cur_slot = 0;
        while (p->cur_slot < m->tri_end && m->he[3 * p->cur_slot].v < 0) p->cur_slot++;
    }
    while (p->cur_k < k) {
        p->cur_slot++;
        while (p->cur_slot < m->tri_end && m->he[3 * p->cur_slot].v < 0) p->cur_slot++;
        p->cur_k++;
    }
    return p->cur_slot;
}

/* Bytes [off, off + n) of the level stream into dst.  Triangle bytes run from one position on (one
 * division a call, not four a byte: each is a division instruction of some 40 cycles on the soft
 * CPU, and the stream is most of the EMIT stage). */
static void level_bytes(wm_proto *p, uint32_t off, uint8_t *dst, uint32_t n)
{
    const wm_mesh *m = p->lm;
    uint32_t hb = WM_PROTO_LEVEL_HEADER_BYTES, vb = 4u * (uint32_t)m->vert_end, tb = 3u * p->lib, i = 0;
    uint32_t lsh = p->lib == 4 ? 2u : 1u; /* index bytes 2 or 4 */
    for (; i < n && off < hb; i++, off++) dst[i] = p->lhdr[off];
    for (; i < n && off < hb + vb; i++, off++) {
        uint32_t v = (off - hb) / 4, part = (off - hb) % 4;
        uint32_t c = part < 2 ? m->vxy[v].x : m->vxy[v].y;
        if (m->vxy[v].x == WM_FREE) c = WM_PROTO_FREE_VERTEX;
        dst[i] = (uint8_t)(c >> (8 * (part & 1)));
    }
    if (i < n) {
        uint32_t r = off - hb - vb, k = r / tb, q = r - k * tb;
        int32_t t = tri_slot(p, (int32_t)k);
        for (;;) {
            uint32_t v = (uint32_t)m->he[3 * t + (int32_t)(q >> lsh)].v;
            dst[i++] = (uint8_t)(v >> (8 * (q & (p->lib - 1u))));
            if (i == n) break;
            if (++q == tb) {
                q = 0;
                t = tri_slot(p, (int32_t)++k);
            }
        }
    }
}

/* Halfwords [pos, end) of the level stream into d: its bytes 2 pos .. 2 end - 1 in little-endian pairs
 * (a vertex slot is two, an index one or two), for even offsets and lengths (the common case): whole
 * vertex slots and triangles at a time, the triangle cursor (tri_slot) kept in registers. */
static void level_halves(wm_proto *p, uint32_t pos, uint32_t end, uint16_t *d)
{
    const wm_mesh *m = p->lm;
    uint32_t hb = WM_PROTO_LEVEL_HEADER_BYTES / 2, ve = hb + 2u * (uint32_t)m->vert_end;
    for (; pos < end && pos < hb; pos++) *d++ = (uint16_t)get16(p->lhdr + 2 * pos);
    if (pos < end && pos < ve) { /* vertex slots: x, y (a free one: WM_PROTO_FREE_VERTEX == WM_FREE twice) */
        const wm_xy *xy = m->vxy;
        uint32_t v = (pos - hb) >> 1;
        if ((pos - hb) & 1u) { /* the first slot's y */
            *d++ = xy[v].x == WM_FREE ? WM_FREE : xy[v].y;
            pos++;
            v++;
        }
        for (; pos + 2u <= end && pos < ve; pos += 2u, v++, d += 2) {
            uint16_t x = xy[v].x;
            d[0] = x;
            d[1] = x == WM_FREE ? x : xy[v].y;
        }
        if (pos < end && pos < ve) { /* the last slot's x */
            *d++ = xy[v].x;
            pos++;
        }
    }
    if (pos < end) { /* the triangles, from the k-th live one's q-th halfword */
        uint32_t per = p->lib == 4 ? 6u : 3u, r = pos - ve, k = r / per, q = r - k * per;
        int32_t t = tri_slot(p, (int32_t)k), te = m->tri_end;
        const wm_he *he = m->he;
        for (;;) {
            const wm_he *h = he + 3 * t;
            if (q == 0 && end - pos >= per) {
                if (per == 3u) {
                    d[0] = (uint16_t)h[0].v;
                    d[1] = (uint16_t)h[1].v;
                    d[2] = (uint16_t)h[2].v;
                } else {
                    uint32_t a = (uint32_t)h[0].v, b = (uint32_t)h[1].v, c = (uint32_t)h[2].v;
                    d[0] = (uint16_t)a;
                    d[1] = (uint16_t)(a >> 16);
                    d[2] = (uint16_t)b;
                    d[3] = (uint16_t)(b >> 16);
                    d[4] = (uint16_t)c;
                    d[5] = (uint16_t)(c >> 16);
                }
                d += per;
                pos += per;
            } else { /* part of one: the frame's first or last */
                for (; q < per && pos < end; q++, pos++)
                    *d++ = (uint16_t)(per == 6u ? (uint32_t)h[q >> 1].v >> (16u * (q & 1u)) : (uint32_t)h[q].v);
                if (q < per) break;
                q = 0;
            }
            if (pos == end) break;
            do t++;
            while (t < te && he[3 * t].v < 0);
            k++;
        }
        p->cur_k = (int32_t)k; /* the cursor where this frame ended */
        p->cur_slot = t;
    }
}

/* --- LEVEL_DELTA (docs/protocol.md, "Level coding"): the body as variable-length numbers --- */

/* The bytes of a variable-length number of v (put_varint's count). */
static WM_ALWAYS_INLINE uint32_t varint_bytes(uint32_t v)
{
    return v < 0x4000u ? 1u + (v >= 0x80u) : 3u + (v >= 0x200000u) + (v >= 0x10000000u);
}

/* v as a variable-length number at d + n (7 bits a byte, low first, the top bit set on all but the
 * last); n plus its bytes. */
static WM_ALWAYS_INLINE uint32_t put_varint(uint8_t *d, uint32_t n, uint32_t v)
{
    while (v >= 0x80u) {
        d[n++] = (uint8_t)(v | 0x80u);
        v >>= 7;
    }
    d[n++] = (uint8_t)v;
    return n;
}

static uint32_t zigzag32(int32_t v) { return ((uint32_t)v << 1) ^ (uint32_t)(0 - (int32_t)((uint32_t)v >> 31)); }

static void coded_reset(wm_proto *p)
{
    static const wm_proto_coder start;
    p->cpos = 0;
    p->coder = start;
    p->cbn = p->cbi = 0;
}

/* One item of the body (docs/protocol.md, "Level coding"), the coder's one statement of it for all its
 * callers: the vertex slot at xy (tri 0) or the live triangle whose half-edges start at h (tri 1),
 * coded against the previous live vertex (c->px, c->py) or triangle's first index (c->pi), which it
 * then moves on.  Its bytes at d (room for 16), or with count set only their count (varint_bytes of
 * the same numbers, one test for the common case: each number one or two bytes; d unused).  The
 * callers pass tri and count as constants and c as a local, so that it inlines to the one case each
 * needs, its state in registers. */
static WM_ALWAYS_INLINE uint32_t code_one(wm_proto_coder *c, int tri, int count, const wm_xy *xy, const wm_he *h,
                                          uint8_t *d)
{
    uint32_t z0, z1, z2 = 0;
    uint8_t *e;
    if (!tri) {
        int32_t x = xy->x, y;
        if (x == WM_FREE) { /* a free slot: one 0 */
            if (!count) d[0] = 0;
            return 1;
        }
        y = xy->y;
        z0 = zigzag32(x - c->px) + 1u;
        z1 = zigzag32(y - c->py);
        c->px = x;
        c->py = y;
    } else {
        int32_t a = h[0].v;
        z0 = zigzag32(a - c->pi);
        z1 = zigzag32(h[1].v - a);
        z2 = zigzag32(h[2].v - a);
        c->pi = a;
    }
    if (count) {
        if ((z0 | z1 | z2) < 0x4000u) return (tri ? 3u : 2u) + (z0 >= 0x80u) + (z1 >= 0x80u) + (z2 >= 0x80u);
        return varint_bytes(z0) + varint_bytes(z1) + (tri ? varint_bytes(z2) : 0u);
    }
    e = d + put_varint(d, 0, z0); /* each number from its own pointer: no index to add to d a byte */
    e += put_varint(e, 0, z1);
    if (tri) e += put_varint(e, 0, z2);
    return (uint32_t)(e - d);
}

/* The body's next item (code_one's bytes into d) from the coder's state alone: for an item a frame
 * splits (coded_bytes gives it through cb).  0 when no item is left. */
static WM_ALWAYS_INLINE uint32_t code_item(const wm_mesh *m, wm_proto_coder *c, uint8_t *d)
{
    if (c->v < m->vert_end) return code_one(c, 0, 0, m->vxy + c->v++, NULL, d);
    if (c->k < m->n_tri) {
        int32_t t = c->slot;
        while (m->he[3 * t].v < 0) t++; /* a free triangle slot */
        c->slot = t + 1;
        c->k++;
        return code_one(c, 1, 0, NULL, m->he + 3 * t, d);
    }
    return 0;
}

/* The coded stream's length: the header and every item's count (code_one) from the coder's start
 * (p's left there), in a loop over the vertex slots and one over the live triangles with pointers. */
static uint32_t coded_total(wm_proto *p)
{
    const wm_mesh *m = p->lm;
    const wm_xy *xy = m->vxy, *xe = xy + m->vert_end;
    const wm_he *h = m->he;
    uint32_t total = WM_PROTO_LEVEL_HEADER_BYTES;
    wm_proto_coder c;
    coded_reset(p);
    c = p->coder;
    for (; xy < xe; xy++) total += code_one(&c, 0, 1, xy, NULL, NULL);
    for (int32_t k = m->n_tri; k > 0; k--, h += 3) {
        while (h->v < 0) h += 3; /* a free triangle slot */
        total += code_one(&c, 1, 1, NULL, h, NULL);
    }
    return total;
}

/* Whole items into d while n - (bytes given) >= 16 (code_one's room; n >= 16): the bytes given, 0 when
 * no item is left.  code_item's items, in a loop over the vertex slots and one over the live triangles
 * with pointers (code_item tests which part it is in and indexes its array each item). */
static uint32_t code_run(const wm_mesh *m, wm_proto_coder *cp, uint8_t *d, uint32_t n)
{
    uint8_t *d0 = d, *de = d + n - 16u;
    wm_proto_coder c = *cp;
    if (c.v < m->vert_end) {
        const wm_xy *xy = m->vxy + c.v, *xe = m->vxy + m->vert_end;
        for (; xy < xe && d <= de; xy++) d += code_one(&c, 0, 0, xy, NULL, d);
        c.v = (int32_t)(xy - m->vxy);
    }
    if (c.v >= m->vert_end) {
        int32_t t = c.slot, k = c.k, kn = m->n_tri;
        const wm_he *h = m->he + 3 * t;
        for (; k < kn && d <= de; k++, t++, h += 3) {
            while (h->v < 0) { /* a free triangle slot */
                h += 3;
                t++;
            }
            d += code_one(&c, 1, 0, NULL, h, d);
        }
        c.slot = t;
        c.k = k;
    }
    *cp = c;
    return (uint32_t)(d - d0);
}

/* The level's coded stream whole into sbuf (wm_proto_stream_buffer), the header's place left for the
 * caller: one pass of the coder (code_run's loops), its length the count that coded_total would make.
 * Its length when every item went in within the raw stream's length and sbuf's (lbuf set when it is
 * the shorter: it is the one sent), 0 when not (coded_total counts then, and the frames code again). */
static uint32_t coded_into(wm_proto *p)
{
    const wm_mesh *m = p->lm;
    uint32_t lim = p->ltotal < p->sbuf_cap ? p->ltotal : p->sbuf_cap, n;
    wm_proto_coder c;
    if (!p->sbuf || lim < WM_PROTO_LEVEL_HEADER_BYTES + 16u) return 0;
    coded_reset(p);
    c = p->coder;
    n = WM_PROTO_LEVEL_HEADER_BYTES +
        code_run(m, &c, p->sbuf + WM_PROTO_LEVEL_HEADER_BYTES, lim - WM_PROTO_LEVEL_HEADER_BYTES);
    if (c.v < m->vert_end || c.k < m->n_tri) return 0; /* stopped short: it may not be the shorter */
    p->lbuf = n < p->ltotal;
    return n;
}

/* The CRCs of a level stream in sbuf (lbuf) for its first sending's frames (p->chunk bytes each), into
 * sbuf after it (lpc) where they fit, and the stream's CRC (lcrc) from them: in one stretch of the emit
 * stage, where each frame's would start with the caches just emptied (the link's clock ran between). */
static void level_crcs(wm_proto *p)
{
    uint32_t chunk = p->chunk, total = p->ltotal, at = (total + 3u) & ~3u, crc = 0;
    uint32_t *pc = (uint32_t *)(void *)(p->sbuf + at);
    if (chunk == 0 || at > p->sbuf_cap || (p->sbuf_cap - at) / 4u < (total + chunk - 1u) / chunk)
        return; /* send_level_from makes them */
    for (uint32_t from = 0; from < total; from += chunk, pc++) {
        uint32_t n = total - from < chunk ? total - from : chunk;
        *pc = ~wm_proto_crc_run(~0u, p->sbuf + from, n);
        crc = wm_proto_crc_combine(p, crc, *pc, n);
    }
    p->lcrc = crc;
    p->lpc = (const uint32_t *)(void *)(p->sbuf + at);
    p->lpc_chunk = chunk;
}

/* Bytes [off, off + n) of the coded stream into dst (in order from where the last call ended: no work
 * but the new bytes; from before it: the coder runs again from the start). */
static void coded_bytes(wm_proto *p, uint32_t off, uint8_t *dst, uint32_t n)
{
    const wm_mesh *m = p->lm;
    wm_proto_coder c;
    uint32_t pos;
    if (off < p->cpos) coded_reset(p);
    pos = p->cpos;
    for (; n && pos < WM_PROTO_LEVEL_HEADER_BYTES; pos++) { /* the header */
        if (pos >= off) {
            *dst++ = p->lhdr[pos];
            n--;
        }
    }
    c = p->coder;
    while (n) { /* the body: whole items at a time (of the current one, the bytes not given yet) */
        uint32_t a, skip;
        if (p->cbi == p->cbn) { /* no item under way */
            if (pos >= off && n >= sizeof p->cb) { /* the next items straight into dst */
                a = code_run(m, &c, dst, n);
                if (a == 0) break;
                pos += a;
                dst += a;
                n -= a;
                continue;
            }
            a = code_item(m, &c, p->cb); /* into cb, to be given in parts */
            if (a == 0) break;        /* past the end: cannot happen (end <= ltotal) */
            p->cbn = (uint8_t)a;
            p->cbi = 0;
        }
        a = (uint32_t)(p->cbn - p->cbi);
        skip = pos < off ? off - pos : 0; /* bytes before off (a resend from within the stream) */
        if (skip >= a) {
            pos += a;
            p->cbi = p->cbn;
            continue;
        }
        p->cbi += (uint8_t)skip;
        pos += skip;
        a -= skip;
        if (a > n) a = n;
        for (uint32_t i = 0; i < a; i++) dst[i] = p->cb[p->cbi + i];
        p->cbi += (uint8_t)a;
        pos += a;
        dst += a;
        n -= a;
    }
    p->coder = c;
    p->cpos = pos;
}

/* MESH frames of p->chunk bytes for bytes [from, end) (end <= ltotal).  The first sending (first: from
 * is 0) takes the stream's CRC on the way, and only its frames are link I/O: building the stream and
 * its CRC is the EMIT stage's work; the frame's CRC follows from the payload's (crc_combine).  A resend
 * happens inside link I/O (the host asked for it). */
static void send_level_from(wm_proto *p, uint32_t from, uint32_t end, int first)
{
    uint32_t chunk = p->chunk;
    const uint32_t *lpc = first && p->lpc && p->lpc_chunk == chunk ? p->lpc : NULL; /* level_crcs' */
    if (first && !lpc) p->lcrc = 0;
    while (from < end) {
        uint32_t n = end - from < chunk ? end - from : chunk, pc;
        uint8_t *b = p->tx.b, *pay = b + WM_PROTO_MESH_BYTES, head[WM_PROTO_HEADER_BYTES];
        zero(b, WM_PROTO_MESH_BYTES);
        b[WM_PROTO_MESH_LEVEL] = p->level;
        b[WM_PROTO_MESH_INDEX] = p->levels_sent;
        put32(b + WM_PROTO_MESH_OFFSET, from);
        if (p->lbuf) pay = p->sbuf + from; /* coded already (coded_into) */
        else if (p->lcoded) coded_bytes(p, from, pay, n);
        else if (WM_LITTLE_ENDIAN && !((from | n) & 1u))
            level_halves(p, from / 2, (from + n) / 2, p->tx.h + WM_PROTO_MESH_BYTES / 2);
        else level_bytes(p, from, pay, n);
        if (lpc) pc = *lpc++;
        else {
            pc = ~wm_proto_crc_run(~0u, pay, n);
            if (first) p->lcrc = wm_proto_crc_combine(p, p->lcrc, pc, n);
        }
        link_begin(p);
        frame_head(head, WM_PROTO_T_MESH, p->seq++, WM_PROTO_MESH_BYTES + n);
        wm_proto_send_encoded(
            p, head, b, WM_PROTO_MESH_BYTES, pay, n,
            wm_proto_crc_combine(
                p, ~wm_proto_crc_run(wm_proto_crc_run(~0u, head, sizeof head), b, WM_PROTO_MESH_BYTES), pc, n));
        link_end(p);
        from += n;
    }
}

static void send_level_end(wm_proto *p)
{
    uint8_t b[WM_PROTO_LEVEL_END_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_LEVEL_END_LEVEL] = p->level;
    b[WM_PROTO_LEVEL_END_INDEX] = p->levels_sent;
    b[WM_PROTO_LEVEL_END_FLAGS] = p->llast ? WM_PROTO_LEVEL_LAST : 0;
    put32(b + WM_PROTO_LEVEL_END_TOTAL, p->ltotal);
    put32(b + WM_PROTO_LEVEL_END_CRC, p->lcrc);
    wm_proto_send_own(p, WM_PROTO_T_LEVEL_END, b, sizeof b);
    out_flush(p);
}

static int abort_code(const wm_proto *p)
{
    return p->abort == ABORT_NO_ACK ? WM_PROTO_E_NO_ACK : WM_PROTO_E_ABORTED;
}

int wm_proto_emit_level(wm_proto *p, const wm_mesh *m, const wm_level_stats *st, int last)
{
    static const uint8_t stat_off[WM_PROTO_STAT_FIELDS] = WM_PROTO_STAT_OFFSETS;
    const int32_t stat_val[WM_PROTO_STAT_FIELDS] = WM_PROTO_STAT_VALUES(st);
    int prev = p->stage, tries = 0; /* ACKs in a row that asked again without progress */
    uint32_t have = 0, best = 0;
    uint64_t work;
    if (p->abort) return abort_code(p);

    /* the stage that made this level ends; its cycles (link I/O excluded) since the last level */
    stage_enter(p, WM_PROTO_STAGE_EMIT);
    work =
        p->cycles[WM_PROTO_STAGE_FILTER] + p->cycles[WM_PROTO_STAGE_TEMPLATE] + p->cycles[WM_PROTO_STAGE_REFINE];

    /* the header of the level stream */
    p->lm = m;
    p->level = (uint8_t)st->level;
    p->lib = m->vert_end > 0xFFFF ? 4 : 2;
    zero(p->lhdr, sizeof p->lhdr);
    p->lhdr[WM_PROTO_LEVEL_HEADER_LEVEL] = (uint8_t)st->level;
    p->lhdr[WM_PROTO_LEVEL_HEADER_INDEX_BYTES] = p->lib;
    put32(p->lhdr + WM_PROTO_LEVEL_HEADER_VERTEX_SLOTS, (uint32_t)m->vert_end);
    put32(p->lhdr + WM_PROTO_LEVEL_HEADER_TRIANGLES, (uint32_t)m->n_tri);
    put64(p->lhdr + WM_PROTO_LEVEL_HEADER_CYCLES, work - p->work_mark);
    p->work_mark = work;
    for (int i = 0; i < WM_PROTO_STAT_FIELDS; i++) put32(p->lhdr + stat_off[i], (uint32_t)stat_val[i]);
    put32(p->lhdr + WM_PROTO_LEVEL_HEADER_ST_E_MAX, st->e_max);
    put32(p->lhdr + WM_PROTO_LEVEL_HEADER_ST_REMOVALS, (uint32_t)st->removals);
    p->ltotal = WM_PROTO_LEVEL_HEADER_BYTES + 4u * (uint32_t)m->vert_end + 3u * p->lib * (uint32_t)m->n_tri;
    p->cur_k = 0x7FFFFFFF; /* the cursor starts again at the first live triangle */
    p->llast = (uint8_t)(last != 0);
    p->lresume = 0;
    p->lbuf = 0;
    { /* delta-coded when that is shorter (coded into sbuf once where it fits, else a pass of the coder
       * that only counts) */
        uint32_t coded = coded_into(p);
        if (coded == 0) coded = coded_total(p);
        p->lcoded = coded < p->ltotal;
        if (p->lcoded) p->ltotal = coded;
        p->lhdr[WM_PROTO_LEVEL_HEADER_CODING] = p->lcoded ? WM_PROTO_LEVEL_DELTA : WM_PROTO_LEVEL_RAW;
    }
    p->lpc = NULL;
    if (p->lbuf) {
        for (uint32_t i = 0; i < WM_PROTO_LEVEL_HEADER_BYTES; i++) p->sbuf[i] = p->lhdr[i];
        level_crcs(p);
    }

    link_begin(p);
    wm_proto_send_progress(p, WM_PROTO_STAGE_EMIT, st->level);
    link_end(p);
    send_level_from(p, 0, p->ltotal, 1);
    link_begin(p); /* from here on everything waits for, or answers, the host */
    send_level_end(p);
    for (;;) {
        if (!wm_proto_wait_ack(p, WM_PROTO_T_LEVEL_END, p->levels_sent, &have, send_level_end)) break;
        if (have >= p->ltotal && !p->lresume) break;
        p->lresume = 0;
        if (have > best) {
            best = have; /* progress: the retry budget starts again */
            tries = 0;
        } else if (++tries > WM_PROTO_ACK_RETRIES) {
            p->abort = ABORT_NO_ACK;
            break;
        }
        send_level_from(p, have, p->lwant && p->lwant < p->ltotal - have ? have + p->lwant : p->ltotal, 0);
        send_level_end(p);
    }
    link_end(p);
    if (p->abort) return abort_code(p);
    p->levels_sent++;
    p->e_max = st->e_max;
    p->triangles = (uint32_t)m->n_tri;
    p->vertices = (uint32_t)m->n_vert;
    /* after the last level the job only returns: no stage's clock runs, so the levels' cycles add up
     * to the filter, template and refine stages' exactly */
    stage_enter(p, last ? -1 : prev);
    return WM_PROTO_E_NONE;
}
