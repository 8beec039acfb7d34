/*
 * wavemesh: the triangle error engine, E(T)'s scan of a triangle's samples in hardware
 *
 * For one triangle (three grid vertices p_k, counter-clockwise, twice the area D > 0, the corner
 * heights z_k) it walks the samples of the closed triangle row by row, x ascending in each row, and
 * returns the largest
 *
 *     V(p) = | E_0(p) z_0 + E_1(p) z_1 + E_2(p) z_2 - D h(p) |
 *
 * and the first sample reaching it (a later sample replaces it only when strictly greater), exactly
 * what firmware/src/tri_error.c's scan returns (wavemesh.model.tri_scan.scan the Python model).  E_k is
 * the edge function orient(p_k+1, p_k+2, p) = A_k x + B_k y + C_k (>= 0 inside, E_0 + E_1 + E_2 =
 * D).  With a limit it stops at the first sample whose V exceeds it and returns that V and sample
 * (wm_tri_error_within's early exit: the caller only learns that E(T) is above its bound).  The
 * division and the slope factor that turn Vmax into E(T) stay with the CPU.
 *
 * What the CPU hands in per triangle: the vertices, the corner heights (it has them: the normal
 * metric's slope factor reads them too) and the limit.  Everything else the engine derives, since
 * the soft CPU pays 5-7 cycles per instruction and dozens per 64-bit product: A_k, B_k, the edge
 * values at the bounding box's corner (two products each), D = E_0 + E_1 + E_2 there, the plane
 * numerator S = sum E_k z_k and its steps along x and y (products with z_k), the row's address.
 *
 *   cmd FIFO -> set-up (6 clocks) -> row spans -> span FIFO -> read requests -> pending FIFO
 *                                                                   |               |
 *                            heights (the memory's response) -> V pipeline (3 stages) -> Vmax, (wx, wy)
 *
 * Row span (rows ymin..ymax): the C takes lo = max(xmin, ceil(-n_k / A_k) over A_k > 0) and hi =
 * min(xmax, floor(n_k / -A_k) over A_k < 0), n_k = B_k y + C_k, and drops the row when an edge with
 * A_k = 0 has n_k < 0 or lo > hi.  Here both bounds come from a binary search over the row without
 * a divider: from x = xmin - 1, bit j from the highest bit of xmax - xmin + 1 down, a step of 2^j
 * is taken when every lower edge (A_k > 0) is still negative there (lo) or every upper edge (A_k <
 * 0) is still >= 0 there (hi), the edge values moving by A_k 2^j (shifts and adds; the predicates
 * are monotone in x, so the search is exact).  S moves with the lower search, so S(lo) comes out
 * too.  A row's span costs 2 + bits clocks and is found while the rows before it stream.
 *
 * Memory: one read request (sample address base + y W + lo, length hi - lo + 1) per row span; the
 * response is that many 16-bit samples in order, on a valid/ready stream (soc_top feeds it from the
 * SDRAM controller's stream reader).  A request waits for the response of the one before only in
 * the memory; the engine keeps up to two requests' positions.  Every sample is taken in the clock
 * it arrives (the response's ready is high while a span is open, and the next span opens in the
 * clock of the last one's last sample), so the engine runs at the memory's rate, one sample per
 * clock, across rows too when the memory answers back-to-back requests without a gap (the SDRAM
 * controller's stream reader takes the next one while the last one's samples stream).  An early exit issues no further request and takes
 * (drops) the samples of those already issued.
 *
 * Arithmetic: grid coordinates of COORD_BITS bits (W, H <= 2^COORD_BITS); edge values in EW = 2
 * COORD_BITS + 4 bits (every point the search visits); S, D h and V modulo 2^VW, VW = 2 COORD_BITS
 * + 18: V < 2^16 D <= 2^(VW-1), so S - D h taken modulo 2^VW is V with its sign, as scan32 takes
 * it modulo 2^32.  The limit is 64 bits as the C's (saturated to VW bits inside).
 *
 * Command beat (s_cmd_*): x0 y0 x1 y1 x2 y2 (COORD_BITS each, unsigned), z0 z1 z2 (16 each), limit
 * (64).  Result beat (m_res_*): vmax (VW bits), x, y of the sample (COORD_BITS each); with a limit,
 * vmax > limit says the scan stopped there.  The result of the commands comes out in their order.
 *
 * Timing per triangle: 1 clock to take the command, 6 of set-up, then per row 2 + bits clocks of
 * search (overlapping the samples of earlier rows), the memory's latency (in the SoC a row whose request
 * is out before the last row's reads are issued adds none: its reads follow them), one clock per sample in the V
 * pipeline, 3 clocks of pipeline and 1 to hand out the result.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tri_engine #
(
    // grid coordinate bits: W, H <= 2^COORD_BITS; 2..15
    parameter COORD_BITS = 11,
    // sample address bits of the read port (base + y W + x, in samples); COORD_BITS + 2 .. 32
    parameter ADDR_BITS = 24,
    // commands queued before the engine takes them; >= 1
    parameter CMD_DEPTH = 4,
    // results held until the CPU takes them; >= 1
    parameter RES_DEPTH = 2,
    // row spans found ahead of their read requests; >= 1
    parameter SPAN_DEPTH = 2
)
(
    input  wire                         clk,
    input  wire                         rst,

    /*
     * Configuration (hold while busy)
     */
    input  wire [ADDR_BITS-1:0]         cfg_base,       // sample address of (0, 0)
    input  wire [COORD_BITS:0]          cfg_width,      // W, samples per row

    /*
     * Commands: one triangle each
     */
    input  wire [3*COORD_BITS-1:0]      s_cmd_x,        // {x2, x1, x0}
    input  wire [3*COORD_BITS-1:0]      s_cmd_y,        // {y2, y1, y0}
    input  wire [47:0]                  s_cmd_z,        // {z2, z1, z0}, the corner heights
    input  wire [63:0]                  s_cmd_limit,    // stop at the first V > limit
    input  wire                         s_cmd_valid,
    output wire                         s_cmd_ready,

    /*
     * Results: one per command, in order
     */
    output wire [2*COORD_BITS+17:0]     m_res_vmax,
    output wire [COORD_BITS-1:0]        m_res_x,
    output wire [COORD_BITS-1:0]        m_res_y,
    output wire                         m_res_valid,
    input  wire                         m_res_ready,

    /*
     * Memory: read requests (a row span) and their samples, in order
     */
    output wire [ADDR_BITS-1:0]         m_rd_addr,
    output wire [COORD_BITS:0]          m_rd_len,
    output wire                         m_rd_valid,
    input  wire                         m_rd_ready,
    input  wire [15:0]                  s_rd_data,
    input  wire                         s_rd_valid,
    output wire                         s_rd_ready,

    /*
     * Status
     */
    output wire                         busy            // a command queued or in work, a result unread
);

localparam CB = COORD_BITS;
localparam EW = 2 * CB + 4;     // edge values, signed
localparam VW = 2 * CB + 18;    // S, D h, V modulo 2^VW
localparam JB = $clog2(CB + 1); // search bit index 0..CB
localparam CMD_W = 6 * CB + 48 + VW;
localparam RES_W = VW + 2 * CB;
// span: {S at lo (VW), y (CB), lo (CB), len (CB+1), address}
localparam SPAN_W = VW + 3 * CB + 1 + ADDR_BITS;
localparam PEND_W = VW + 2 * CB + CB + 1;

// check configuration
initial begin
    if (COORD_BITS < 2 || COORD_BITS > 15) begin
        $error("Error: COORD_BITS must be 2..15 (instance %m)");
        $finish;
    end
    if (ADDR_BITS < COORD_BITS + 2 || ADDR_BITS > 32) begin
        $error("Error: ADDR_BITS must be COORD_BITS + 2 .. 32 (instance %m)");
        $finish;
    end
    if (CMD_DEPTH < 1 || RES_DEPTH < 1 || SPAN_DEPTH < 1) begin
        $error("Error: CMD_DEPTH, RES_DEPTH and SPAN_DEPTH must be at least 1 (instance %m)");
        $finish;
    end
end

/*
 * Command FIFO (the limit saturated to VW bits on the way in: every V is below 2^(VW-1))
 */
wire [VW-1:0] limit_sat = |s_cmd_limit[63:VW] ? {VW{1'b1}} : s_cmd_limit[VW-1:0];
wire [CMD_W-1:0] cmd_data;
wire cmd_valid;
reg  cmd_ready;
wire [$clog2(CMD_DEPTH+1)-1:0] cmd_count_unused;

wm_fifo #(
    .DATA_WIDTH(CMD_W),
    .DEPTH(CMD_DEPTH)
) cmd_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data({limit_sat, s_cmd_z, s_cmd_y, s_cmd_x}),
    .s_valid(s_cmd_valid),
    .s_ready(s_cmd_ready),
    .m_data(cmd_data),
    .m_valid(cmd_valid),
    .m_ready(cmd_ready),
    .count(cmd_count_unused)
);

/*
 * Set-up and row spans
 */
localparam [3:0]
    ST_IDLE = 4'd0,     // waiting for a command
    ST_BOX = 4'd1,      // bounding box, A_k, B_k
    ST_EDGE = 4'd2,     // k = 0..2: E_k at (xmin - 1, ymin), dS, dSy
    ST_PLANE = 4'd3,    // k = 0..2: S at (xmin - 1, ymin), D; the first row's address, the search bits
    ST_SEARCH = 4'd4,   // bit j of the row's lo and hi
    ST_PUSH = 4'd5,     // the row's span into the span FIFO, then the next row
    ST_DRAIN = 4'd6,    // every request answered, every sample through the pipeline
    ST_RESULT = 4'd7;   // the result into the result FIFO

reg [3:0] state_reg = ST_IDLE, state_next;
reg [1:0] k_reg = 2'd0, k_next;
reg [JB-1:0] j_reg = {JB{1'b0}}, j_next;
reg [JB-1:0] jtop_reg = {JB{1'b0}}, jtop_next;

// the triangle
reg [CB-1:0] x0_reg = 0, x1_reg = 0, x2_reg = 0, y0_reg = 0, y1_reg = 0, y2_reg = 0;
reg [15:0] z0_reg = 0, z1_reg = 0, z2_reg = 0;
reg [VW-1:0] limit_reg = {VW{1'b0}};
reg [CB-1:0] xmin_reg = 0, ymin_reg = 0, ymax_reg = 0;
reg signed [CB:0] a0_reg = 0, a1_reg = 0, a2_reg = 0, b0_reg = 0, b1_reg = 0, b2_reg = 0;
reg [CB:0] n_reg = 0;   // xmax - xmin + 1: the search's range
// edge values at (xmin - 1, y) for the row (r) and at the search's positions (e)
reg signed [EW-1:0] r0_reg = 0, r0_next, r1_reg = 0, r1_next, r2_reg = 0, r2_next;
reg signed [EW-1:0] e0_reg = 0, e0_next, e1_reg = 0, e1_next, e2_reg = 0, e2_next;
reg [VW-1:0] ds_reg = 0, ds_next;     // S step along x: sum A_k z_k
reg [VW-1:0] dsy_reg = 0, dsy_next;   // along y: sum B_k z_k
reg [VW-1:0] sr_reg = 0, sr_next;     // S at (xmin - 1, y)
reg [VW-1:0] s_reg = 0, s_next;       // S at the lower search's position
reg [VW-1:0] d_reg = 0, d_next;       // D (< 2^(2 CB + 1))
reg [CB-1:0] py_reg = 0, py_next;
reg [ADDR_BITS-1:0] row_reg = 0, row_next;   // address of (0, y)
reg [CB:0] t_reg = 0, t_next;   // lower search: lo = xmin + t
reg [CB:0] u_reg = 0, u_next;   // upper search: hi = xmin - 1 + u

reg span_valid;
wire span_ready;

// the sample pipeline's state the control reads
reg [VW-1:0] vmax_reg = {VW{1'b0}};
reg [CB-1:0] wx_reg = 0, wy_reg = 0;
reg stop_reg = 1'b0;
wire drained;
reg res_valid;
wire res_ready;

// per-k selections for the set-up products
reg signed [CB:0] ak, bk;
reg signed [CB+1:0] dxk, dyk;
reg [15:0] zk;
reg signed [EW-1:0] rk;
always @* begin
    case (k_reg)
        2'd0: begin ak = a0_reg; bk = b0_reg; zk = z0_reg; rk = r0_reg;
            dxk = $signed({2'b00, xmin_reg}) - 1 - $signed({2'b00, x1_reg});
            dyk = $signed({2'b00, ymin_reg}) - $signed({2'b00, y1_reg}); end
        2'd1: begin ak = a1_reg; bk = b1_reg; zk = z1_reg; rk = r1_reg;
            dxk = $signed({2'b00, xmin_reg}) - 1 - $signed({2'b00, x2_reg});
            dyk = $signed({2'b00, ymin_reg}) - $signed({2'b00, y2_reg}); end
        default: begin ak = a2_reg; bk = b2_reg; zk = z2_reg; rk = r2_reg;
            dxk = $signed({2'b00, xmin_reg}) - 1 - $signed({2'b00, x0_reg});
            dyk = $signed({2'b00, ymin_reg}) - $signed({2'b00, y0_reg}); end
    endcase
end

// E_k(xmin - 1, ymin) = A_k (xmin - 1 - x_k1) + B_k (ymin - y_k1)
wire signed [EW-1:0] ek_box = $signed({{(EW-CB-1){ak[CB]}}, ak}) * $signed({{(EW-CB-2){dxk[CB+1]}}, dxk})
                            + $signed({{(EW-CB-1){bk[CB]}}, bk}) * $signed({{(EW-CB-2){dyk[CB+1]}}, dyk});
// products modulo 2^VW
wire [VW-1:0] az_k = {{(VW-CB-1){ak[CB]}}, ak} * {{(VW-16){1'b0}}, zk};
wire [VW-1:0] bz_k = {{(VW-CB-1){bk[CB]}}, bk} * {{(VW-16){1'b0}}, zk};
wire [VW-1:0] rz_k = {{(VW-EW){rk[EW-1]}}, rk} * {{(VW-16){1'b0}}, zk};
wire [ADDR_BITS-1:0] row_first = cfg_base
    + {{ADDR_BITS-CB{1'b0}}, ymin_reg} * {{ADDR_BITS-CB-1{1'b0}}, cfg_width};

// the highest bit of n: the search's first step
function [JB-1:0] top_bit(input [CB:0] n);
    integer b;
    begin
        top_bit = {JB{1'b0}};
        for (b = 0; b <= CB; b = b + 1) begin
            if (n[b]) top_bit = b[JB-1:0];
        end
    end
endfunction

// one search step: the candidates and the edge values there
wire [CB:0] step = {{CB{1'b0}}, 1'b1} << j_reg;
wire signed [EW-1:0] a0_step = $signed({{(EW-CB-1){a0_reg[CB]}}, a0_reg}) <<< j_reg;
wire signed [EW-1:0] a1_step = $signed({{(EW-CB-1){a1_reg[CB]}}, a1_reg}) <<< j_reg;
wire signed [EW-1:0] a2_step = $signed({{(EW-CB-1){a2_reg[CB]}}, a2_reg}) <<< j_reg;
wire signed [EW-1:0] e0_cand = e0_reg + a0_step;
wire signed [EW-1:0] e1_cand = e1_reg + a1_step;
wire signed [EW-1:0] e2_cand = e2_reg + a2_step;
wire lower0 = a0_reg > 0, lower1 = a1_reg > 0, lower2 = a2_reg > 0;
wire upper0 = a0_reg < 0, upper1 = a1_reg < 0, upper2 = a2_reg < 0;
// inside every lower edge at the candidate (lo <= candidate), every upper edge (hi >= candidate)
wire in_lower = (!lower0 || !e0_cand[EW-1]) && (!lower1 || !e1_cand[EW-1]) && (!lower2 || !e2_cand[EW-1]);
wire in_upper = (!upper0 || !e0_cand[EW-1]) && (!upper1 || !e1_cand[EW-1]) && (!upper2 || !e2_cand[EW-1]);
wire [CB:0] t_cand = t_reg + step;
wire [CB:0] u_cand = u_reg + step;
wire take_lo = t_cand <= n_reg && !in_lower;
wire take_hi = u_cand <= n_reg && in_upper;

// the row's span
wire [CB:0] len = u_reg - t_reg;           // hi - lo + 1 = u - t when not empty
// an edge parallel to the rows excludes the whole row when negative
wire flat_out = (a0_reg == 0 && r0_reg[EW-1]) || (a1_reg == 0 && r1_reg[EW-1]) || (a2_reg == 0 && r2_reg[EW-1]);
wire row_empty = flat_out || u_reg <= t_reg;
wire [CB-1:0] lo_x = xmin_reg + t_reg[CB-1:0];   // lo (t = n only in an empty row)
wire [ADDR_BITS-1:0] span_addr = row_reg + {{ADDR_BITS-CB{1'b0}}, lo_x};
wire [SPAN_W-1:0] span_data = {s_reg + ds_reg, py_reg, lo_x, len, span_addr};

always @* begin
    state_next = state_reg;
    k_next = k_reg;
    j_next = j_reg;
    jtop_next = jtop_reg;
    r0_next = r0_reg; r1_next = r1_reg; r2_next = r2_reg;
    e0_next = e0_reg; e1_next = e1_reg; e2_next = e2_reg;
    ds_next = ds_reg;
    dsy_next = dsy_reg;
    sr_next = sr_reg;
    s_next = s_reg;
    d_next = d_reg;
    py_next = py_reg;
    row_next = row_reg;
    t_next = t_reg;
    u_next = u_reg;
    cmd_ready = 1'b0;
    span_valid = 1'b0;
    res_valid = 1'b0;

    case (state_reg)
        ST_IDLE: begin
            // take the next triangle
            cmd_ready = 1'b1;
            if (cmd_valid) begin
                state_next = ST_BOX;
            end
        end
        ST_BOX: begin
            // bounding box and edges registered with the command; clear the sums
            ds_next = {VW{1'b0}};
            dsy_next = {VW{1'b0}};
            sr_next = {VW{1'b0}};
            d_next = {VW{1'b0}};
            k_next = 2'd0;
            state_next = ST_EDGE;
        end
        ST_EDGE: begin
            // edge k's value at (xmin - 1, ymin) and its share of the steps of S
            case (k_reg)
                2'd0: r0_next = ek_box;
                2'd1: r1_next = ek_box;
                default: r2_next = ek_box;
            endcase
            ds_next = ds_reg + az_k;
            dsy_next = dsy_reg + bz_k;
            k_next = k_reg == 2'd2 ? 2'd0 : k_reg + 2'd1;
            if (k_reg == 2'd2) begin
                state_next = ST_PLANE;
            end
        end
        ST_PLANE: begin
            // S = sum E_k z_k and D = sum E_k at (xmin - 1, ymin)
            sr_next = sr_reg + rz_k;
            d_next = d_reg + {{(VW-EW){rk[EW-1]}}, rk};
            k_next = k_reg == 2'd2 ? 2'd0 : k_reg + 2'd1;
            if (k_reg == 2'd2) begin
                // the first row
                py_next = ymin_reg;
                row_next = row_first;
                jtop_next = top_bit(n_reg);
                j_next = top_bit(n_reg);
                e0_next = r0_reg; e1_next = r1_reg; e2_next = r2_reg;
                s_next = sr_next;
                t_next = {(CB+1){1'b0}};
                u_next = {(CB+1){1'b0}};
                state_next = ST_SEARCH;
            end
        end
        ST_SEARCH: begin
            // a step of 2^j for each bound where it stays outside (lo) or inside (hi)
            if (take_lo) begin
                t_next = t_cand;
                s_next = s_reg + (ds_reg << j_reg);
            end
            if (take_hi) begin
                u_next = u_cand;
            end
            if ((lower0 && take_lo) || (upper0 && take_hi)) e0_next = e0_cand;
            if ((lower1 && take_lo) || (upper1 && take_hi)) e1_next = e1_cand;
            if ((lower2 && take_lo) || (upper2 && take_hi)) e2_next = e2_cand;
            j_next = j_reg - 1'b1;
            if (j_reg == {JB{1'b0}}) begin
                state_next = ST_PUSH;
            end
        end
        ST_PUSH: begin
            // lo = xmin + t, hi = xmin - 1 + u: a span when lo <= hi, then the next row
            span_valid = !row_empty && !stop_reg;
            if (stop_reg || row_empty || span_ready) begin
                if (stop_reg || py_reg == ymax_reg) begin
                    state_next = ST_DRAIN;
                end else begin
                    py_next = py_reg + 1'b1;
                    row_next = row_reg + {{ADDR_BITS-CB-1{1'b0}}, cfg_width};
                    r0_next = r0_reg + {{(EW-CB-1){b0_reg[CB]}}, b0_reg};
                    r1_next = r1_reg + {{(EW-CB-1){b1_reg[CB]}}, b1_reg};
                    r2_next = r2_reg + {{(EW-CB-1){b2_reg[CB]}}, b2_reg};
                    e0_next = r0_next; e1_next = r1_next; e2_next = r2_next;
                    sr_next = sr_reg + dsy_reg;
                    s_next = sr_next;
                    t_next = {(CB+1){1'b0}};
                    u_next = {(CB+1){1'b0}};
                    j_next = jtop_reg;
                    state_next = ST_SEARCH;
                end
            end
        end
        ST_DRAIN: begin
            // every span requested (or dropped after a stop) and every sample through
            if (drained) begin
                state_next = ST_RESULT;
            end
        end
        default: begin
            // ST_RESULT: hand the result out
            res_valid = 1'b1;
            if (res_ready) begin
                state_next = ST_IDLE;
            end
        end
    endcase
end

always @(posedge clk) begin
    state_reg <= state_next;
    k_reg <= k_next;
    j_reg <= j_next;
    jtop_reg <= jtop_next;
    r0_reg <= r0_next; r1_reg <= r1_next; r2_reg <= r2_next;
    e0_reg <= e0_next; e1_reg <= e1_next; e2_reg <= e2_next;
    ds_reg <= ds_next;
    dsy_reg <= dsy_next;
    sr_reg <= sr_next;
    s_reg <= s_next;
    d_reg <= d_next;
    py_reg <= py_next;
    row_reg <= row_next;
    t_reg <= t_next;
    u_reg <= u_next;

    if (state_reg == ST_IDLE && cmd_valid) begin
        // the command's fields
        {limit_reg, z2_reg, z1_reg, z0_reg, y2_reg, y1_reg, y0_reg, x2_reg, x1_reg, x0_reg} <= cmd_data;
    end
    if (state_reg == ST_BOX) begin
        // A_k = y_k1 - y_k2, B_k = x_k2 - x_k1 (k1 = k + 1, k2 = k + 2 mod 3), the box
        a0_reg <= $signed({1'b0, y1_reg}) - $signed({1'b0, y2_reg});
        a1_reg <= $signed({1'b0, y2_reg}) - $signed({1'b0, y0_reg});
        a2_reg <= $signed({1'b0, y0_reg}) - $signed({1'b0, y1_reg});
        b0_reg <= $signed({1'b0, x2_reg}) - $signed({1'b0, x1_reg});
        b1_reg <= $signed({1'b0, x0_reg}) - $signed({1'b0, x2_reg});
        b2_reg <= $signed({1'b0, x1_reg}) - $signed({1'b0, x0_reg});
        xmin_reg <= min3(x0_reg, x1_reg, x2_reg);
        ymin_reg <= min3(y0_reg, y1_reg, y2_reg);
        ymax_reg <= max3(y0_reg, y1_reg, y2_reg);
        n_reg <= {1'b0, max3(x0_reg, x1_reg, x2_reg)} - {1'b0, min3(x0_reg, x1_reg, x2_reg)} + 1'b1;
    end

    if (rst) begin
        state_reg <= ST_IDLE;
        k_reg <= 2'd0;
        j_reg <= {JB{1'b0}};
    end
end

function [CB-1:0] min3(input [CB-1:0] a, input [CB-1:0] b, input [CB-1:0] c);
    begin
        min3 = a < b ? (a < c ? a : c) : (b < c ? b : c);
    end
endfunction

function [CB-1:0] max3(input [CB-1:0] a, input [CB-1:0] b, input [CB-1:0] c);
    begin
        max3 = a > b ? (a > c ? a : c) : (b > c ? b : c);
    end
endfunction

/*
 * Span FIFO, read requests, pending FIFO
 */
wire [SPAN_W-1:0] span_out;
wire span_out_valid;
reg  span_out_ready;
wire [$clog2(SPAN_DEPTH+1)-1:0] span_count_unused;

wm_fifo #(
    .DATA_WIDTH(SPAN_W),
    .DEPTH(SPAN_DEPTH)
) span_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(span_data),
    .s_valid(span_valid),
    .s_ready(span_ready),
    .m_data(span_out),
    .m_valid(span_out_valid),
    .m_ready(span_out_ready),
    .count(span_count_unused)
);

// the request register: held until the memory takes it (also after a stop: its samples are dropped)
reg rq_valid_reg = 1'b0;
reg [SPAN_W-1:0] rq_reg = {SPAN_W{1'b0}};
wire pend_ready;
wire rq_take = rq_valid_reg && pend_ready && m_rd_ready;

assign m_rd_valid = rq_valid_reg && pend_ready;   // pend_ready falls only when this pushes
assign m_rd_addr = rq_reg[ADDR_BITS-1:0];
assign m_rd_len = rq_reg[ADDR_BITS +: CB+1];

always @* begin
    // load the next span when the register is free; after a stop, drop the spans instead
    span_out_ready = (!rq_valid_reg || rq_take) || stop_reg;
end

always @(posedge clk) begin
    if (span_out_valid && span_out_ready && !stop_reg) begin
        rq_valid_reg <= 1'b1;
        rq_reg <= span_out;
    end else if (rq_take) begin
        rq_valid_reg <= 1'b0;
    end
    if (rst) begin
        rq_valid_reg <= 1'b0;
    end
end

// pending: {S at lo, y, lo, len} of every request issued, in order
wire [PEND_W-1:0] pend_out;
wire pend_valid;
reg  pend_pop;
wire [1:0] pend_count_unused;

wm_fifo #(
    .DATA_WIDTH(PEND_W),
    .DEPTH(2)
) pend_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(rq_reg[SPAN_W-1:ADDR_BITS]),
    .s_valid(rq_take),
    .s_ready(pend_ready),
    .m_data(pend_out),
    .m_valid(pend_valid),
    .m_ready(pend_pop),
    .count(pend_count_unused)
);

/*
 * Samples: the open span, then the V pipeline (D h; V = |S - D h|; the maximum)
 */
reg act_reg = 1'b0;                 // a span is open: its samples are taken as they come
reg [CB:0] left_reg = 0;            // samples of it still to come
reg [CB-1:0] cx_reg = 0, cy_reg = 0;
reg [VW-1:0] cs_reg = 0;

assign s_rd_ready = act_reg;
wire rd_take = s_rd_valid && act_reg;

always @* begin
    // the next span opens when none is open or in the clock of the open one's last sample
    pend_pop = pend_valid && (!act_reg || (rd_take && left_reg == {{CB{1'b0}}, 1'b1}));
end

reg p1_valid_reg = 1'b0, p2_valid_reg = 1'b0, p3_valid_reg = 1'b0;
reg [15:0] p1_h_reg = 0;
reg [VW-1:0] p1_s_reg = 0, p2_s_reg = 0, p2_dh_reg = 0, p3_v_reg = 0;
reg [CB-1:0] p1_x_reg = 0, p1_y_reg = 0, p2_x_reg = 0, p2_y_reg = 0, p3_x_reg = 0, p3_y_reg = 0;

wire [VW-1:0] dh = d_reg * {{(VW-16){1'b0}}, p1_h_reg};
wire [VW-1:0] diff = p2_s_reg - p2_dh_reg;
wire [VW-1:0] absdiff = diff[VW-1] ? {VW{1'b0}} - diff : diff;

always @(posedge clk) begin
    if (pend_pop) begin
        // open the next span (also in the clock of the last one's last sample)
        act_reg <= 1'b1;
        {cs_reg, cy_reg, cx_reg, left_reg} <= pend_out;
    end else if (rd_take) begin
        // one sample: on to the next
        cs_reg <= cs_reg + ds_reg;
        cx_reg <= cx_reg + 1'b1;
        left_reg <= left_reg - 1'b1;
        if (left_reg == {{CB{1'b0}}, 1'b1}) act_reg <= 1'b0;
    end

    p1_valid_reg <= rd_take;
    p1_h_reg <= s_rd_data;
    p1_s_reg <= cs_reg;
    p1_x_reg <= cx_reg;
    p1_y_reg <= cy_reg;

    p2_valid_reg <= p1_valid_reg;
    p2_dh_reg <= dh;
    p2_s_reg <= p1_s_reg;
    p2_x_reg <= p1_x_reg;
    p2_y_reg <= p1_y_reg;

    p3_valid_reg <= p2_valid_reg;
    p3_v_reg <= absdiff;
    p3_x_reg <= p2_x_reg;
    p3_y_reg <= p2_y_reg;

    if (state_reg == ST_IDLE && cmd_valid) begin
        // a new triangle: the first corner until a sample beats V = 0
        vmax_reg <= {VW{1'b0}};
        wx_reg <= cmd_data[CB-1:0];
        wy_reg <= cmd_data[3*CB +: CB];
        stop_reg <= 1'b0;
    end else if (p3_valid_reg && !stop_reg && p3_v_reg > vmax_reg) begin
        // strictly greater replaces; above the limit the scan stops here
        vmax_reg <= p3_v_reg;
        wx_reg <= p3_x_reg;
        wy_reg <= p3_y_reg;
        if (p3_v_reg > limit_reg) stop_reg <= 1'b1;
    end

    if (rst) begin
        act_reg <= 1'b0;
        p1_valid_reg <= 1'b0;
        p2_valid_reg <= 1'b0;
        p3_valid_reg <= 1'b0;
        stop_reg <= 1'b0;
    end
end

assign drained = !span_out_valid && !rq_valid_reg && !pend_valid && !act_reg
    && !p1_valid_reg && !p2_valid_reg && !p3_valid_reg;

/*
 * Result FIFO
 */
wire [$clog2(RES_DEPTH+1)-1:0] res_count_unused;
wire res_out_valid;

wm_fifo #(
    .DATA_WIDTH(RES_W),
    .DEPTH(RES_DEPTH)
) res_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data({wy_reg, wx_reg, vmax_reg}),
    .s_valid(res_valid),
    .s_ready(res_ready),
    .m_data({m_res_y, m_res_x, m_res_vmax}),
    .m_valid(res_out_valid),
    .m_ready(m_res_ready),
    .count(res_count_unused)
);

assign m_res_valid = res_out_valid;
assign busy = cmd_valid || state_reg != ST_IDLE || res_out_valid;

endmodule

`resetall
