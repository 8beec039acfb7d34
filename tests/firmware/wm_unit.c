/* Native unit tests of the firmware: tiny hand-built meshes for every operator, the exact helpers,
 * E(T), the filter bank and small refinements.  Run by ctest and by tests/firmware (also under
 * AddressSanitizer and UndefinedBehaviorSanitizer with the invariant check after every operator).
 * Prints one line per failure and "N passed, N failed". */
#include <stdio.h>
#include <string.h>

#include "wavemesh.h"
/* wm_internal.h's inline 32-bit-division paths as the soft CPU takes them, tested against plain
 * division (the library's own use of them runs natively in the checked build) */
#define WM_NARROW_DIV 1
#include "wm_internal.h"

static int passed, failed;

#define CHECK(c)                                                \
    do {                                                        \
        if (c) {                                                \
            passed++;                                           \
        } else {                                                \
            failed++;                                           \
            printf("FAIL %s:%d: %s\n", __FILE__, __LINE__, #c); \
        }                                                       \
    } while (0)

static unsigned char mem[1 << 22];
static uint32_t scratch[3 * 4096];

/* A W x H grid cut into two triangles by the diagonal (0,0)-(W-1,H-1):
 *   0 ---- 1          vertices 0 (0,0), 1 (W-1,0), 2 (0,H-1), 3 (W-1,H-1)  (y grows downwards)
 *   |  \   |          triangles (0, 1, 3) and (0, 3, 2): orient > 0
 *   2 ---- 3 */
static int square(wm_mesh *m, int32_t w, int32_t h, int32_t cap)
{
    int32_t xy[8] = {0, 0, w - 1, 0, 0, h - 1, w - 1, h - 1};
    int32_t tris[6] = {0, 1, 3, 0, 3, 2};
    int rc = wm_mesh_init(m, mem, sizeof mem, w, h, cap, wm_vert_cap_for(w, h, cap));
    if (rc != WM_OK) return rc;
    return wm_mesh_build(m, xy, 4, tris, 2, scratch);
}

static int32_t find_edge(const wm_mesh *m, int32_t ax, int32_t ay, int32_t bx, int32_t by)
{
    for (int32_t e = 0; e < 3 * m->tri_end; e++) {
        int32_t a, b;
        if (m->he[3 * WM_TRI(e)].v < 0) continue;
        a = m->he[e].v;
        b = m->he[WM_NEXT(e)].v;
        if (m->vxy[a].x == ax && m->vxy[a].y == ay && m->vxy[b].x == bx && m->vxy[b].y == by) return e;
    }
    return -1;
}

static int32_t find_vertex(const wm_mesh *m, int32_t x, int32_t y)
{
    for (int32_t v = 0; v < m->vert_end; v++)
        if (m->vxy[v].x == x && m->vxy[v].y == y) return v;
    return -1;
}

static void test_build(void)
{
    wm_mesh m;
    int32_t xy[8] = {0, 0, 4, 0, 0, 4, 4, 4};
    int32_t cw[6] = {0, 3, 1, 0, 2, 3};     /* clockwise */
    int32_t hole[3] = {0, 1, 3};             /* half the square */
    int32_t bad[6] = {0, 1, 3, 0, 3, 9};     /* index out of range */
    int32_t out_xy[8], out_t[6];
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    CHECK(m.n_tri == 2 && m.n_vert == 4);
    CHECK(wm_mesh_check(&m) == WM_OK);
    CHECK(m.he[find_edge(&m, 0, 0, 4, 4)].o == find_edge(&m, 4, 4, 0, 0));
    CHECK(m.he[find_edge(&m, 4, 0, 4, 4)].o == -1);
    CHECK(wm_mesh_export(&m, out_xy, out_t) == 2);
    CHECK(memcmp(out_xy, xy, sizeof xy) == 0 && out_t[0] == 0 && out_t[1] == 1 && out_t[5] == 2);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, 5, 5, 8, 8) == WM_OK);
    CHECK(wm_mesh_build(&m, xy, 4, cw, 2, scratch) == WM_ERR_MESH);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, 5, 5, 8, 8) == WM_OK);
    CHECK(wm_mesh_build(&m, xy, 4, hole, 1, scratch) == WM_ERR_MESH);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, 5, 5, 8, 8) == WM_OK);
    CHECK(wm_mesh_build(&m, xy, 4, bad, 2, scratch) == WM_ERR_ARG);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, 5, 5, 1, 8) == WM_OK);
    CHECK(wm_mesh_build(&m, xy, 4, bad, 2, scratch) == WM_ERR_CAPACITY);
    CHECK(wm_mesh_init(&m, mem, 16, 5, 5, 8, 8) == WM_ERR_MEMORY);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, 1, 5, 8, 8) == WM_ERR_ARG);
    CHECK(wm_mesh_init(&m, mem, sizeof mem, WM_MAX_SIDE + 1, 5, 8, 8) == WM_ERR_ARG);
    /* a corrupted mesh fails the check */
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    m.vxy[3].x = 3;
    CHECK(wm_mesh_check(&m) == WM_ERR_MESH);
}

static void test_edge_split(void)
{
    wm_mesh m;
    int32_t touched[4], n = 0, e;
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    e = find_edge(&m, 0, 0, 4, 4);
    CHECK(wm_edge_split(&m, e, 1, 2, touched, &n) == WM_ERR_REFUSED); /* off the edge */
    CHECK(wm_edge_split(&m, e, 0, 0, touched, &n) == WM_ERR_REFUSED); /* an end point */
    CHECK(wm_edge_split(&m, e, 2, 2, touched, &n) == WM_OK);
    CHECK(n == 4 && m.n_tri == 4 && m.n_vert == 5);
    CHECK(wm_mesh_check(&m) == WM_OK);
    CHECK(find_edge(&m, 2, 2, 4, 0) >= 0 && find_edge(&m, 0, 4, 2, 2) >= 0);
    /* border edge: one triangle becomes two */
    e = find_edge(&m, 4, 0, 4, 4);
    CHECK(e >= 0 && wm_edge_split(&m, e, 4, 1, touched, &n) == WM_OK);
    CHECK(n == 2 && m.n_tri == 5 && wm_mesh_check(&m) == WM_OK);
    /* capacity: no slot left for two more triangles */
    CHECK(square(&m, 5, 5, 3) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 4, 4), 2, 2, touched, &n) == WM_ERR_CAPACITY);
    CHECK(m.n_tri == 2 && wm_mesh_check(&m) == WM_OK);
}

static void test_tri_split(void)
{
    wm_mesh m;
    int32_t touched[3], n = 0, e, t;
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    e = find_edge(&m, 0, 0, 4, 4);
    t = WM_TRI(e); /* (0,0) (4,4) (0,4) */
    CHECK(wm_tri_split(&m, t, 2, 2, touched, &n) == WM_ERR_REFUSED); /* on an edge */
    CHECK(wm_tri_split(&m, t, 3, 1, touched, &n) == WM_ERR_REFUSED); /* in the other triangle */
    /* off the grid, and inside t if the orientations wrapped around in 32 bits */
    CHECK(wm_tri_split(&m, t, 1442100146, -234560211, touched, &n) == WM_ERR_REFUSED);
    CHECK(wm_tri_split(&m, t, 1, 3, touched, &n) == WM_OK);
    CHECK(n == 3 && m.n_tri == 4 && m.n_vert == 5 && wm_mesh_check(&m) == WM_OK);
    CHECK(find_edge(&m, 1, 3, 0, 0) >= 0 || find_edge(&m, 0, 0, 1, 3) >= 0);
    CHECK(square(&m, 5, 5, 3) == WM_OK);
    CHECK(wm_tri_split(&m, 1, 1, 3, touched, &n) == WM_ERR_CAPACITY && wm_mesh_check(&m) == WM_OK);
}

static void test_edge_swap(void)
{
    wm_mesh m;
    int32_t e, touched[4], n;
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    e = find_edge(&m, 0, 0, 4, 4);
    CHECK(wm_edge_swappable(&m, e) == 1);
    CHECK(wm_edge_swap(&m, e, touched, &n) == WM_OK && n == 2);
    CHECK(wm_mesh_check(&m) == WM_OK);
    CHECK(find_edge(&m, 0, 0, 4, 4) < 0 && (find_edge(&m, 4, 0, 0, 4) >= 0 || find_edge(&m, 0, 4, 4, 0) >= 0));
    CHECK(wm_edge_swap(&m, find_edge(&m, 0, 0, 4, 0), touched, &n) == WM_ERR_REFUSED); /* border */
    /* a non-convex quadrilateral: after a ternary split at (1,3), the edge (1,3)-(0,4) has the
     * quadrilateral (4,4) (0,4) (0,0) (1,3), with (1,3) inside the hull of the other three */
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    CHECK(wm_tri_split(&m, WM_TRI(find_edge(&m, 0, 0, 4, 4)), 1, 3, touched, &n) == WM_OK);
    e = find_edge(&m, 1, 3, 0, 4);
    if (e < 0) e = find_edge(&m, 0, 4, 1, 3);
    CHECK(e >= 0 && wm_edge_swappable(&m, e) == 0);
    CHECK(wm_edge_swap(&m, e, touched, &n) == WM_ERR_REFUSED && wm_mesh_check(&m) == WM_OK);
    /* collinear corners (non-strict convex) are refused too */
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 4, 4), 2, 2, touched, &n) == WM_OK);
    e = find_edge(&m, 2, 2, 4, 0);
    CHECK(e >= 0 && wm_edge_swappable(&m, e) == 0);
}

static void test_vertex_move(void)
{
    wm_mesh m;
    int32_t touched[4], n, v;
    CHECK(square(&m, 5, 5, 8) == WM_OK);
    CHECK(wm_vertex_move(&m, 0, 1, 1) == WM_ERR_REFUSED); /* a corner */
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 4, 4), 2, 2, touched, &n) == WM_OK);
    v = find_vertex(&m, 2, 2);
    CHECK(wm_vertex_move(&m, v, 3, 3) == WM_OK && wm_mesh_check(&m) == WM_OK);
    CHECK(wm_vertex_move(&m, v, 4, 3) == WM_ERR_REFUSED); /* onto the border */
    CHECK(wm_vertex_move(&m, v, 1, 1) == WM_OK && wm_mesh_check(&m) == WM_OK);
    /* a border vertex slides along its side only */
    CHECK(wm_edge_split(&m, find_edge(&m, 4, 0, 4, 4), 4, 2, touched, &n) == WM_OK);
    v = find_vertex(&m, 4, 2);
    CHECK(wm_vertex_move(&m, v, 3, 2) == WM_ERR_REFUSED);
    CHECK(wm_vertex_move(&m, v, 4, 3) == WM_OK && wm_mesh_check(&m) == WM_OK);
    CHECK(wm_vertex_move(&m, v, 4, 4) == WM_ERR_REFUSED); /* onto a corner: triangle flat */
    CHECK(wm_mesh_check(&m) == WM_OK);
}

/* floor(sqrt(x)) bit by bit (the method fixed.c's fast roots replaced): the reference. */
static uint64_t isqrt_ref(uint64_t x)
{
    uint64_t r = 0, bit = (uint64_t)1 << 62;
    while (bit > x) bit >>= 2;
    while (bit) {
        if (x >= r + bit) {
            x -= r + bit;
            r = (r >> 1) + bit;
        } else {
            r >>= 1;
        }
        bit >>= 2;
    }
    return r;
}

static uint64_t rand64(uint64_t *s)
{
    *s ^= *s << 13;
    *s ^= *s >> 7;
    *s ^= *s << 17;
    return *s;
}

/* The exact roots of wm_isqrt64 (one Newton step from a 32-bit root, then one square, above 2^32) at
 * every bit length: squares, their neighbours (the step's worst cases sit just below a square), and
 * random numbers of every length; a wrong root counts once. */
static void test_isqrt(void)
{
    uint64_t seed = 0x9E3779B97F4A7C15u;
    int bad = 0;
    for (int b = 0; b < 64 && !bad; b++)
        for (int i = 0; i < 4000; i++) {
            uint64_t x = rand64(&seed) >> (63 - b), r = isqrt_ref(x);
            uint64_t sq = r * r, next = r == 0xFFFFFFFFu ? UINT64_MAX : (r + 1) * (r + 1) - 1;
            if (wm_isqrt64(x) != r || wm_isqrt64(sq) != r || wm_isqrt64(next) != r ||
                (r > 0 && wm_isqrt64(sq - 1) != r - 1)) {
                bad = 1;
                printf("isqrt: wrong root near %llu\n", (unsigned long long)x);
                break;
            }
        }
    CHECK(!bad);
    CHECK(wm_bit_length64(0) == 0);
    for (int b = 0; b < 64; b++) {
        uint64_t p = (uint64_t)1 << b;
        CHECK(wm_bit_length64(p) == b + 1 && wm_bit_length64(p | (p - 1)) == b + 1 &&
              wm_bit_length64(p | 1) == b + 1);
    }
    for (uint64_t r = 0xFFFFFFFFu; r > 0xFFFFFF00u; r--)
        CHECK(wm_isqrt64(r * r) == r && wm_isqrt64(r * r - 1) == r - 1);
    for (uint64_t r = 1u << 15; r < (1u << 15) + 64; r++) CHECK(wm_isqrt64(r * r << 32) == r << 16);
}

/* The 32-bit-division fast paths (wm_udiv_small, wm_ceil_q16_div, wm_frac_mul's) against plain 64-bit
 * division, at every bit length of the dividend and divisors around the paths' limits. */
static void test_narrow_div(void)
{
    uint64_t seed = 0x2545F4914F6CDD1Du;
    int bad = 0;
    for (int b = 0; b < 64; b++)
        for (int i = 0; i < 400; i++) {
            uint64_t n = rand64(&seed) >> (63 - b), v = rand64(&seed);
            uint32_t d = (uint32_t)(v % 65535u) + 1u, rem = 0;
            uint64_t dd = (uint64_t)1 + (v >> (40 - b % 26)) % (((uint64_t)1 << (8 + b % 26)) - 1);
            uint64_t q = wm_udiv_small(n, i < 8 ? 65535u - (uint32_t)i : d, &rem);
            uint64_t dn = i < 8 ? 65535u - (uint32_t)i : d, nq = n >> 16;
            uint32_t m = (uint32_t)(v >> 48), sh = (uint32_t)(v >> 20) % 17u, e = (uint32_t)(v >> 8) % 40u;
            uint64_t fd = i & 1 ? dd : d, ref, prod = (n >> 17) * m;
            int k = (int)sh - (int)e;
            bad |= q != n / dn || rem != n % dn;
            bad |= wm_ceil_q16_div(nq, dd) != (nq * 65536u + dd - 1) / dd;
            bad |= wm_ceil_q16_div(nq >> 16, dd) != ((nq >> 16) * 65536u + dd - 1) / dd;
            /* wm_frac_mul as it read before its fast path */
            if (k <= 0) ref = -k >= 64 ? 0 : (prod / fd) >> -k;
            else
                ref = (prod / fd) > (UINT64_MAX >> 1 >> k) ? UINT64_MAX >> 1
                                                           : ((prod / fd) << k) + (((prod % fd) << k) / fd);
            if (ref > UINT64_MAX >> 1) ref = UINT64_MAX >> 1;
            bad |= wm_frac_mul(n >> 17, fd, m, (int32_t)e, (int)sh, UINT64_MAX >> 1) != ref;
        }
    CHECK(!bad);
    for (uint32_t d = 1; d < 70000u; d += 997u) {
        uint32_t rem;
        CHECK(wm_udiv_small(UINT64_MAX, d < 65536u ? d : 65535u, &rem) == UINT64_MAX / (d < 65536u ? d : 65535u));
        CHECK(wm_ceil_q16_div(0xFFFFFFFFu, (uint64_t)d << 8) ==
              ((uint64_t)0xFFFFFFFFu * 65536u + ((uint64_t)d << 8) - 1) / ((uint64_t)d << 8));
    }
}

static void test_fixed(void)
{
    CHECK(wm_isqrt64(0) == 0 && wm_isqrt64(15) == 3 && wm_isqrt64(16) == 4);
    CHECK(wm_isqrt64(UINT64_MAX) == 0xFFFFFFFFu);
    test_isqrt();
    test_narrow_div();
    CHECK(wm_gcd(12, -18) == 6 && wm_gcd(0, 5) == 5 && wm_gcd(7, 0) == 7);
    CHECK(wm_floor_div(-7, 2) == -4 && wm_floor_div(7, 2) == 3 && wm_ceil_div(-7, 2) == -3);
    CHECK(wm_ceil_div(7, 2) == 4 && wm_floor_div(-8, 2) == -4);
    CHECK(wm_cmp_mul(UINT64_MAX, UINT64_MAX, UINT64_MAX, UINT64_MAX - 1) > 0);
    CHECK(wm_cmp_mul((uint64_t)1 << 40, (uint64_t)1 << 40, (uint64_t)1 << 50, (uint64_t)1 << 30) == 0);
    CHECK(wm_cmp_mul(3, (uint64_t)1 << 63, 1, UINT64_MAX) > 0);
    /* atan2 in Q16 radians: pi/4 = 51472, pi/2 = 102944, pi = 205887 (within a few units) */
    CHECK(wm_angle_q16(1, 1) >= 51469 && wm_angle_q16(1, 1) <= 51475);
    CHECK(wm_angle_q16(0, 5) >= 102940 && wm_angle_q16(0, 5) <= 102948);
    CHECK(wm_angle_q16(-1000000000, 1) >= 205880 && wm_angle_q16(-1000000000, 1) <= 205890);
    CHECK(wm_angle_q16(7, 0) == 0);
    CHECK(wm_angle_q16(1, 2) > wm_angle_q16(2, 1));
}

static void test_error(void)
{
    /* 5 x 5 field, zero but for one sample; triangle (0,0) (4,0) (0,4) */
    uint16_t h[25];
    int32_t x[3] = {0, 4, 0}, y[3] = {0, 0, 4}, wx, wy;
    wm_field f = {5, 5, 1, h, NULL, NULL};
    wm_params p;
    memset(h, 0, sizeof h);
    memset(&p, 0, sizeof p);
    p.metric = WM_METRIC_VERTICAL;
    p.scale_m = 32768;
    p.scale_e = 15; /* s = 1 */
    h[1 * 5 + 1] = 7;
    CHECK(wm_tri_error(&f, &p, x, y, &wx, &wy) == 7u * 65536u && wx == 1 && wy == 1);
    p.metric = WM_METRIC_NORMAL; /* flat plane: the same */
    CHECK(wm_tri_error(&f, &p, x, y, NULL, NULL) == 7u * 65536u);
    /* a sample on the hypotenuse counts (closed triangle) */
    h[1 * 5 + 1] = 0;
    h[2 * 5 + 2] = 3;
    CHECK(wm_tri_error(&f, &p, x, y, &wx, &wy) == 3u * 65536u && wx == 2 && wy == 2);
    /* tilted plane z = 4 x: normal = vertical / sqrt(17) */
    for (int i = 0; i < 25; i++) h[i] = (uint16_t)(4 * (i % 5));
    h[1 * 5 + 1] = 4 + 10;
    p.metric = WM_METRIC_VERTICAL;
    CHECK(wm_tri_error(&f, &p, x, y, NULL, NULL) == 10u * 65536u);
    p.metric = WM_METRIC_NORMAL;
    {
        uint32_t e = wm_tri_error(&f, &p, x, y, NULL, NULL);
        /* 10 / sqrt(17) = 2.42535625...; Q16.16 = 158948.4: an upper bound within 2^-15 */
        CHECK(e >= 158949u && e <= 158949u + 8u);
    }
    /* half the scale: slope 2 -> 10 / sqrt(5) in samples... s = 0.5: g = 2 */
    p.scale_e = 16;
    {
        uint32_t e = wm_tri_error(&f, &p, x, y, NULL, NULL);
        /* 10 / sqrt(1 + 4) = 4.47213595 samples: 293086.8 */
        CHECK(e >= 293087u && e <= 293087u + 12u);
    }
    /* s = 1 on cells 2 wide (s / dx = 0.5): the same slope 2, the same bits; dy plays no part here */
    p.scale_e = 15;
    p.slope_x_m = 32768, p.slope_x_e = 16;
    p.slope_y_m = 40000, p.slope_y_e = 3;
    {
        uint32_t e = wm_tri_error(&f, &p, x, y, NULL, NULL);
        CHECK(e >= 293087u && e <= 293087u + 12u);
        p.scale_e = 16, p.slope_x_m = p.slope_y_m = 0; /* m = 0: the height scale, a cell of 1 */
        CHECK(wm_tri_error(&f, &p, x, y, NULL, NULL) == e);
    }
}

static void test_haar(void)
{
    /* 3 x 3: the last row and column repeat; level 1 has 2 x 2 cells */
    uint16_t s[9] = {1, 2, 3, 4, 5, 6, 7, 8, 9}, sc[64];
    int32_t d[64];
    CHECK(wm_details_size(3, 3, 2) == 3 * 4 + 3 * 1);
    CHECK(wm_haar(s, 3, 3, 2, d, sc) == WM_OK);
    /* cell (0,0): p00=1 p01=2 p10=4 p11=5: d1 = 7-5 = 2, d2 = 9-3 = 6, d3 = 6-6 = 0 */
    CHECK(d[0] == 2 && d[1] == 6 && d[2] == 0);
    /* cell (0,1): p00=3 p01=3 p10=6 p11=6: d1 = 0, d2 = 6 */
    CHECK(d[3] == 0 && d[4] == 6 && d[5] == 0);
    /* level 2 from a = [[3, 5], [8, 9]] (rounded half up): d1 = 14-11 = 3, d2 = 17-8 = 9, d3 = 12-13 = -1 */
    CHECK(d[12] == 3 && d[13] == 9 && d[14] == -1);
}

/* A finished refiner's statistics against its mesh measured afresh: E_max the largest E(T) and over the
 * triangles above zeta (the error bound and the decimation keep upper bounds of E(T) within zeta, and
 * wm_settle makes the level's E_max from them: it must be the exact one). */
static void check_final_stats(const wm_refiner *r, const wm_field *f, const wm_params *p, const wm_level_stats *st)
{
    const wm_mesh *m = wm_refine_mesh(r);
    uint32_t emax = 0;
    int32_t over = 0;
    for (int32_t t = 0; t < m->tri_end; t++) {
        int32_t x[3], y[3], wx, wy;
        uint32_t e;
        if (m->he[3 * t].v < 0) continue;
        wm_tri_xy(m, t, x, y);
        e = wm_tri_error(f, p, x, y, &wx, &wy);
        if (e > emax) emax = e;
        if (e > p->zeta) over++;
    }
    CHECK(st->e_max == emax && st->over == over);
}

/* A field with a step and a bump, refined from two triangles with zeta = 0: every sample ends
 * exactly on the mesh. */
static void test_refine(void)
{
    enum { W = 17, H = 13, M = 3 };
    static uint16_t h[W * H], sc[W * H];
    static int32_t d[4096];
    int32_t xy[8] = {0, 0, W - 1, 0, 0, H - 1, W - 1, H - 1}, tris[6] = {0, 1, 3, 0, 3, 2};
    wm_field f = {W, H, M, h, d, NULL};
    wm_params p;
    wm_refiner *r = NULL;
    wm_level_stats st;
    int32_t cap = wm_tri_cap_max(W, H), levels = 0;
    for (int yy = 0; yy < H; yy++)
        for (int xx = 0; xx < W; xx++) h[yy * W + xx] = (uint16_t)((xx > 8 ? 300 : 0) + (yy - 6) * (yy - 6) + xx);
    CHECK(wm_haar(h, W, H, M, d, sc) == WM_OK);
    memset(&p, 0, sizeof p);
    p.metric = WM_METRIC_NORMAL;
    p.iterations = 2;
    p.scale_m = 32768;
    p.scale_e = 15;
    p.delta_p = 58982; /* 0.9 */
    p.alpha = 39322;   /* 0.6 */
    p.delta_v = 2u << 16;
    p.delta_d = 0;
    p.zeta = 0;
    CHECK(wm_refine_bound(W, H, cap) <= sizeof mem);
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_OK);
    CHECK(wm_refine_level(r) == M - 1);
    while (!wm_refine_done(r)) {
        CHECK(wm_refine_step(r, &st) == WM_OK);
        CHECK(wm_mesh_check(wm_refine_mesh(r)) == WM_OK);
        levels++;
    }
    CHECK(levels == M - 1 && st.level == 0 && st.e_max == 0 && st.over == 0);
    check_final_stats(r, &f, &p, &st);
    CHECK(wm_refine_step(r, &st) == WM_ERR_STATE);
    /* the budget stops the error bound early */
    p.max_triangles = 20;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_OK);
    while (!wm_refine_done(r)) CHECK(wm_refine_step(r, &st) == WM_OK);
    CHECK(st.triangles <= 20 && st.budget_hit == 1 && st.over > 0);
    check_final_stats(r, &f, &p, &st);
    /* zeta above 0 in the normal metric: the bound's upper bounds and the final decimation's removals */
    p.max_triangles = 0;
    p.zeta = 2u << 16;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_OK);
    while (!wm_refine_done(r)) CHECK(wm_refine_step(r, &st) == WM_OK);
    CHECK(st.over == 0 && st.e_max <= p.zeta && st.removals > 0);
    check_final_stats(r, &f, &p, &st);
    p.max_triangles = 24; /* and a budget that stops it */
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_OK);
    while (!wm_refine_done(r)) CHECK(wm_refine_step(r, &st) == WM_OK);
    CHECK(st.budget_hit == 1);
    check_final_stats(r, &f, &p, &st);
    p.zeta = 0;
    /* a capacity too small is a return code, and the mesh stays valid */
    p.max_triangles = 0;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, 12) == WM_OK);
    {
        int rc = WM_OK;
        while (!wm_refine_done(r) && rc == WM_OK) rc = wm_refine_step(r, &st);
        CHECK(rc == WM_ERR_CAPACITY);
    }
    CHECK(wm_mesh_check(wm_refine_mesh(r)) == WM_OK && wm_refine_mesh(r)->n_tri <= 12);
    /* vertex-based neighbourhood and vertical metric */
    p.neighbourhood = WM_NEIGHBOURHOOD_VERTEX;
    p.metric = WM_METRIC_VERTICAL;
    p.zeta = 3u << 16;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_OK);
    while (!wm_refine_done(r)) CHECK(wm_refine_step(r, &st) == WM_OK);
    CHECK(st.over == 0 && st.e_max <= p.zeta && wm_mesh_check(wm_refine_mesh(r)) == WM_OK);
    check_final_stats(r, &f, &p, &st);
    /* bad parameters */
    p.iterations = 4;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 4, tris, 2, cap) == WM_ERR_ARG);
    p.iterations = 1;
    CHECK(wm_refine_init(&r, mem, 64, &f, &p, xy, 4, tris, 2, cap) == WM_ERR_MEMORY);
}

/* Vertex removal: an interior and a border vertex go back to the two triangles; corners are
 * refused; then random splits and removals (every plan kind) keep the mesh proper throughout. */
static void test_vertex_remove(void)
{
    wm_mesh m;
    int32_t touched[WM_MAX_RING], tris[3 * WM_MAX_RING], ring[WM_MAX_RING], nt = 0, nk = 0, v, e;
    uint32_t seed = 12345u;
    CHECK(square(&m, 9, 9, 4096) == WM_OK);
    CHECK(wm_tri_split(&m, 0, 6, 3, touched, &nt) == WM_OK);
    v = find_vertex(&m, 6, 3);
    CHECK(wm_vertex_ring(&m, v, ring) == 3);
    CHECK(wm_vertex_remove_plan(&m, v, -1, tris, &nt) == WM_OK && nt == 1);
    CHECK(wm_vertex_remove(&m, v, tris, nt, touched, &nk) == WM_OK && nk == 1);
    CHECK(m.n_tri == 2 && m.n_vert == 4 && wm_mesh_check(&m) == WM_OK);
    e = find_edge(&m, 0, 0, 8, 0);
    if (e < 0) e = find_edge(&m, 8, 0, 0, 0);
    CHECK(e >= 0 && wm_edge_split(&m, e, 4, 0, touched, &nt) == WM_OK);
    v = find_vertex(&m, 4, 0);
    CHECK(v >= 0 && wm_vertex_ring(&m, v, ring) == 3);
    CHECK(wm_vertex_remove_plan(&m, v, 0, tris, &nt) == WM_OK && nt == 1);
    CHECK(wm_vertex_remove(&m, v, tris, nt, NULL, NULL) == WM_OK);
    CHECK(m.n_tri == 2 && m.n_vert == 4 && wm_mesh_check(&m) == WM_OK);
    CHECK(wm_vertex_ring(&m, find_vertex(&m, 0, 0), ring) == WM_ERR_REFUSED);
    /* Random: split at random grid points, remove random vertices with random plans. */
    CHECK(square(&m, 33, 29, 4096) == WM_OK);
    for (int step = 0; step < 3000; step++) {
        int32_t x, y, t, a, rc, n;
        seed = seed * 1103515245u + 12345u;
        x = (int32_t)((seed >> 8) % 33u);
        seed = seed * 1103515245u + 12345u;
        y = (int32_t)((seed >> 8) % 29u);
        if ((seed >> 20) % 3u != 0 || m.n_vert < 8) { /* split the triangle holding (x, y) */
            for (t = 0; t < m.tri_end; t++) {
                int32_t tx[3], ty[3], s0, s1, s2;
                if (m.he[3 * t].v < 0) continue;
                for (int k = 0; k < 3; k++) tx[k] = m.vxy[m.he[3 * t + k].v].x, ty[k] = m.vxy[m.he[3 * t + k].v].y;
                s0 = (int32_t)wm_orient(tx[1], ty[1], tx[2], ty[2], x, y);
                s1 = (int32_t)wm_orient(tx[2], ty[2], tx[0], ty[0], x, y);
                s2 = (int32_t)wm_orient(tx[0], ty[0], tx[1], ty[1], x, y);
                if (s0 > 0 && s1 > 0 && s2 > 0) {
                    if (m.n_tri + 2 <= m.tri_cap) CHECK(wm_tri_split(&m, t, x, y, touched, &nt) == WM_OK);
                    break;
                }
            }
            continue;
        }
        v = find_vertex(&m, x, y);
        if (v < 0) continue;
        n = wm_vertex_ring(&m, v, ring);
        if (n < 0) {
            CHECK(n == WM_ERR_REFUSED);
            continue;
        }
        a = (int32_t)((seed >> 4) % (uint32_t)(n + 1)) - 1;
        rc = wm_vertex_remove_plan(&m, v, a, tris, &nt);
        CHECK(rc == WM_OK || (rc == WM_ERR_REFUSED && a >= 0));
        if (rc != WM_OK) continue;
        {
            int32_t before = m.n_tri, border = wm_on_border(&m, x, y);
            CHECK(nt == n - 2);
            CHECK(wm_vertex_remove(&m, v, tris, nt, touched, &nk) == WM_OK && nk == nt);
            CHECK(m.n_tri == before - (border ? 1 : 2));
            CHECK(wm_mesh_check(&m) == WM_OK);
        }
    }
    CHECK(wm_mesh_check(&m) == WM_OK);
}

/* wm_orient in 32-bit arithmetic over the whole coordinate range (0..WM_MAX_SIDE - 1): the 64-bit
 * products' difference, corners at the range's ends among them (the checking build's UBSan sees any
 * overflow). */
static void test_orient(void)
{
    const int32_t M = WM_MAX_SIDE - 1, ends[4] = {0, 1, WM_MAX_SIDE - 2, WM_MAX_SIDE - 1};
    uint64_t seed = 0x9E3779B97F4A7C15u;
    int wrong = 0;
    CHECK(wm_orient(0, 0, M, 0, 0, M) == (int64_t)M * M && wm_orient(0, 0, 0, M, M, 0) == -(int64_t)M * M);
    CHECK(wm_orient(M, 0, M, M, 0, 0) == (int64_t)M * M && wm_orient(0, M, M, 0, M, M) == (int64_t)M * M);
    for (int i = 0; i < 200000; i++) {
        int32_t p[6];
        int64_t want;
        for (int c = 0; c < 6; c++) {
            uint64_t r = rand64(&seed);
            p[c] = (r & 3u) == 0u ? ends[(r >> 2) & 3u] : (int32_t)((r >> 8) % (uint64_t)WM_MAX_SIDE);
        }
        want = ((int64_t)p[2] - p[0]) * ((int64_t)p[5] - p[1]) - ((int64_t)p[4] - p[0]) * ((int64_t)p[3] - p[1]);
        wrong += wm_orient(p[0], p[1], p[2], p[3], p[4], p[5]) != want;
    }
    CHECK(wrong == 0);
}

/* The in-circle predicate at the extremes of the coordinate range, and the smallest angle taken
 * opposite the shortest side. */
static void test_incircle(void)
{
    const int32_t M = WM_MAX_SIDE - 1;
    int32_t x[3] = {0, 4, 0}, y[3] = {0, 0, 3};
    CHECK(wm_incircle(0, 0, 2, 0, 0, 2, 1, 1) > 0);
    CHECK(wm_incircle(0, 0, 2, 0, 0, 2, 2, 2) == 0);
    CHECK(wm_incircle(0, 0, 2, 0, 0, 2, 3, 3) < 0);
    CHECK(wm_incircle(0, 0, M, 0, 0, M, M, M) == 0);
    CHECK(wm_incircle(0, 0, M, 0, 0, M, M - 1, M - 1) > 0);
    CHECK(wm_incircle(0, 0, M, 0, 0, M, M, M - 1) > 0);
    CHECK(wm_incircle(M, 0, M, M, 0, M, 0, 0) == 0);
    CHECK(wm_incircle(M, 0, M, M, 0, M, 0, 1) > 0);
    /* atan2(3, 4) = 0.6435 rad, the angle at (4, 0) opposite the shortest side */
    CHECK(wm_min_angle(x, y) > 42100 && wm_min_angle(x, y) < 42200);
    /* wm_angle_above bounds the CORDIC's smallest angle from above (refine.c's swaps refuse on it):
     * random counter-clockwise triangles over the whole range, slivers and near-equilateral ones */
    {
        uint32_t seed = 12345u;
        int32_t worst = 1 << 30;
        for (int i = 0; i < 200000; i++) {
            int64_t dot, cross;
            int32_t a, ab;
            int32_t span = i % 4 == 0 ? 8 : i % 4 == 1 ? 200 : M;
            for (int c = 0; c < 3; c++) {
                seed = seed * 1103515245u + 12345u;
                x[c] = (int32_t)((seed >> 8) % (uint32_t)(span + 1));
                seed = seed * 1103515245u + 12345u;
                y[c] = (int32_t)((seed >> 8) % (uint32_t)(span + 1));
            }
            if (i % 7 == 0) x[2] = (x[0] + x[1]) / 2 + 1, y[2] = (y[0] + y[1]) / 2; /* a sliver */
            if (wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) < 0) {
                int32_t t = x[1];
                x[1] = x[2], x[2] = t, t = y[1], y[1] = y[2], y[2] = t;
            }
            if (wm_orient(x[0], y[0], x[1], y[1], x[2], y[2]) <= 0) continue;
            wm_min_corner(x, y, &dot, &cross);
            a = wm_min_angle(x, y);
            ab = wm_angle_above(dot, cross);
            CHECK(a == wm_angle_q16(dot, cross));
            CHECK(ab >= a);
            if (ab - a < worst) worst = ab - a;
        }
        CHECK(worst < 32); /* and close for small angles */
    }
}

/* R(v)'s eigen-decomposition (autocorr.c): a rank-one matrix n n^T, a diagonal one, a rotated one. */
static void test_eigen(void)
{
    int64_t a[6], lam[3], vec[9];
    const int64_t one = (int64_t)1 << 30;
    /* n = (0.6, 0, 0.8): n n^T has eigenvalues 0, 0, 1 and n as the third eigenvector */
    a[0] = one * 36 / 100, a[1] = 0, a[2] = one * 48 / 100, a[3] = 0, a[4] = 0, a[5] = one * 64 / 100;
    wm_sym3_eigen(a, lam, vec);
    CHECK(lam[0] > -64 && lam[0] < 64 && lam[1] > -64 && lam[1] < 64 && lam[2] > one - 64 && lam[2] < one + 64);
    CHECK((vec[6] > one * 6 / 10 - 64 && vec[6] < one * 6 / 10 + 64) ||
          (vec[6] < -one * 6 / 10 + 64 && vec[6] > -one * 6 / 10 - 64));
    /* diag(0.5, 0.125, 0.375): sorted, the vectors are the axes */
    a[0] = one / 2, a[1] = a[2] = a[4] = 0, a[3] = one / 8, a[5] = 3 * one / 8;
    wm_sym3_eigen(a, lam, vec);
    CHECK(lam[0] == one / 8 && lam[1] == 3 * one / 8 && lam[2] == one / 2);
    CHECK(vec[1] == one && vec[5] == one && vec[6] == one);
    /* [[0.5, 0.25], [0.25, 0.5]] (+ 0 on the third axis): 0, 0.25, 0.75 */
    a[0] = one / 2, a[1] = one / 4, a[2] = 0, a[3] = one / 2, a[4] = 0, a[5] = 0;
    wm_sym3_eigen(a, lam, vec);
    CHECK(lam[0] > -64 && lam[0] < 64 && lam[1] > one / 4 - 64 && lam[1] < one / 4 + 64);
    CHECK(lam[2] > 3 * one / 4 - 64 && lam[2] < 3 * one / 4 + 64);
}

/* Edge collapse (4.5.3) on a 9 x 9 square: the diagonal split at (4, 4) and (6, 6); the edge
 * (4, 4) - (6, 6) collapses at its midpoint (5, 5); corners never move; a half-edge collapse. */
static void test_edge_collapse(void)
{
    wm_mesh m;
    int32_t touched[6 * WM_MAX_RING], tris[6 * WM_MAX_RING], nt, n, p, e;
    CHECK(square(&m, 9, 9, 64) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 8, 8), 4, 4, NULL, NULL) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 4, 4, 8, 8), 6, 6, NULL, NULL) == WM_OK);
    CHECK(m.n_tri == 6 && m.n_vert == 6);
    e = find_edge(&m, 4, 4, 6, 6);
    CHECK(wm_edge_collapse_plan(&m, e, 5, 5, tris, &nt) == WM_OK && nt == 4);
    CHECK(wm_edge_collapse_plan(&m, e, 5, 4, tris, &nt) == WM_ERR_ARG); /* not on the edge */
    CHECK(wm_edge_collapse(&m, e, 5, 5, touched, &n, &p) == WM_OK && n == 4);
    CHECK(m.n_tri == 4 && m.n_vert == 5 && m.vxy[p].x == 5 && m.vxy[p].y == 5 && wm_mesh_check(&m) == WM_OK);
    CHECK(find_vertex(&m, 4, 4) < 0 && find_vertex(&m, 6, 6) < 0);
    /* (5, 5) - (8, 0): a corner does not move, so only the half-edge collapse into it */
    e = find_edge(&m, 5, 5, 8, 0);
    CHECK(e >= 0 && wm_edge_collapse_plan(&m, e, 5, 5, tris, &nt) == WM_ERR_REFUSED);
    CHECK(wm_edge_collapse(&m, e, 8, 0, touched, &n, NULL) == WM_OK && n == 2);
    CHECK(m.n_tri == 2 && m.n_vert == 4 && wm_mesh_check(&m) == WM_OK);
}

/* The O(h log h) hole triangulation (reduce.c) against the polygon: n - 2 counter-clockwise
 * triangles whose doubled areas add up to the ring's. */
static void test_star_plan(void)
{
    wm_mesh m;
    int32_t ring[WM_MAX_RING], tris[3 * WM_MAX_RING], n, nt, v;
    int64_t area = 0, ring_area = 0;
    CHECK(square(&m, 9, 9, 64) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 8, 8), 4, 4, NULL, NULL) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 0, 0, 8, 0), 4, 0, NULL, NULL) == WM_OK);
    CHECK(wm_edge_split(&m, find_edge(&m, 8, 0, 8, 8), 8, 5, NULL, NULL) == WM_OK);
    v = find_vertex(&m, 4, 4);
    n = wm_vertex_ring(&m, v, ring);
    CHECK(n == 6);
    CHECK(wm_star_plan(&m, ring, n, 4, 4, tris, &nt) == WM_OK && nt == n - 2);
    for (int32_t j = 0; j < nt; j++) {
        int32_t a = tris[3 * j], b = tris[3 * j + 1], c = tris[3 * j + 2];
        int64_t o = wm_orient(m.vxy[a].x, m.vxy[a].y, m.vxy[b].x, m.vxy[b].y, m.vxy[c].x, m.vxy[c].y);
        CHECK(o > 0);
        area += o;
    }
    for (int32_t i = 1; i + 1 < n; i++)
        ring_area += wm_orient(m.vxy[ring[0]].x, m.vxy[ring[0]].y, m.vxy[ring[i]].x, m.vxy[ring[i]].y,
                               m.vxy[ring[i + 1]].x, m.vxy[ring[i + 1]].y);
    CHECK(area == ring_area);
    CHECK(wm_vertex_remove(&m, v, tris, nt, NULL, NULL) == WM_OK && wm_mesh_check(&m) == WM_OK);
}

/* Step 2(d) on a plane: every vertex but the corners goes (4.32 holds everywhere, E(T) = 0). */
static void test_reduce_plane(void)
{
    static uint16_t z[17 * 17];
    static int32_t det[3 * 9 * 9 + 3 * 5 * 5];
    wm_field f;
    wm_params p;
    wm_refiner *r;
    wm_level_stats st;
    int32_t xy[2 * 9], tris[3 * 8], k = 0;
    for (int32_t y = 0; y < 17; y++)
        for (int32_t x = 0; x < 17; x++) z[y * 17 + x] = (uint16_t)(1000 + 7 * x + 3 * y);
    /* a 3 x 3 lattice of vertices at 0, 8, 16, each square cut by the same diagonal */
    for (int32_t y = 0; y < 3; y++)
        for (int32_t x = 0; x < 3; x++) xy[2 * (3 * y + x)] = 8 * x, xy[2 * (3 * y + x) + 1] = 8 * y;
    for (int32_t y = 0; y < 2; y++)
        for (int32_t x = 0; x < 2; x++) {
            int32_t a = 3 * y + x, b = a + 1, c = a + 3, d = a + 4;
            tris[k++] = a, tris[k++] = b, tris[k++] = d;
            tris[k++] = a, tris[k++] = d, tris[k++] = c;
        }
    CHECK(wm_haar(z, 17, 17, 2, det, (uint16_t *)scratch) == WM_OK);
    f.width = f.height = 17, f.levels = 2, f.samples = z, f.details = det, f.mask = NULL;
    memset(&p, 0, sizeof p);
    p.metric = WM_METRIC_NORMAL, p.iterations = 1, p.scale_m = 32768, p.scale_e = 15;
    p.delta_p = 58982, p.alpha = 39322, p.delta_v = 2u << 16, p.delta_lambda = 655, p.delta_c = 64225;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 9, tris, 8, 600) == WM_OK);
    wm_refine_stats(r, &st);
    CHECK(st.removals == 5 && st.triangles == 2 && st.vertices == 4 && st.e_max == 0);
    CHECK(wm_mesh_check(wm_refine_mesh(r)) == WM_OK);
    /* without the reduction nothing goes */
    p.flags = WM_FLAG_NO_REDUCE;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 9, tris, 8, 600) == WM_OK);
    wm_refine_stats(r, &st);
    CHECK(st.removals == 0 && st.triangles == 8);
    /* delta_c out of range */
    p.delta_c = 65537;
    CHECK(wm_refine_init(&r, mem, sizeof mem, &f, &p, xy, 9, tris, 8, 600) == WM_ERR_ARG);
}

/* The board's clamp, wm_tri_cap_skewed: the smallest capacity from the grid's for which 2 vert_cap rounded
 * up to 8 bytes lies 1 to 7 KiB past a multiple of 8 KiB, never above its limit.  The laid-out mesh's vxy
 * follows vh by vh's bytes rounded up to 8; on a power-of-two grid (32-bit indices) that is within 1 KiB
 * of a multiple of 8 KiB with the grid's own capacity (a vertex's vh and vxy on one line index of a
 * direct-mapped cache) and 1 to 7 KiB past one with the skewed capacity (the clamp's reason). */
static void test_cap_skewed(void)
{
    static const int32_t sides[] = {2, 3, 64, 100, 128, 255};
    wm_mesh m;
    for (size_t i = 0; i < sizeof sides / sizeof sides[0]; i++) {
        int32_t w = sides[i], cap = wm_tri_cap_max(w, w), vc = wm_vert_cap_for(w, w, cap);
        int32_t c = wm_tri_cap_skewed(w, w, cap, cap + 10000);
        size_t r = (((size_t)2 * (size_t)wm_vert_cap_for(w, w, c) + 7u) & ~(size_t)7u) % 8192u;
        CHECK(c >= cap && c - cap <= 8192 && c % 2 == cap % 2 && r >= 1024u && r <= 8192u - 1024u);
        for (int32_t d = cap; d < c; d += 2) { /* the smallest such */
            size_t q = (((size_t)2 * (size_t)wm_vert_cap_for(w, w, d) + 7u) & ~(size_t)7u) % 8192u;
            CHECK(q < 1024u || q > 8192u - 1024u);
        }
        CHECK(wm_tri_cap_skewed(w, w, cap, cap) == cap); /* never above limit */
        if (wm_mesh_bound(cap, vc) == 0) continue; /* beyond 16-bit indices */
        CHECK(wm_mesh_init(&m, mem, sizeof mem, w, w, cap, vc) == WM_OK);
        CHECK((size_t)((const uint8_t *)(const void *)m.vxy - (const uint8_t *)(const void *)m.vh) ==
              (((size_t)sizeof(wm_index) * (size_t)vc + 7u) & ~(size_t)7u));
        if (sizeof(wm_index) == 4 && (w & (w - 1)) == 0 && w >= 64) {
            size_t d0 = (((size_t)4 * (size_t)vc + 7u) & ~(size_t)7u) % 8192u;
            size_t d = (((size_t)4 * (size_t)wm_vert_cap_for(w, w, c) + 7u) & ~(size_t)7u) % 8192u;
            CHECK(d0 < 1024u || d0 > 8192u - 1024u);
            CHECK(d >= 1024u && d <= 8192u - 1024u);
        }
    }
}

int main(void)
{
    test_build();
    test_cap_skewed();
    test_edge_split();
    test_tri_split();
    test_edge_swap();
    test_vertex_move();
    test_fixed();
    test_error();
    test_haar();
    test_refine();
    test_vertex_remove();
    test_orient();
    test_incircle();
    test_eigen();
    test_edge_collapse();
    test_star_plan();
    test_reduce_plane();
    printf("%d passed, %d failed\n", passed, failed);
    return failed ? 1 : 0;
}
