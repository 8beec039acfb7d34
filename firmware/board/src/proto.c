/*
 * wavemesh wire protocol, device side (proto.h; docs/protocol.md has every byte table).
 *
 * Frame, both ways (SLIP-delimited; 0xC0 and 0xDB inside escaped as 0xDB 0xDC and 0xDB 0xDD):
 *
 *   byte  0      type   WM_PROTO_T_*
 *   byte  1      seq    the host's request number; replies carry it back
 *   bytes 2..3   len    payload bytes, 0..WM_PROTO_MAX_PAYLOAD
 *   bytes 4..    payload
 *   last 4       CRC-32 (zlib's) of bytes 0 .. 3+len
 *
 * A run of bytes between two 0xC0 that is not such a frame (short, long, bad escape, wrong length
 * field, wrong CRC) is dropped without an answer; so is a frame whose next byte does not come within
 * WM_PROTO_BYTE_TIMEOUT_MS.  The host finds out by its own timeout and sends again.  Everything
 * else a valid frame can get wrong (type, length, state, value) gets an ERROR frame with its code.
 *
 * States (host requests in brackets):
 *
 *   IDLE --[CONFIG ok]--> RECEIVING --[DATA .. last sample]--> READY --[RUN, CRC ok]--> RUNNING
 *     ^                       |  silence > SESSION_TIMEOUT: ERROR TIMEOUT                  |
 *     +-----------------------+------------------- [HELLO], [ABORT] ----------------------+
 *     +---------------- job done: DONE (repeated until ACK, at most ACK_RETRIES times) ---+
 *
 * During RUNNING the job has the CPU; the engine reads frames only inside wm_proto_emit_level and
 * while it waits for DONE's ACK: ACK, HELLO (ends the job), ABORT (ends the job), STATUS, and
 * duplicates of the RUN request are handled there, anything else gets BAD_STATE.
 */
#include "proto.h"

/* Both devices (rv32, x86-64) are little-endian, the wire's order: words and halfwords go straight
 * between it and memory.  Elsewhere byte by byte. */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
#define WM_LITTLE_ENDIAN 1
#else
#define WM_LITTLE_ENDIAN 0
#endif

/* DATA's samples start at a word, MESH's stream bytes at an even offset (read and written as pairs of
 * halfwords and as halfwords) */
typedef char proto_halfword_payloads[(WM_PROTO_HEADER_BYTES + WM_PROTO_DATA_BYTES) % 4 == 0 &&
                                             WM_PROTO_MESH_BYTES % 2 == 0 &&
                                             WM_PROTO_LEVEL_HEADER_BYTES % 2 == 0 &&
                                             WM_PROTO_FREE_VERTEX == WM_FREE
                                         ? 1
                                         : -1];

#define CACHED_MAX 16u /* largest reply kept for duplicate requests (OK: 4, ERROR: 8) */
#define SERVE_POLL_MS 100u /* how often the idle loop looks at the session clock */

/* ---------------------------------------------------------------------------------------------- */
/* Little-endian fields */

static uint16_t get16(const uint8_t *b) { return (uint16_t)(b[0] | (uint16_t)b[1] << 8); }

static uint32_t get32(const uint8_t *b)
{
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

static uint64_t get64(const uint8_t *b) { return (uint64_t)get32(b) | (uint64_t)get32(b + 4) << 32; }

static void put16(uint8_t *b, uint32_t v)
{
    b[0] = (uint8_t)v;
    b[1] = (uint8_t)(v >> 8);
}

static void put32(uint8_t *b, uint32_t v)
{
    put16(b, v);
    put16(b + 2, v >> 16);
}

static void put64(uint8_t *b, uint64_t v)
{
    put32(b, (uint32_t)v);
    put32(b + 4, (uint32_t)(v >> 32));
}

static void zero(uint8_t *b, size_t n)
{
    for (size_t i = 0; i < n; i++) b[i] = 0;
}

/* ---------------------------------------------------------------------------------------------- */
/* CRC-32 (reflected, 0xEDB88320), a byte at a time from a 1 KB table in the firmware RAM: the RUN
 * check reads every uploaded sample (2 MB at 1024 x 1024), and four bits at a time (a 64-byte table)
 * took twice the lookups and shifts per byte; every received byte goes through it too */

static const uint32_t crc_table[256] = {
    0x00000000u, 0x77073096u, 0xEE0E612Cu, 0x990951BAu, 0x076DC419u, 0x706AF48Fu, 0xE963A535u, 0x9E6495A3u,
    0x0EDB8832u, 0x79DCB8A4u, 0xE0D5E91Eu, 0x97D2D988u, 0x09B64C2Bu, 0x7EB17CBDu, 0xE7B82D07u, 0x90BF1D91u,
    0x1DB71064u, 0x6AB020F2u, 0xF3B97148u, 0x84BE41DEu, 0x1ADAD47Du, 0x6DDDE4EBu, 0xF4D4B551u, 0x83D385C7u,
    0x136C9856u, 0x646BA8C0u, 0xFD62F97Au, 0x8A65C9ECu, 0x14015C4Fu, 0x63066CD9u, 0xFA0F3D63u, 0x8D080DF5u,
    0x3B6E20C8u, 0x4C69105Eu, 0xD56041E4u, 0xA2677172u, 0x3C03E4D1u, 0x4B04D447u, 0xD20D85FDu, 0xA50AB56Bu,
    0x35B5A8FAu, 0x42B2986Cu, 0xDBBBC9D6u, 0xACBCF940u, 0x32D86CE3u, 0x45DF5C75u, 0xDCD60DCFu, 0xABD13D59u,
    0x26D930ACu, 0x51DE003Au, 0xC8D75180u, 0xBFD06116u, 0x21B4F4B5u, 0x56B3C423u, 0xCFBA9599u, 0xB8BDA50Fu,
    0x2802B89Eu, 0x5F058808u, 0xC60CD9B2u, 0xB10BE924u, 0x2F6F7C87u, 0x58684C11u, 0xC1611DABu, 0xB6662D3Du,
    0x76DC4190u, 0x01DB7106u, 0x98D220BCu, 0xEFD5102Au, 0x71B18589u, 0x06B6B51Fu, 0x9FBFE4A5u, 0xE8B8D433u,
    0x7807C9A2u, 0x0F00F934u, 0x9609A88Eu, 0xE10E9818u, 0x7F6A0DBBu, 0x086D3D2Du, 0x91646C97u, 0xE6635C01u,
    0x6B6B51F4u, 0x1C6C6162u, 0x856530D8u, 0xF262004Eu, 0x6C0695EDu, 0x1B01A57Bu, 0x8208F4C1u, 0xF50FC457u,
    0x65B0D9C6u, 0x12B7E950u, 0x8BBEB8EAu, 0xFCB9887Cu, 0x62DD1DDFu, 0x15DA2D49u, 0x8CD37CF3u, 0xFBD44C65u,
    0x4DB26158u, 0x3AB551CEu, 0xA3BC0074u, 0xD4BB30E2u, 0x4ADFA541u, 0x3DD895D7u, 0xA4D1C46Du, 0xD3D6F4FBu,
    0x4369E96Au, 0x346ED9FCu, 0xAD678846u, 0xDA60B8D0u, 0x44042D73u, 0x33031DE5u, 0xAA0A4C5Fu, 0xDD0D7CC9u,
    0x5005713Cu, 0x270241AAu, 0xBE0B1010u, 0xC90C2086u, 0x5768B525u, 0x206F85B3u, 0xB966D409u, 0xCE61E49Fu,
    0x5EDEF90Eu, 0x29D9C998u, 0xB0D09822u, 0xC7D7A8B4u, 0x59B33D17u, 0x2EB40D81u, 0xB7BD5C3Bu, 0xC0BA6CADu,
    0xEDB88320u, 0x9ABFB3B6u, 0x03B6E20Cu, 0x74B1D29Au, 0xEAD54739u, 0x9DD277AFu, 0x04DB2615u, 0x73DC1683u,
    0xE3630B12u, 0x94643B84u, 0x0D6D6A3Eu, 0x7A6A5AA8u, 0xE40ECF0Bu, 0x9309FF9Du, 0x0A00AE27u, 0x7D079EB1u,
    0xF00F9344u, 0x8708A3D2u, 0x1E01F268u, 0x6906C2FEu, 0xF762575Du, 0x806567CBu, 0x196C3671u, 0x6E6B06E7u,
    0xFED41B76u, 0x89D32BE0u, 0x10DA7A5Au, 0x67DD4ACCu, 0xF9B9DF6Fu, 0x8EBEEFF9u, 0x17B7BE43u, 0x60B08ED5u,
    0xD6D6A3E8u, 0xA1D1937Eu, 0x38D8C2C4u, 0x4FDFF252u, 0xD1BB67F1u, 0xA6BC5767u, 0x3FB506DDu, 0x48B2364Bu,
    0xD80D2BDAu, 0xAF0A1B4Cu, 0x36034AF6u, 0x41047A60u, 0xDF60EFC3u, 0xA867DF55u, 0x316E8EEFu, 0x4669BE79u,
    0xCB61B38Cu, 0xBC66831Au, 0x256FD2A0u, 0x5268E236u, 0xCC0C7795u, 0xBB0B4703u, 0x220216B9u, 0x5505262Fu,
    0xC5BA3BBEu, 0xB2BD0B28u, 0x2BB45A92u, 0x5CB36A04u, 0xC2D7FFA7u, 0xB5D0CF31u, 0x2CD99E8Bu, 0x5BDEAE1Du,
    0x9B64C2B0u, 0xEC63F226u, 0x756AA39Cu, 0x026D930Au, 0x9C0906A9u, 0xEB0E363Fu, 0x72076785u, 0x05005713u,
    0x95BF4A82u, 0xE2B87A14u, 0x7BB12BAEu, 0x0CB61B38u, 0x92D28E9Bu, 0xE5D5BE0Du, 0x7CDCEFB7u, 0x0BDBDF21u,
    0x86D3D2D4u, 0xF1D4E242u, 0x68DDB3F8u, 0x1FDA836Eu, 0x81BE16CDu, 0xF6B9265Bu, 0x6FB077E1u, 0x18B74777u,
    0x88085AE6u, 0xFF0F6A70u, 0x66063BCAu, 0x11010B5Cu, 0x8F659EFFu, 0xF862AE69u, 0x616BFFD3u, 0x166CCF45u,
    0xA00AE278u, 0xD70DD2EEu, 0x4E048354u, 0x3903B3C2u, 0xA7672661u, 0xD06016F7u, 0x4969474Du, 0x3E6E77DBu,
    0xAED16A4Au, 0xD9D65ADCu, 0x40DF0B66u, 0x37D83BF0u, 0xA9BCAE53u, 0xDEBB9EC5u, 0x47B2CF7Fu, 0x30B5FFE9u,
    0xBDBDF21Cu, 0xCABAC28Au, 0x53B39330u, 0x24B4A3A6u, 0xBAD03605u, 0xCDD70693u, 0x54DE5729u, 0x23D967BFu,
    0xB3667A2Eu, 0xC4614AB8u, 0x5D681B02u, 0x2A6F2B94u, 0xB40BBE37u, 0xC30C8EA1u, 0x5A05DF1Bu, 0x2D02EF8Du,
};

static inline uint32_t crc_update(uint32_t c, uint8_t byte) { return crc_table[(c ^ byte) & 0xFFu] ^ (c >> 8); }

/* Two bytes, a 16-bit word's little-endian bytes (the wire order of samples and mask words). */
static inline uint32_t crc_update16(uint32_t c, uint32_t v)
{
    c ^= v & 0xFFFFu;
    c = crc_table[c & 0xFFu] ^ (c >> 8);
    return crc_table[c & 0xFFu] ^ (c >> 8);
}

uint32_t wm_proto_crc32(uint32_t crc, const uint8_t *data, size_t n)
{
    uint32_t c = ~crc;
    for (size_t i = 0; i < n; i++) c = crc_update(c, data[i]);
    return ~c;
}

/* The engine's bulk CRC (every received frame, every level stream, RUN's check of the stored samples):
 * four bytes a step from an aligned word, "slicing by four" (3 KB more of tables, made by
 * wm_proto_init: crc_slice[k][i] is crc_table[i] followed by k + 1 zero bytes), some 27 cycles a byte
 * on the soft CPU against 48.  c is the register (inverted CRC). */
static uint32_t crc_slice[3][256];

static void crc_slice_init(void)
{
    for (int i = 0; i < 256; i++) {
        uint32_t c = crc_table[i];
        for (int k = 0; k < 3; k++) {
            c = crc_table[c & 0xFFu] ^ (c >> 8);
            crc_slice[k][i] = c;
        }
    }
}

static uint32_t crc_run(uint32_t c, const uint8_t *s, size_t n)
{
#if WM_LITTLE_ENDIAN
    for (; n && ((uintptr_t)s & 3u); n--) c = crc_update(c, *s++);
    for (; n >= 4; n -= 4, s += 4) {
        uint32_t w;
        __builtin_memcpy(&w, __builtin_assume_aligned(s, 4), 4); /* one load: the wire's order is the CPU's */
        c ^= w;
        c = crc_slice[2][c & 0xFFu] ^ crc_slice[1][c >> 8 & 0xFFu] ^ crc_slice[0][c >> 16 & 0xFFu] ^
            crc_table[c >> 24];
    }
#endif
    for (; n; n--) c = crc_update(c, *s++);
    return c;
}

/* CRC combination (as zlib's crc32_combine): the CRC-32 of A B is crc_mul(x^(8 |B|), crc(A)) ^ crc(B),
 * products of polynomials modulo the CRC's, bit 31 the constant term.  A frame's CRC then follows from
 * its payload's (computed once, for the level stream's CRC) at some 3 k cycles a frame. */
static uint32_t crc_mul(uint32_t a, uint32_t b)
{
    uint32_t r = 0;
    for (; a; a <<= 1) {
        if (a & 0x80000000u) r ^= b;
        b = b & 1u ? b >> 1 ^ 0xEDB88320u : b >> 1;
    }
    return r;
}

static uint32_t crc_combine(wm_proto *p, uint32_t crc_a, uint32_t crc_b, uint32_t nb)
{
    if (p->x8n_n != nb) { /* x^(8 nb): one chunk size a level, mostly */
        uint32_t r = 0x80000000u, sq = 0x00800000u; /* x^0, x^8 */
        for (uint32_t k = nb; k; k >>= 1) {
            if (k & 1u) r = crc_mul(sq, r);
            sq = crc_mul(sq, sq);
        }
        p->x8n_n = nb;
        p->x8n = r;
    }
    return crc_mul(p->x8n, crc_a) ^ crc_b;
}

/* ---------------------------------------------------------------------------------------------- */
/* Time */

static uint64_t now(const wm_proto *p) { return p->io.cycles(p->io.ctx); }

static uint64_t ms_to_cycles(const wm_proto *p, uint32_t ms) { return (uint64_t)ms * p->ms_cycles; }

/* ---------------------------------------------------------------------------------------------- */
/* Sending: SLIP-encode into a buffer, written out when it may not hold the next piece and before every
 * read */

static void out_flush(wm_proto *p)
{
    if (p->out_len) {
        p->io.write(p->io.ctx, p->out, p->out_len);
        p->out_len = 0;
    }
}

static void out_raw(wm_proto *p, uint8_t b)
{
    if (p->out_len == sizeof p->out) out_flush(p);
    p->out[p->out_len++] = b;
}

/* n bytes SLIP-escaped (each takes at most two); a long run straight through the transport's
 * write_escaped when it has one (no copy through the buffer) */
static void out_slip(wm_proto *p, const uint8_t *s, uint32_t n)
{
    if (p->io.write_escaped && n >= 64) {
        out_flush(p);
        p->io.write_escaped(p->io.ctx, s, n);
        return;
    }
    while (n) {
        uint32_t k;
        uint8_t *d;
        const uint8_t *e;
        if (sizeof p->out - p->out_len < 64) out_flush(p);
        k = (uint32_t)(sizeof p->out - p->out_len) / 2;
        if (k > n) k = n;
        n -= k;
        d = p->out + p->out_len;
        for (e = s + k; s < e; s++) {
            uint8_t b = *s;
            if (b == WM_PROTO_SLIP_END) {
                *d++ = WM_PROTO_SLIP_ESC;
                *d++ = WM_PROTO_SLIP_ESC_END;
            } else if (b == WM_PROTO_SLIP_ESC) {
                *d++ = WM_PROTO_SLIP_ESC;
                *d++ = WM_PROTO_SLIP_ESC_ESC;
            } else {
                *d++ = b;
            }
        }
        p->out_len = (uint32_t)(d - p->out);
    }
}

/* One frame: header, payload (two pieces, either may be empty), CRC (of the header and payload). */
static void send_encoded(wm_proto *p, const uint8_t head[WM_PROTO_HEADER_BYTES], const uint8_t *a, uint32_t na,
                         const uint8_t *b, uint32_t nb, uint32_t crc)
{
    uint8_t tail[WM_PROTO_CRC_BYTES];
    put32(tail, crc);
    out_raw(p, WM_PROTO_SLIP_END);
    out_slip(p, head, WM_PROTO_HEADER_BYTES);
    out_slip(p, a, na);
    out_slip(p, b, nb);
    out_slip(p, tail, sizeof tail);
    out_raw(p, WM_PROTO_SLIP_END);
}

static void frame_head(uint8_t head[WM_PROTO_HEADER_BYTES], uint8_t type, uint8_t seq, uint32_t n)
{
    head[0] = type;
    head[1] = seq;
    put16(head + 2, n);
}

static void send_frame2(wm_proto *p, uint8_t type, uint8_t seq, const uint8_t *a, uint32_t na, const uint8_t *b,
                        uint32_t nb)
{
    uint8_t head[WM_PROTO_HEADER_BYTES];
    frame_head(head, type, seq, na + nb);
    send_encoded(p, head, a, na, b, nb, ~crc_run(crc_run(crc_run(~0u, head, sizeof head), a, na), b, nb));
}

static void send_frame(wm_proto *p, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n)
{
    send_frame2(p, type, seq, payload, n, 0, 0);
}

/* A frame of the device's own (not a reply): the device's sequence number. */
static void send_own(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n)
{
    send_frame(p, type, p->seq++, payload, n);
}

/* A reply to the frame just received; kept for a duplicate of it when it answers CONFIG/RUN/ABORT. */
static void reply(wm_proto *p, uint8_t type, const uint8_t *payload, uint32_t n)
{
    send_frame(p, type, p->f_seq, payload, n);
    if ((p->f_type == WM_PROTO_T_CONFIG || p->f_type == WM_PROTO_T_RUN || p->f_type == WM_PROTO_T_ABORT) &&
        n <= CACHED_MAX) {
        for (uint32_t i = 0; i < n; i++) p->cache[i] = payload[i];
        p->cache_type = type;
        p->cache_len = (uint8_t)n;
        p->cache_req = p->f_type;
        p->cache_seq = p->f_seq;
        p->cache_valid = 1;
    }
}

/* A duplicate of the last CONFIG, RUN or ABORT (the host sent it again: our reply was lost). */
static int duplicate(wm_proto *p)
{
    if (!p->cache_valid || p->cache_req != p->f_type || p->cache_seq != p->f_seq) return 0;
    send_frame(p, p->cache_type, p->f_seq, p->cache, p->cache_len);
    return 1;
}

static void reply_ok(wm_proto *p)
{
    uint8_t b[WM_PROTO_OK_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_OK_REQUEST] = p->f_type;
    reply(p, WM_PROTO_T_OK, b, sizeof b);
}

static void error_payload(wm_proto *p, uint8_t b[WM_PROTO_ERROR_BYTES], uint8_t code, uint8_t req, uint32_t detail)
{
    zero(b, WM_PROTO_ERROR_BYTES);
    b[WM_PROTO_ERROR_CODE] = code;
    b[WM_PROTO_ERROR_REQUEST] = req;
    b[WM_PROTO_ERROR_STATE] = p->state;
    put32(b + WM_PROTO_ERROR_DETAIL, detail);
    p->last_error = code;
    p->last_detail = detail;
}

/* ERROR in answer to the frame just received. */
static void reply_error(wm_proto *p, uint8_t code, uint32_t detail)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    error_payload(p, b, code, p->f_type, detail);
    reply(p, WM_PROTO_T_ERROR, b, sizeof b);
}

/* ERROR of the device's own (the session was dropped). */
static void send_error(wm_proto *p, uint8_t code, uint32_t detail)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    error_payload(p, b, code, 0, detail);
    send_own(p, WM_PROTO_T_ERROR, b, sizeof b);
}

/* ---------------------------------------------------------------------------------------------- */
/* Receiving */

static void rx_reset(wm_proto *p)
{
    p->rx_len = 0;
    p->rx_esc = 0;
    p->rx_bad = 0;
}

/* The bytes between two delimiters: a frame with the right length field and CRC?  (The CRC in one
 * go at the end: on a UART, the RX FIFO's 64 bytes are some 140 k cycles at 115200 baud, a 1 KB frame's
 * CRC some 30 k.) */
static int rx_check(wm_proto *p)
{
    uint32_t n, body = p->rx_len - WM_PROTO_CRC_BYTES;
    if (p->rx_len < WM_PROTO_HEADER_BYTES + WM_PROTO_CRC_BYTES) return 0;
    n = get16(p->rx.b + 2);
    if (p->rx_len != WM_PROTO_HEADER_BYTES + n + WM_PROTO_CRC_BYTES) return 0;
    if (~crc_run(~0u, p->rx.b, body) != get32(p->rx.b + body)) return 0;
    p->f_type = p->rx.b[0];
    p->f_seq = p->rx.b[1];
    p->f_len = (uint16_t)n;
    p->f_pay = p->rx.b + WM_PROTO_HEADER_BYTES;
    return 1;
}

#define RX_BURST 256u

/* One received byte: 1 when it completes a valid frame (in f_type, f_seq, f_len, f_pay). */
static int rx_byte(wm_proto *p, int c)
{
    if (c == WM_PROTO_SLIP_END) {
        /* the end of a frame (or a delimiter before one) */
        int ok = !p->rx_bad && !p->rx_esc && p->rx_len && rx_check(p);
        if (!ok && (p->rx_len || p->rx_bad || p->rx_esc)) p->bad_frames++;
        rx_reset(p);
        if (ok && p->f_len > p->caps.max_payload) {
            /* a whole frame, but longer than this device said it takes (HELLO's max_payload) */
            reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        return ok;
    }
    if (p->rx_bad) return 0; /* discarding until the next delimiter */
    if (p->rx_esc) {
        p->rx_esc = 0;
        if (c == WM_PROTO_SLIP_ESC_END) {
            c = WM_PROTO_SLIP_END;
        } else if (c == WM_PROTO_SLIP_ESC_ESC) {
            c = WM_PROTO_SLIP_ESC;
        } else {
            p->rx_bad = 1; /* an escape of nothing */
            return 0;
        }
    } else if (c == WM_PROTO_SLIP_ESC) {
        p->rx_esc = 1;
        return 0;
    }
    if (p->rx_len >= sizeof p->rx.b) {
        p->rx_bad = 1; /* longer than any frame */
        return 0;
    }
    p->rx.b[p->rx_len++] = (uint8_t)c;
    return 0;
}

/* Bytes already received, at most max, into dst, up to and including the first delimiter or escape
 * (wm_proto_io.read's contract): their number, or WM_PROTO_RX_CLOSED. */
static int rx_take(wm_proto *p, uint8_t *dst, uint32_t max)
{
    uint32_t n = 0;
    if (p->io.read) return p->io.read(p->io.ctx, dst, max);
    while (n < max) {
        int c = p->io.getc(p->io.ctx, 0);
        if (c < 0) return c == WM_PROTO_RX_CLOSED && n == 0 ? WM_PROTO_RX_CLOSED : (int)n;
        dst[n++] = (uint8_t)c;
        if (c == WM_PROTO_SLIP_END || c == WM_PROTO_SLIP_ESC) break;
    }
    return (int)n;
}

/* After the byte c: the bytes already waiting, at most RX_BURST, each in its place in the frame buffer
 * (all but the last of a read are plain bytes: they stay where they landed; the last goes through
 * rx_byte).  1 when a frame is complete, -1 when the link closed, 0 when no byte waits (or the burst's
 * bound is reached: it keeps a flood without delimiters from holding off the caller's timeouts). */
static int rx_burst(wm_proto *p, int c)
{
    uint32_t k = 1;
    if (rx_byte(p, c)) return 1;
    while (k < RX_BURST) {
        uint32_t room = (uint32_t)sizeof p->rx.b - p->rx_len;
        int n;
        if (p->rx_esc || p->rx_bad || room == 0) { /* a byte to translate, or to drop */
            c = p->io.getc(p->io.ctx, 0);
            if (c < 0) return c == WM_PROTO_RX_CLOSED ? -1 : 0;
            k++;
            if (rx_byte(p, c)) return 1;
            continue;
        }
        if (room > RX_BURST - k) room = RX_BURST - k;
        n = rx_take(p, p->rx.b + p->rx_len, room);
        if (n <= 0) return n == WM_PROTO_RX_CLOSED ? -1 : 0;
        k += (uint32_t)n;
        p->rx_len += (uint32_t)n - 1u;
        if (rx_byte(p, p->rx.b[p->rx_len])) return 1;
    }
    return 0;
}

/* Waits up to wait_ms for a valid frame: 1 (in f_type, f_seq, f_len, f_pay until the next call),
 * 0 when the time is up, -1 when the link closed.  Damaged frames are dropped and counted. */
static int rx_frame(wm_proto *p, uint32_t wait_ms)
{
    uint64_t t0 = now(p), limit = ms_to_cycles(p, wait_ms), bt = ms_to_cycles(p, WM_PROTO_BYTE_TIMEOUT_MS);
    for (;;) {
        uint64_t t = now(p), spent = t - t0;
        int in_frame = p->rx_len || p->rx_esc || p->rx_bad;
        uint32_t to;
        int c;
        if (in_frame && t - p->rx_last >= bt) { /* the rest of this frame is not coming */
            p->bad_frames++;
            rx_reset(p);
            in_frame = 0;
        }
        if (spent >= limit) return 0;
        /* milliseconds left, rounded up (a 32-bit division where it fits: no libgcc call per byte) */
        to = limit - spent > 0xFFFFFFFFu ? wait_ms : (uint32_t)(limit - spent) / p->ms_cycles + 1u;
        if (in_frame && to > WM_PROTO_BYTE_TIMEOUT_MS) to = WM_PROTO_BYTE_TIMEOUT_MS;
        out_flush(p);
        c = p->io.getc(p->io.ctx, to);
        if (c == WM_PROTO_RX_CLOSED) return -1;
        if (c < 0) continue;
        /* a burst of what is already waiting, without the timeouts' bookkeeping (the clock reads and
         * the division above cost some 400 cycles a byte on the soft CPU) */
        c = rx_burst(p, c);
        p->rx_last = now(p);
        if (c != 0) return c;
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* Cycle accounting and progress
 *
 * One clock runs at a time: the current stage's, or, while link_depth > 0, the link's.  Link I/O is
 * everything whose duration or work depends on something other than the job: every frame the job
 * sends (PROGRESS carries a timestamp, every frame the device's sequence number, the CRC and the
 * SLIP escapes follow from both), every write to the transport (a UART's FIFO may be full), every
 * wait for the host and every resend it asks for.  What is left to the stages (filter, template,
 * refine, and emit: building each level stream once) depends only on the job, so a job gives the same
 * stage counts on every run, over any link, at any host speed. */

/* The cycles since the last mark go to the clock that ran: the link's or the current stage's. */
static void charge(wm_proto *p)
{
    uint64_t t = now(p);
    if (p->link_depth) p->link += t - p->t_mark;
    else if (p->stage >= 0 && p->stage < WM_PROTO_STAGE_COUNT) p->cycles[p->stage] += t - p->t_mark;
    p->t_mark = t;
}

/* Tells the transport which clock runs from now on (io.mark, for traces). */
static void mark(wm_proto *p)
{
    if (p->io.mark) {
        uint32_t c = p->stage >= 0 && p->stage < WM_PROTO_STAGE_COUNT ? (uint32_t)p->stage : WM_PROTO_CLOCK_NONE;
        p->io.mark(p->io.ctx, p->link_depth ? c | WM_PROTO_CLOCK_LINK : c);
    }
}

/* Another stage begins (not inside link I/O). */
static void stage_enter(wm_proto *p, int stage)
{
    charge(p);
    p->stage = stage;
    mark(p);
}

/* Link I/O begins: the stage's clock stops, the link's runs (nested calls count once). */
static void link_begin(wm_proto *p)
{
    if (p->link_depth == 0) charge(p); /* to the stage */
    if (++p->link_depth == 1) mark(p);
}

/* Link I/O ends: the stage's clock runs again. */
static void link_end(wm_proto *p)
{
    if (p->link_depth == 1) charge(p); /* to the link */
    if (--p->link_depth == 0) mark(p);
}

static void send_progress(wm_proto *p, int stage, int level)
{
    uint8_t b[WM_PROTO_PROGRESS_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_PROGRESS_STAGE] = (uint8_t)stage;
    b[WM_PROTO_PROGRESS_LEVEL] = (uint8_t)level;
    b[WM_PROTO_PROGRESS_LEVELS] = (uint8_t)p->job.levels;
    put64(b + WM_PROTO_PROGRESS_CYCLES, now(p) - p->run_t0);
    send_own(p, WM_PROTO_T_PROGRESS, b, sizeof b);
    out_flush(p);
}

void wm_proto_stage(wm_proto *p, int stage, int level)
{
    if (stage == WM_PROTO_STAGE_REFINE) p->level = (uint8_t)level;
    stage_enter(p, stage);
    link_begin(p);
    send_progress(p, stage, level);
    link_end(p);
}

/* ---------------------------------------------------------------------------------------------- */
/* Requests outside a job */

static void status_reply(wm_proto *p)
{
    uint8_t b[WM_PROTO_STATUS_REPLY_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_STATUS_REPLY_STATE] = p->state;
    b[WM_PROTO_STATUS_REPLY_LAST_ERROR] = p->last_error;
    b[WM_PROTO_STATUS_REPLY_LEVEL] = p->level;
    put32(b + WM_PROTO_STATUS_REPLY_SAMPLES, p->next);
    put32(b + WM_PROTO_STATUS_REPLY_EXPECTED, p->total);
    put32(b + WM_PROTO_STATUS_REPLY_LAST_DETAIL, p->last_detail);
    reply(p, WM_PROTO_T_STATUS_REPLY, b, sizeof b);
}

static void session_end(wm_proto *p)
{
    p->state = WM_PROTO_STATE_IDLE;
    p->total = p->next = 0;
}

static void do_hello(wm_proto *p)
{
    uint8_t b[WM_PROTO_HELLO_REPLY_BYTES];
    const wm_proto_caps *c = &p->caps;
    if (p->f_len != WM_PROTO_HELLO_BYTES) { /* not a HELLO: nothing ends */
        reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    session_end(p); /* a HELLO starts afresh, whatever was going on */
    p->cache_valid = 0;
    if ((get16(p->f_pay + WM_PROTO_HELLO_VERSION) >> 8) != WM_PROTO_VERSION_MAJOR) {
        reply_error(p, WM_PROTO_E_VERSION, WM_PROTO_VERSION);
        return;
    }
    zero(b, sizeof b);
    put16(b + WM_PROTO_HELLO_REPLY_VERSION, WM_PROTO_VERSION);
    b[WM_PROTO_HELLO_REPLY_FW_MAJOR] = c->fw_major;
    b[WM_PROTO_HELLO_REPLY_FW_MINOR] = c->fw_minor;
    for (int i = 0; i < 8; i++) b[WM_PROTO_HELLO_REPLY_NAME + i] = (uint8_t)c->name[i];
    put16(b + WM_PROTO_HELLO_REPLY_MAX_WIDTH, c->max_width);
    put16(b + WM_PROTO_HELLO_REPLY_MAX_HEIGHT, c->max_height);
    put32(b + WM_PROTO_HELLO_REPLY_MAX_SAMPLES, c->max_samples);
    put32(b + WM_PROTO_HELLO_REPLY_TRI_CAPACITY, c->tri_capacity);
    b[WM_PROTO_HELLO_REPLY_MAX_LEVELS] = c->max_levels;
    b[WM_PROTO_HELLO_REPLY_WINDOW] = p->div != c->div && c->switched_window ? c->switched_window : c->window;
    put16(b + WM_PROTO_HELLO_REPLY_MAX_PAYLOAD, c->max_payload);
    put32(b + WM_PROTO_HELLO_REPLY_CLK_HZ, c->clk_hz);
    /* the start rate as the transport states it; after a BAUD clk_hz / div rounded (protocol.divisor_baud) */
    put32(b + WM_PROTO_HELLO_REPLY_BAUD,
          p->div && p->div != c->div ? (c->clk_hz + p->div / 2u) / p->div : c->baud);
    put32(b + WM_PROTO_HELLO_REPLY_FEATURES,
          p->div && p->div < c->rice_min_div ? c->features & ~(uint32_t)WM_PROTO_FEATURE_RICE : c->features);
    put16(b + WM_PROTO_HELLO_REPLY_BYTE_TIMEOUT_MS, WM_PROTO_BYTE_TIMEOUT_MS);
    put16(b + WM_PROTO_HELLO_REPLY_ACK_TIMEOUT_MS, WM_PROTO_ACK_TIMEOUT_MS);
    put32(b + WM_PROTO_HELLO_REPLY_SESSION_TIMEOUT_MS, WM_PROTO_SESSION_TIMEOUT_MS);
    put16(b + WM_PROTO_HELLO_REPLY_ACK_RETRIES, WM_PROTO_ACK_RETRIES);
    put32(b + WM_PROTO_HELLO_REPLY_IDLE_TIMEOUT_MS, c->idle_timeout_ms);
    put32(b + WM_PROTO_HELLO_REPLY_WRITE_TIMEOUT_MS, c->write_timeout_ms);
    put32(b + WM_PROTO_HELLO_REPLY_DIV_MIN, c->div_min);
    put32(b + WM_PROTO_HELLO_REPLY_DIV_MAX, c->div_max);
    reply(p, WM_PROTO_T_HELLO_REPLY, b, sizeof b);
}

/* BAUD, outside a session: OK at the old rate, then the new divisor.  Until a valid frame comes at the
 * new rate (the host's HELLO) the old divisor is kept in probe_div; wm_proto_serve goes back to it after
 * WM_PROTO_BAUD_PROBE_MS without one, so a switch the host cannot follow never strands the device. */
static void do_baud(wm_proto *p)
{
    uint32_t div;
    if (p->f_len != WM_PROTO_BAUD_BYTES) {
        reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (p->state != WM_PROTO_STATE_IDLE) {
        reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    div = get32(p->f_pay + WM_PROTO_BAUD_DIVISOR);
    if (!p->io.set_divisor || p->caps.div_max == 0 || div < p->caps.div_min || div > p->caps.div_max) {
        reply_error(p, WM_PROTO_E_BAD_BAUD, div);
        return;
    }
    reply_ok(p);
    out_flush(p);
    if (!p->probing)
        p->probe_div = p->div; /* a second BAUD before the first was proved: back to the first's old */
    p->io.set_divisor(p->io.ctx, div);
    p->div = div;
    p->probing = 1;
    p->probe_t0 = now(p);
    rx_reset(p);
}

/* CONFIG's field ranges (host/wavemesh/device/protocol.py, CONFIG: the ones the host checks before sending) */
typedef struct config_range {
    uint8_t off, bytes;
    uint64_t lo, hi;
} config_range;

static const config_range config_ranges[WM_PROTO_CONFIG_RANGES] = WM_PROTO_CONFIG_RANGE_TABLE;

/* CONFIG's fields, checked one by one: 0, or the error code with *detail. */
static int parse_config(wm_proto *p, wm_proto_job *j, uint32_t *detail)
{
    const uint8_t *c = p->f_pay;
    const wm_proto_caps *cap = &p->caps;
    uint32_t w = get16(c + WM_PROTO_CONFIG_WIDTH), h = get16(c + WM_PROTO_CONFIG_HEIGHT);
    uint32_t levels = c[WM_PROTO_CONFIG_LEVELS], metric = c[WM_PROTO_CONFIG_METRIC];
    uint32_t nb = c[WM_PROTO_CONFIG_NEIGHBOURHOOD], k = c[WM_PROTO_CONFIG_ITERATIONS];
    uint32_t flags = get32(c + WM_PROTO_CONFIG_FLAGS), tau = get32(c + WM_PROTO_CONFIG_TAU);
    uint32_t budget = get32(c + WM_PROTO_CONFIG_MAX_TRIANGLES), cap_tri = get32(c + WM_PROTO_CONFIG_CAPACITY);
    uint32_t scale_m = get32(c + WM_PROTO_CONFIG_SCALE_M), scale_e = get32(c + WM_PROTO_CONFIG_SCALE_E);
    uint32_t delta_p = get32(c + WM_PROTO_CONFIG_DELTA_P), alpha = get32(c + WM_PROTO_CONFIG_ALPHA);
    uint32_t delta_c = get32(c + WM_PROTO_CONFIG_DELTA_C);
    uint32_t slope_x_m = get32(c + WM_PROTO_CONFIG_SLOPE_X_M), slope_x_e = get32(c + WM_PROTO_CONFIG_SLOPE_X_E);
    uint32_t slope_y_m = get32(c + WM_PROTO_CONFIG_SLOPE_Y_M), slope_y_e = get32(c + WM_PROTO_CONFIG_SLOPE_Y_E);
#define BAD(field)                         \
    do {                                   \
        *detail = WM_PROTO_CONFIG_##field; \
        return WM_PROTO_E_BAD_VALUE;       \
    } while (0)
    /* every field within the protocol's range (the first one out of it is named), ... */
    for (int i = 0; i < WM_PROTO_CONFIG_RANGES; i++) {
        const config_range *r = &config_ranges[i];
        uint64_t v = r->bytes == 8   ? get64(c + r->off)
                     : r->bytes == 4 ? get32(c + r->off)
                     : r->bytes == 2 ? get16(c + r->off)
                                     : c[r->off];
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
    j->params.metric = (int32_t)metric;
    j->params.neighbourhood = (int32_t)nb;
    j->params.iterations = (int32_t)k;
    j->params.max_triangles = (int32_t)budget;
    j->params.zeta = get32(c + WM_PROTO_CONFIG_ZETA);
    j->params.scale_m = scale_m;
    j->params.scale_e = (int32_t)scale_e;
    j->params.delta_p = delta_p;
    j->params.alpha = alpha;
    j->params.delta_v = get32(c + WM_PROTO_CONFIG_DELTA_V);
    j->params.flags = (flags >> WM_PROTO_CONFIG_REFINER_SHIFT) & WM_FLAG_ALL; /* WM_FLAG_* */
    j->params.delta_d = get64(c + WM_PROTO_CONFIG_DELTA_D);
    j->delta_lambda = get32(c + WM_PROTO_CONFIG_DELTA_LAMBDA);
    j->delta_c = delta_c;
    j->params.delta_lambda = j->delta_lambda;
    j->params.delta_c = delta_c;
    j->params.slope_x_m = slope_x_m;
    j->params.slope_x_e = (int32_t)slope_x_e;
    j->params.slope_y_m = slope_y_m;
    j->params.slope_y_e = (int32_t)slope_y_e;
    j->heights = p->heights;
    j->mask = (flags & WM_PROTO_CONFIG_MASK) ? p->mask : NULL;
    if (wm_params_check(&j->params) != WM_OK) { /* cannot happen after the checks above */
        *detail = WM_PROTO_CONFIG_ZETA;
        return WM_PROTO_E_BAD_VALUE;
    }
    return 0;
}

static void do_config(wm_proto *p)
{
    uint32_t detail = 0;
    int code;
    if (duplicate(p)) return;
    if (p->f_len != WM_PROTO_CONFIG_BYTES) {
        reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    session_end(p); /* a new CONFIG replaces the session */
    code = parse_config(p, &p->job, &detail);
    if (code) {
        reply_error(p, (uint8_t)code, detail);
        return;
    }
    p->total = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (p->job.mask) p->total += (p->total + 15) / 16; /* the mask's words follow the samples */
    p->next = 0;
    p->nak_sent = 0;
    p->state = WM_PROTO_STATE_RECEIVING;
    for (int s = 0; s < WM_PROTO_STAGE_COUNT; s++) p->cycles[s] = 0;
    p->link = 0;
    p->link_depth = 0;
    p->stage = -1;
    stage_enter(p, WM_PROTO_STAGE_RECEIVE);
    reply_ok(p);
}

/* Word k of what DATA carries: sample k, or beyond the W H samples the mask's bytes in pairs. */
static void put_word(wm_proto *p, uint32_t k, uint16_t v)
{
    uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (k < wh) {
        p->heights[k] = v;
    } else {
        p->mask[2 * (k - wh)] = (uint8_t)v;
        p->mask[2 * (k - wh) + 1] = (uint8_t)(v >> 8);
    }
}

static uint16_t word_at(const wm_proto *p, uint32_t k)
{
    uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height;
    if (k < wh) return p->heights[k];
    return (uint16_t)(p->mask[2 * (k - wh)] | p->mask[2 * (k - wh) + 1] << 8);
}

/* CODING_RICE (docs/protocol.md, "Sample coding"; host/wavemesh/device/coding.py encodes): n samples from off,
 * each a prediction from the samples stored before it (the block's predictor: MED or the plane) plus a
 * zig-zag residual, Rice-coded in blocks of WM_PROTO_RICE_BLOCK with a k each, bits most significant first.  0, or -1 when the len bytes at s are
 * not such a stream (too short, or a byte or more left over). */
static int rice_decode(wm_proto *p, uint32_t off, uint32_t n, const uint8_t *s, uint32_t len)
{
    /* The bits left-aligned in acc (the next one is bit 31), nb of them valid; refilled a byte at a time
     * to at least 25 while bytes are left.  The left and above-left samples are carried in registers
     * (the height memory is the SDRAM): one load a sample, the one above. */
    const uint8_t *e = s + len;
    uint16_t *h = p->heights;
    uint32_t w = (uint32_t)p->job.width, x = off % w, i = off, end = off + n;
    uint32_t acc = 0, nb = 0, left = 0, ul = 0;
#define REFILL()                             \
    while (nb <= 24 && s < e) {              \
        acc |= (uint32_t)*s++ << (24u - nb); \
        nb += 8u;                            \
    }
    if (x) {
        left = h[i - 1];
        if (i > w) ul = h[i - w - 1];
    }
    while (i < end) {
        uint32_t pick, k, m = end - i < WM_PROTO_RICE_BLOCK ? end - i : WM_PROTO_RICE_BLOCK;
        REFILL();
        if (nb < WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS) return -1;
        pick = acc >> (32u - WM_PROTO_RICE_PRED_BITS);
        k = (acc << WM_PROTO_RICE_PRED_BITS) >> (32u - WM_PROTO_RICE_K_BITS);
        acc <<= WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS;
        nb -= WM_PROTO_RICE_PRED_BITS + WM_PROTO_RICE_K_BITS;
        for (; m; m--, i++) {
            uint32_t q = 0, z, pred;
            REFILL();
            while (q < WM_PROTO_RICE_ESCAPE && nb && (acc & 0x80000000u)) { /* the quotient's ones */
                acc <<= 1;
                nb--;
                q++;
            }
            if (q == WM_PROTO_RICE_ESCAPE) {
                REFILL();
                if (nb < 16u) return -1;
                z = acc >> 16;
                acc <<= 16;
                nb -= 16u;
            } else {
                if (nb == 0) return -1; /* no room for the quotient's zero */
                acc <<= 1;
                nb--;
                REFILL();
                if (nb < k) return -1;
                z = k ? (q << k) | (acc >> (32u - k)) : q;
                acc = k ? acc << k : acc;
                nb -= k;
            }
            if (i < w) {
                pred = x ? left : 0u;
            } else {
                uint32_t b = h[i - w];
                if (x == 0) {
                    pred = b;
                } else {
                    uint32_t hi = left > b ? left : b, lo = left > b ? b : left;
                    pred = pick == WM_PROTO_RICE_PRED_PLANE || (ul < hi && ul > lo) ? left + b - ul
                           : ul >= hi                                               ? lo
                                                                                    : hi;
                }
                ul = b;
            }
            left = (uint16_t)(pred + ((z >> 1) ^ (0u - (z & 1u))));
            h[i] = (uint16_t)left;
            if (++x == w) x = 0;
        }
    }
#undef REFILL
    return s == e && nb < 8u ? 0 : -1;
}

static void do_data(wm_proto *p)
{
    uint8_t b[WM_PROTO_DATA_ACK_BYTES];
    uint32_t off, n, i, coding, tail;
    const uint8_t *s;
    if (p->state != WM_PROTO_STATE_RECEIVING && p->state != WM_PROTO_STATE_READY) {
        reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    off = get32(p->f_pay + WM_PROTO_DATA_OFFSET);
    n = get16(p->f_pay + WM_PROTO_DATA_COUNT);
    coding = p->f_pay[WM_PROTO_DATA_CODING];
    tail = (uint32_t)p->f_len - WM_PROTO_DATA_BYTES;
    if (p->f_len < WM_PROTO_DATA_BYTES + 1 || n == 0 || (coding == WM_PROTO_CODING_RAW && tail != 2 * n) ||
        (coding != WM_PROTO_CODING_RAW && coding != WM_PROTO_CODING_RICE)) {
        reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (off > p->total || n > p->total - off ||
        (coding == WM_PROTO_CODING_RICE && off + n > (uint32_t)p->job.width * (uint32_t)p->job.height)) {
        reply_error(p, WM_PROTO_E_BAD_OFFSET, off);
        return;
    }
    zero(b, sizeof b);
    if (off <= p->next && coding == WM_PROTO_CODING_RICE) {
        /* every sample before off is stored: the predictions are the host's */
        if (rice_decode(p, off, n, p->f_pay + WM_PROTO_DATA_BYTES, tail)) {
            reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return;
        }
        if (off + n > p->next) {
            p->next = off + n;
            p->nak_sent = 0;
        }
    } else if (off <= p->next) {
        /* in order, or a repeat that may reach beyond what is stored */
        s = p->f_pay + WM_PROTO_DATA_BYTES;
#if WM_LITTLE_ENDIAN
        if (off + n <= (uint32_t)p->job.width * (uint32_t)p->job.height) {
            /* samples only, straight (the wire's byte order is the CPU's): two a step when the
             * destination is word-aligned (the source is: an even offset in a word-aligned buffer) */
            const uint16_t *h = p->rx.h + (WM_PROTO_HEADER_BYTES + WM_PROTO_DATA_BYTES) / 2;
            uint16_t *d = p->heights + off;
            i = 0;
            if (!((uintptr_t)d & 3u))
                for (; i + 2 <= n; i += 2)
                    __builtin_memcpy(__builtin_assume_aligned(d + i, 4), __builtin_assume_aligned(h + i, 4), 4);
            for (; i < n; i++) d[i] = h[i];
        } else
#endif
        {
            for (i = 0; i < n; i++) put_word(p, off + i, get16(s + 2 * i));
        }
        if (off + n > p->next) {
            p->next = off + n;
            p->nak_sent = 0;
        }
    } else if (!p->nak_sent) {
        /* a gap: a frame before this one was lost; ask once per gap for everything from next */
        p->nak_sent = 1;
        b[WM_PROTO_DATA_ACK_FLAGS] = WM_PROTO_ACK_NAK;
    }
    if (p->next == p->total) p->state = WM_PROTO_STATE_READY;
    put32(b + WM_PROTO_DATA_ACK_NEXT, p->next);
    reply(p, WM_PROTO_T_DATA_ACK, b, sizeof b);
}

static void run_job(wm_proto *p);

static void do_run(wm_proto *p)
{
    uint32_t crc = 0;
    if (duplicate(p)) return;
    if (p->f_len != WM_PROTO_RUN_BYTES) {
        reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        return;
    }
    if (p->state != WM_PROTO_STATE_READY) {
        reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return;
    }
    {
        /* the samples, then the mask's words, each as its two little-endian bytes */
        uint32_t wh = (uint32_t)p->job.width * (uint32_t)p->job.height, c = ~crc;
#if WM_LITTLE_ENDIAN
        c = crc_run(c, (const uint8_t *)p->heights, 2u * (wh < p->total ? wh : p->total));
#else
        for (uint32_t i = 0; i < wh && i < p->total; i++) c = crc_update16(c, p->heights[i]);
#endif
        for (uint32_t i = wh; i < p->total; i++) c = crc_update16(c, word_at(p, i));
        crc = ~c;
    }
    if (crc != get32(p->f_pay + WM_PROTO_RUN_CRC)) {
        session_end(p);
        reply_error(p, WM_PROTO_E_DATA_CRC, crc);
        return;
    }
    reply_ok(p);
    out_flush(p);
    run_job(p);
}

/* A frame outside a job. */
static void handle(wm_proto *p)
{
    switch (p->f_type) {
    case WM_PROTO_T_HELLO: do_hello(p); break;
    case WM_PROTO_T_STATUS:
        if (p->f_len != 0) reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        else status_reply(p);
        break;
    case WM_PROTO_T_ABORT:
        if (duplicate(p)) break;
        if (p->f_len != 0) {
            reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            break;
        }
        session_end(p);
        reply_ok(p);
        break;
    case WM_PROTO_T_CONFIG: do_config(p); break;
    case WM_PROTO_T_DATA: do_data(p); break;
    case WM_PROTO_T_RUN: do_run(p); break;
    case WM_PROTO_T_BAUD: do_baud(p); break;
    case WM_PROTO_T_ACK: break; /* a late answer to a job that is over */
    default:
        /* the device's own types (an echo on the line) are ignored; anything else is unknown */
        if (p->f_type < 0x80u) reply_error(p, WM_PROTO_E_BAD_TYPE, p->f_type);
        break;
    }
}

/* ---------------------------------------------------------------------------------------------- */
/* During the job */

#define ABORT_HOST 1u   /* ABORT or HELLO: already answered, no DONE */
#define ABORT_NO_ACK 2u /* the host stopped answering */
#define ABORT_CLOSED 3u /* the link closed */

/* A frame that arrived while the job waits: 1 when it is the ACK of (kind, index), with *have. */
static int job_frame(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have)
{
    switch (p->f_type) {
    case WM_PROTO_T_ACK:
        if (p->f_len != WM_PROTO_ACK_BYTES) {
            reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        if (p->f_pay[WM_PROTO_ACK_KIND] == kind && p->f_pay[WM_PROTO_ACK_INDEX] == index) {
            uint32_t c = get16(p->f_pay + WM_PROTO_ACK_CHUNK), most = p->caps.max_payload - WM_PROTO_MESH_BYTES;
            *have = get32(p->f_pay + WM_PROTO_ACK_HAVE);
            if (kind == WM_PROTO_T_LEVEL_END) {
                /* a host on a lossy line asks for smaller frames (and only the bytes it misses) */
                p->lwant = get32(p->f_pay + WM_PROTO_ACK_WANT);
                p->chunk = (uint16_t)(c == 0 || c > most ? most : c < WM_PROTO_MIN_CHUNK ? WM_PROTO_MIN_CHUNK : c);
            }
            return 1;
        }
        return 0; /* an ACK of something earlier */
    case WM_PROTO_T_HELLO:
        if (p->f_len == WM_PROTO_HELLO_BYTES) p->abort = ABORT_HOST; /* else BAD_LENGTH, the job goes on */
        do_hello(p);
        return 0;
    case WM_PROTO_T_ABORT:
        if (duplicate(p)) return 0;
        if (p->f_len != 0) {
            reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
            return 0;
        }
        p->abort = ABORT_HOST;
        session_end(p);
        reply_ok(p);
        return 0;
    case WM_PROTO_T_STATUS:
        if (p->f_len != 0) reply_error(p, WM_PROTO_E_BAD_LENGTH, p->f_len);
        else status_reply(p);
        return 0;
    case WM_PROTO_T_RUN:
    case WM_PROTO_T_CONFIG:
        if (duplicate(p)) return 0;
        reply_error(p, WM_PROTO_E_BAD_STATE, p->state);
        return 0;
    case WM_PROTO_T_DATA:
    case WM_PROTO_T_BAUD: reply_error(p, WM_PROTO_E_BAD_STATE, p->state); return 0;
    default:
        if (p->f_type < 0x80u) reply_error(p, WM_PROTO_E_BAD_TYPE, p->f_type);
        return 0;
    }
}

/* Waits for the ACK of (kind, index), sending `again` each time ACK_TIMEOUT passes without one.
 * Returns 1 with *have, or 0 when the job must stop (p->abort says why). */
static int wait_ack(wm_proto *p, uint8_t kind, uint8_t index, uint32_t *have, int *tries,
                    void (*again)(wm_proto *))
{
    for (;;) {
        int r = rx_frame(p, WM_PROTO_ACK_TIMEOUT_MS);
        if (r < 0) {
            p->abort = ABORT_CLOSED;
            return 0;
        }
        if (r == 0) {
            if (++*tries > WM_PROTO_ACK_RETRIES) {
                p->abort = ABORT_NO_ACK;
                return 0;
            }
            again(p);
            continue;
        }
        if (job_frame(p, kind, index, have)) return 1;
        if (p->abort) return 0;
    }
}

/* --- the level stream: LEVEL_HEADER, vertex slots, triangles (docs/protocol.md) --- */

/* The k-th live triangle's slot (sequential calls are O(1) each). */
static int32_t tri_slot(wm_proto *p, int32_t k)
{
    const wm_mesh *m = p->lm;
    if (k < p->cur_k) {
        p->cur_k = 0;
        p->cur_slot = 0;
        while (p->cur_slot < m->tri_end && m->hv[3 * p->cur_slot] < 0) p->cur_slot++;
    }
    while (p->cur_k < k) {
        p->cur_slot++;
        while (p->cur_slot < m->tri_end && m->hv[3 * p->cur_slot] < 0) p->cur_slot++;
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
        uint32_t c = part < 2 ? m->vx[v] : m->vy[v];
        if (m->vx[v] == WM_FREE) c = WM_PROTO_FREE_VERTEX;
        dst[i] = (uint8_t)(c >> (8 * (part & 1)));
    }
    if (i < n) {
        uint32_t r = off - hb - vb, k = r / tb, q = r - k * tb;
        int32_t t = tri_slot(p, (int32_t)k);
        for (;;) {
            uint32_t v = (uint32_t)m->hv[3 * t + (int32_t)(q >> lsh)];
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
        const uint16_t *vx = m->vx, *vy = m->vy;
        uint32_t v = (pos - hb) >> 1;
        if ((pos - hb) & 1u) { /* the first slot's y */
            *d++ = vx[v] == WM_FREE ? WM_FREE : vy[v];
            pos++;
            v++;
        }
        for (; pos + 2u <= end && pos < ve; pos += 2u, v++, d += 2) {
            uint16_t x = vx[v];
            d[0] = x;
            d[1] = x == WM_FREE ? x : vy[v];
        }
        if (pos < end && pos < ve) { /* the last slot's x */
            *d++ = vx[v];
            pos++;
        }
    }
    if (pos < end) { /* the triangles, from the k-th live one's q-th halfword */
        uint32_t per = p->lib == 4 ? 6u : 3u, r = pos - ve, k = r / per, q = r - k * per;
        int32_t t = tri_slot(p, (int32_t)k), te = m->tri_end;
        const wm_index *hv = m->hv;
        for (;;) {
            const wm_index *h = hv + 3 * t;
            if (q == 0 && end - pos >= per) {
                if (per == 3u) {
                    d[0] = (uint16_t)h[0];
                    d[1] = (uint16_t)h[1];
                    d[2] = (uint16_t)h[2];
                } else {
                    uint32_t a = (uint32_t)h[0], b = (uint32_t)h[1], c = (uint32_t)h[2];
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
                    *d++ = (uint16_t)(per == 6u ? (uint32_t)h[q >> 1] >> (16u * (q & 1u)) : (uint32_t)h[q]);
                if (q < per) break;
                q = 0;
            }
            if (pos == end) break;
            do t++;
            while (t < te && hv[3 * t] < 0);
            k++;
        }
        p->cur_k = (int32_t)k; /* the cursor where this frame ended */
        p->cur_slot = t;
    }
}

/* --- LEVEL_DELTA (docs/protocol.md, "Level coding"): the body as variable-length numbers --- */

static uint32_t put_varint(uint8_t *d, uint32_t v)
{
    uint32_t n = 0;
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
    p->cpos = 0;
    p->cv = p->ck = p->cslot = 0;
    p->cpx = p->cpy = p->cpi = 0;
    p->cbn = p->cbi = 0;
}

/* The next item of the body into cb (a vertex slot, then the live triangles); 0 when none is left. */
static int coded_item(wm_proto *p)
{
    const wm_mesh *m = p->lm;
    uint32_t n = 0;
    if (p->cv < m->vert_end) {
        int32_t v = p->cv++;
        if (m->vx[v] == WM_FREE) {
            p->cb[n++] = 0; /* a free slot */
        } else {
            int32_t x = m->vx[v], y = m->vy[v];
            n += put_varint(p->cb + n, zigzag32(x - p->cpx) + 1u);
            n += put_varint(p->cb + n, zigzag32(y - p->cpy));
            p->cpx = x;
            p->cpy = y;
        }
    } else if (p->ck < m->n_tri) {
        const wm_index *h;
        int32_t a;
        while (m->hv[3 * p->cslot] < 0) p->cslot++;
        h = m->hv + 3 * p->cslot;
        a = h[0];
        n += put_varint(p->cb + n, zigzag32(a - p->cpi));
        n += put_varint(p->cb + n, zigzag32(h[1] - a));
        n += put_varint(p->cb + n, zigzag32(h[2] - a));
        p->cpi = a;
        p->cslot++;
        p->ck++;
    } else {
        return 0;
    }
    p->cbn = (uint8_t)n;
    p->cbi = 0;
    return 1;
}

/* The coded stream's length: the header and every item (the coder starts again). */
static uint32_t coded_total(wm_proto *p)
{
    uint32_t total = WM_PROTO_LEVEL_HEADER_BYTES;
    coded_reset(p);
    while (coded_item(p)) total += p->cbn;
    coded_reset(p);
    return total;
}

/* Bytes [off, off + n) of the coded stream into dst (in order from where the last call ended: no work
 * but the new bytes; from before it: the coder runs again from the start). */
static void coded_bytes(wm_proto *p, uint32_t off, uint8_t *dst, uint32_t n)
{
    if (off < p->cpos) coded_reset(p);
    while (n) {
        uint8_t c;
        if (p->cpos < WM_PROTO_LEVEL_HEADER_BYTES) {
            c = p->lhdr[p->cpos];
        } else {
            if (p->cbi == p->cbn && !coded_item(p)) return; /* past the end: cannot happen (end <= ltotal) */
            c = p->cb[p->cbi++];
        }
        if (p->cpos++ >= off) {
            *dst++ = c;
            n--;
        }
    }
}

/* MESH frames of p->chunk bytes for bytes [from, end) (end <= ltotal).  The first sending (first: from
 * is 0) takes the stream's CRC on the way, and only its frames are link I/O: building the stream and
 * its CRC is the EMIT stage's work; the frame's CRC follows from the payload's (crc_combine).  A resend
 * happens inside link I/O (the host asked for it). */
static void send_level_from(wm_proto *p, uint32_t from, uint32_t end, int first)
{
    uint32_t chunk = p->chunk;
    if (first) p->lcrc = 0;
    while (from < end) {
        uint32_t n = end - from < chunk ? end - from : chunk, pc;
        uint8_t *b = p->tx.b, head[WM_PROTO_HEADER_BYTES];
        zero(b, WM_PROTO_MESH_BYTES);
        b[WM_PROTO_MESH_LEVEL] = p->level;
        b[WM_PROTO_MESH_INDEX] = p->levels_sent;
        put32(b + WM_PROTO_MESH_OFFSET, from);
        if (p->lcoded) coded_bytes(p, from, b + WM_PROTO_MESH_BYTES, n);
        else if (WM_LITTLE_ENDIAN && !((from | n) & 1u))
            level_halves(p, from / 2, (from + n) / 2, p->tx.h + WM_PROTO_MESH_BYTES / 2);
        else level_bytes(p, from, b + WM_PROTO_MESH_BYTES, n);
        pc = ~crc_run(~0u, b + WM_PROTO_MESH_BYTES, n);
        if (first) p->lcrc = crc_combine(p, p->lcrc, pc, n);
        link_begin(p);
        frame_head(head, WM_PROTO_T_MESH, p->seq++, WM_PROTO_MESH_BYTES + n);
        send_encoded(p, head, b, WM_PROTO_MESH_BYTES, b + WM_PROTO_MESH_BYTES, n,
                     crc_combine(p, ~crc_run(crc_run(~0u, head, sizeof head), b, WM_PROTO_MESH_BYTES), pc, n));
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
    send_own(p, WM_PROTO_T_LEVEL_END, b, sizeof b);
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
    int prev = p->stage, tries = 0;
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
    { /* delta-coded when that is shorter (a pass of the coder that only counts) */
        uint32_t coded = coded_total(p);
        p->lcoded = coded < p->ltotal;
        if (p->lcoded) p->ltotal = coded;
        p->lhdr[WM_PROTO_LEVEL_HEADER_CODING] = p->lcoded ? WM_PROTO_LEVEL_DELTA : WM_PROTO_LEVEL_RAW;
    }

    link_begin(p);
    send_progress(p, WM_PROTO_STAGE_EMIT, st->level);
    link_end(p);
    send_level_from(p, 0, p->ltotal, 1);
    link_begin(p); /* from here on everything waits for, or answers, the host */
    send_level_end(p);
    for (;;) {
        if (!wait_ack(p, WM_PROTO_T_LEVEL_END, p->levels_sent, &have, &tries, send_level_end)) break;
        if (have >= p->ltotal) break;
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
    stage_enter(p, prev);
    return WM_PROTO_E_NONE;
}

static void send_done(wm_proto *p)
{
    send_own(p, WM_PROTO_T_DONE, p->done, sizeof p->done);
    out_flush(p);
}

static void run_job(wm_proto *p)
{
    uint32_t detail = 0, have = 0;
    int rc, tries = 0;
    uint8_t *b = p->done;
    p->state = WM_PROTO_STATE_RUNNING;
    p->abort = 0;
    p->levels_sent = 0;
    p->chunk = (uint16_t)(p->caps.max_payload - WM_PROTO_MESH_BYTES); /* until the host asks for less */
    p->e_max = p->triangles = p->vertices = 0;
    p->level = (uint8_t)(p->job.levels - 1);
    p->run_t0 = now(p);
    p->link = 0;
    p->link_depth = 0;
    p->work_mark = 0;
    stage_enter(p, -1); /* the receive stage ends */

    rc = p->job_fn(p->job_ctx, &p->job, p, &detail);
    stage_enter(p, -1);
    if (p->abort == ABORT_HOST || p->abort == ABORT_CLOSED) {
        session_end(p); /* already answered (HELLO, ABORT), or nobody is listening */
        if (p->abort == ABORT_HOST) p->last_error = WM_PROTO_E_ABORTED;
        return;
    }
    if (p->abort == ABORT_NO_ACK) {
        rc = WM_PROTO_E_NO_ACK;
        detail = p->level;
    }
    zero(b, WM_PROTO_DONE_BYTES);
    b[WM_PROTO_DONE_STATUS] = (uint8_t)rc;
    b[WM_PROTO_DONE_LEVELS] = p->levels_sent;
    put32(b + WM_PROTO_DONE_DETAIL, detail);
    put32(b + WM_PROTO_DONE_E_MAX, p->e_max);
    put32(b + WM_PROTO_DONE_TRIANGLES, p->triangles);
    put32(b + WM_PROTO_DONE_VERTICES, p->vertices);
    put64(b + WM_PROTO_DONE_CYCLES_RECEIVE, p->cycles[WM_PROTO_STAGE_RECEIVE]);
    put64(b + WM_PROTO_DONE_CYCLES_FILTER, p->cycles[WM_PROTO_STAGE_FILTER]);
    put64(b + WM_PROTO_DONE_CYCLES_TEMPLATE, p->cycles[WM_PROTO_STAGE_TEMPLATE]);
    put64(b + WM_PROTO_DONE_CYCLES_REFINE, p->cycles[WM_PROTO_STAGE_REFINE]);
    put64(b + WM_PROTO_DONE_CYCLES_EMIT, p->cycles[WM_PROTO_STAGE_EMIT]);
    put64(b + WM_PROTO_DONE_CYCLES_LINK, p->link);
    if (rc) {
        p->last_error = (uint8_t)rc;
        p->last_detail = detail;
    }
    send_progress(p, WM_PROTO_STAGE_DONE, 0);
    if (p->abort != ABORT_NO_ACK) { /* a host that stopped answering gets one DONE, no wait */
        send_done(p);
        wait_ack(p, WM_PROTO_T_DONE, 0, &have, &tries, send_done);
    } else {
        send_done(p);
    }
    session_end(p);
}

/* ---------------------------------------------------------------------------------------------- */

void wm_proto_init(wm_proto *p, const wm_proto_io *io, const wm_proto_caps *caps, uint16_t *heights,
                   wm_proto_job_fn job, void *job_ctx)
{
    zero((uint8_t *)p, sizeof *p);
    p->io = *io;
    p->caps = *caps;
    if (p->caps.window < 1) p->caps.window = 1;
    if (p->caps.window > WM_PROTO_MAX_WINDOW) p->caps.window = WM_PROTO_MAX_WINDOW;
    if (p->caps.switched_window > p->caps.window) p->caps.switched_window = p->caps.window;
    if (p->caps.max_payload < WM_PROTO_MIN_PAYLOAD || p->caps.max_payload > WM_PROTO_MAX_PAYLOAD)
        p->caps.max_payload = WM_PROTO_MAX_PAYLOAD;
    if (p->caps.max_levels > WM_PROTO_MAX_LEVELS) p->caps.max_levels = WM_PROTO_MAX_LEVELS;
    p->heights = heights;
    p->job_fn = job;
    p->job_ctx = job_ctx;
    p->ms_cycles = caps->clk_hz / 1000u ? caps->clk_hz / 1000u : 1u;
    if (!p->io.set_divisor) p->caps.div_max = 0;
    if (p->caps.div_max == 0) p->caps.div_min = 0;
    p->div = p->caps.div_max ? p->caps.div : 0; /* 0: HELLO states caps.baud */
    p->stage = -1;
    p->state = WM_PROTO_STATE_IDLE;
    p->last_valid = now(p); /* the idle clock starts when the connection does */
    p->x8n = 0x80000000u;   /* x^0, for x8n_n = 0 */
    crc_slice_init();
    rx_reset(p);
}

void wm_proto_set_mask(wm_proto *p, uint8_t *mask, uint32_t bytes)
{
    p->mask = mask;
    p->mask_bytes = mask ? bytes : 0;
}

int wm_proto_serve(wm_proto *p)
{
    for (;;) {
        int r = rx_frame(p, SERVE_POLL_MS);
        if (r < 0) {
            session_end(p);
            out_flush(p);
            return WM_PROTO_SERVE_CLOSED;
        }
        if (r > 0) {
            p->probing = 0; /* a valid frame: the line's rate is proved */
            handle(p);
            p->last_valid = now(p); /* the session clock restarts with every valid frame */
            out_flush(p);
            continue;
        }
        if (p->probing && now(p) - p->probe_t0 >= ms_to_cycles(p, WM_PROTO_BAUD_PROBE_MS)) {
            /* nothing valid at the new rate: back to the old one, where the host will look for us */
            p->probing = 0;
            p->div = p->probe_div;
            p->io.set_divisor(p->io.ctx, p->div);
            rx_reset(p);
        }
        if (p->state == WM_PROTO_STATE_IDLE && !p->probing && p->div != p->caps.div &&
            now(p) - p->last_valid >= ms_to_cycles(p, WM_PROTO_BAUD_IDLE_MS)) {
            /* the host left at a switched rate: the next one starts at the start rate */
            p->div = p->caps.div;
            p->io.set_divisor(p->io.ctx, p->div);
            rx_reset(p);
        }
        if ((p->state == WM_PROTO_STATE_RECEIVING || p->state == WM_PROTO_STATE_READY) &&
            now(p) - p->last_valid >= ms_to_cycles(p, WM_PROTO_SESSION_TIMEOUT_MS)) {
            uint32_t got = p->next;
            session_end(p);
            send_error(p, WM_PROTO_E_TIMEOUT, got);
            out_flush(p);
            p->last_valid = now(p); /* the idle clock counts from the session's end */
        }
        if (p->state == WM_PROTO_STATE_IDLE && p->caps.idle_timeout_ms &&
            now(p) - p->last_valid >= ms_to_cycles(p, p->caps.idle_timeout_ms)) {
            out_flush(p);
            return WM_PROTO_SERVE_IDLE; /* the transport closes the connection: another client may come */
        }
    }
}

/* A frame with at most WM_PROTO_ERROR_BYTES of payload, SLIP-encoded into dst (for a connection the
 * engine does not serve); its length, 0 when cap is too small. */
static size_t encode_small(uint8_t *dst, size_t cap, uint8_t type, uint8_t seq, const uint8_t *payload, uint32_t n)
{
    uint8_t raw[WM_PROTO_HEADER_BYTES + WM_PROTO_ERROR_BYTES + WM_PROTO_CRC_BYTES];
    size_t len = 0, k;
    if (n > WM_PROTO_ERROR_BYTES || cap < WM_PROTO_BUSY_FRAME_MAX) return 0;
    raw[0] = type;
    raw[1] = seq;
    put16(raw + 2, n);
    for (k = 0; k < n; k++) raw[WM_PROTO_HEADER_BYTES + k] = payload[k];
    put32(raw + WM_PROTO_HEADER_BYTES + n, wm_proto_crc32(0, raw, WM_PROTO_HEADER_BYTES + n));
    dst[len++] = WM_PROTO_SLIP_END;
    for (k = 0; k < WM_PROTO_HEADER_BYTES + n + WM_PROTO_CRC_BYTES; k++) {
        if (raw[k] == WM_PROTO_SLIP_END || raw[k] == WM_PROTO_SLIP_ESC) {
            dst[len++] = WM_PROTO_SLIP_ESC;
            dst[len++] = raw[k] == WM_PROTO_SLIP_END ? WM_PROTO_SLIP_ESC_END : WM_PROTO_SLIP_ESC_ESC;
        } else {
            dst[len++] = raw[k];
        }
    }
    dst[len++] = WM_PROTO_SLIP_END;
    return len;
}

size_t wm_proto_busy_frame(uint8_t *dst, size_t cap)
{
    uint8_t b[WM_PROTO_ERROR_BYTES];
    zero(b, sizeof b);
    b[WM_PROTO_ERROR_CODE] = WM_PROTO_E_BUSY;
    b[WM_PROTO_ERROR_STATE] = WM_PROTO_STATE_IDLE; /* nothing starts on this connection */
    return encode_small(dst, cap, WM_PROTO_T_ERROR, 0, b, sizeof b);
}
