/*
 * wavemesh: one level of the integer 2D spline-wavelet filter bank (docs/model.md, "Filter bank";
 * host/wavemesh/model/spline.py is the specification, matched bit for bit)
 *
 * The interface, the stall rule (every register advances only when en is high) and the record
 * order (raster order of the blocks) are haar_level's, so haar_bank builds either (WAVELET).  Per
 * record (i, j), with h = [1, 3, 3, 1] on taps 2i-1 .. 2i+2 and g = [-1, 1] on 2i, 2i+1, every
 * index clamped into the level:
 *
 *     vertical, per input column c:   L[c] = a[2i-1,c] + 3 a[2i,c] + 3 a[2i+1,c] + a[2i+2,c]
 *                                     D[c] = a[2i+1,c] - a[2i,c]
 *     horizontal:  a  = (L[2j-1] + 3 L[2j] + 3 L[2j+1] + L[2j+2] + 32) >> 6
 *                  d1 = (L[2j+1] - L[2j] + 2) >>> 2
 *                  d2 = (D[2j-1] + 3 D[2j] + 3 D[2j+1] + D[2j+2] + 2) >>> 2
 *                  d3 = D[2j+1] - D[2j]
 *
 * Vertical filter: one line buffer word per column, {P, Q, R}, read and rewritten on every row:
 *
 *     row 0:           P = 4 v (a[-1] = a[0]),  Q = v
 *     odd row 2k+1:    P += 3 v,  R = v                  (P = a[2k-1] + 3 a[2k] + 3 a[2k+1], Q = a[2k])
 *     even row 2k+2:   L = P + v, D = R - Q: record row k's column out;  P = R + 3 v,  Q = v
 *
 * The last row completes the last record row at once when it is odd (L = P + 4 v, D = v - Q: the
 * two taps below are clamped to it).  When it is even (2k, k >= 1) it completes record row k - 1,
 * and record row k (L = a[2k-1] + 7 a[2k], D = 0) needs the same row: the level stores that L as P
 * and, after its last input, replays the row from the line buffer (the flush, one column per
 * enabled cycle).  So a level of odd height (>= 3) emits its last record row after its input, the
 * one burst of this bank (Haar emits every record while its input streams).  A level of one row
 * emits L = 8 v, D = 0 on row 0.
 *
 * Horizontal filter: the same recursion over the columns of a record row, in registers.  The last
 * column completes one record when it is odd and two when it is even (>= 2): the second waits one
 * enabled cycle in a holding register, where the next column (the first of the next row, or no
 * input) makes none.
 *
 * Pipeline (stage registers advance together with en):
 *
 *   in -> line buffer read (address: input column, or the flush column)
 *      -> stage 1: the token (sample, position flags); the block RAM's own read register
 *      -> stage r: the word registered; the writes of the two enabled cycles the read could not
 *                  see (at its own edge and the next: only a level one or two columns wide reads
 *                  a column again that soon) forwarded through registered selects; vertical
 *                  filter; line buffer write
 *      -> stage 2: L, D of a column; 3 L, 7 L, 3 D, 7 D
 *      -> stage t: the same; horizontal filter (one adder deep)
 *      -> stage 3: the record's sums; rounding and narrowing, combinational, into the bank's FIFOs
 *
 * Widths: P, L <= 8 * 65535 (19 bits unsigned); D, Q-differences 17 bits signed; the horizontal
 * sums <= 64 * 65535 (22 bits) and +-8 * 65535 (21 bits signed); every record field fits its
 * 16 / 18 bits (the model's bounds).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module spline_level #
(
    // Largest number of input columns (the previous level's width) this level accepts; >= 1
    parameter MAX_WIDTH = 512,
    // Largest number of input rows; >= 1
    parameter MAX_HEIGHT = 512,
    // Width of the input column counter in bits: $clog2(MAX_WIDTH), at least 1
    parameter X_WIDTH = 9,
    // Width of the input row counter in bits: $clog2(MAX_HEIGHT), at least 1
    parameter Y_WIDTH = 9
)
(
    input  wire                 clk,
    input  wire                 rst,

    /*
     * Control
     */
    input  wire                 en,         // the level advances (all its registers, together)
    input  wire                 start,      // load the frame's size: counters to the first sample
    input  wire [X_WIDTH-1:0]   cfg_wm1,    // input columns - 1 (held for the whole frame)
    input  wire [Y_WIDTH-1:0]   cfg_hm1,    // input rows - 1 (held for the whole frame)

    /*
     * Approximation input (taken when en && in_valid)
     */
    input  wire                 in_valid,
    input  wire [15:0]          in_data,
    output wire                 in_last,    // the next input is the last one of the frame

    /*
     * Record output (taken when en && rec_valid)
     */
    output wire                 rec_valid,
    output wire [15:0]          rec_a,
    output wire [17:0]          rec_d1,
    output wire [17:0]          rec_d2,
    output wire [17:0]          rec_d3
);

localparam WORD = 19 + 16 + 16;  // line buffer word {P, Q, R}

// check configuration
initial begin
    if (MAX_WIDTH < 1 || MAX_HEIGHT < 1) begin
        $error("Error: MAX_WIDTH and MAX_HEIGHT must be at least 1 (instance %m)");
        $finish;
    end
    if (X_WIDTH != (MAX_WIDTH > 1 ? $clog2(MAX_WIDTH) : 1) ||
            Y_WIDTH != (MAX_HEIGHT > 1 ? $clog2(MAX_HEIGHT) : 1)) begin
        $error("Error: X_WIDTH/Y_WIDTH must be $clog2 of MAX_WIDTH/MAX_HEIGHT, at least 1 (instance %m)");
        $finish;
    end
end

// position of the next input sample, and of the next flush column
wire [X_WIDTH-1:0] x, fx;
wire [Y_WIDTH-1:0] y;
wire x_last, y_last, fx_last;
wire unused_fy, unused_fy_last;

// the flush: replaying the last record row from the line buffer
reg flush_reg = 1'b0, flush_next;

// stage 1: a column's sample (or a flush column) with the line buffer word being read
reg s1_valid_reg = 1'b0;
reg s1_flush_reg = 1'b0;
reg [15:0] s1_v_reg = 16'd0;
reg [X_WIDTH-1:0] s1_addr_reg = {X_WIDTH{1'b0}};
reg s1_xfirst_reg = 1'b0, s1_xlast_reg = 1'b0, s1_xodd_reg = 1'b0;
reg s1_yfirst_reg = 1'b0, s1_ylast_reg = 1'b0, s1_yodd_reg = 1'b0;

// stage r: the same with the line buffer's word registered (block RAM output is slow on ECP5), and
// the two writes its read could not see (the one at the read's edge and the next): forwarded
reg r_valid_reg = 1'b0;
reg r_flush_reg = 1'b0;
reg [15:0] r_v_reg = 16'd0;
reg [17:0] r_v3_reg = 18'd0;           // 3 v
reg [18:0] r_v7_reg = 19'd0;           // 7 v
reg [X_WIDTH-1:0] r_addr_reg = {X_WIDTH{1'b0}};
reg r_xfirst_reg = 1'b0, r_xlast_reg = 1'b0, r_xodd_reg = 1'b0;
reg r_yfirst_reg = 1'b0, r_ylast_reg = 1'b0, r_yodd_reg = 1'b0;
reg [WORD-1:0] r_word_reg = {WORD{1'b0}};
reg r_fwd_a_reg = 1'b0, r_fwd_b_reg = 1'b0;   // the newer (a) or older (b) missed write is to this column
reg [WORD-1:0] r_fwd_a_word_reg = {WORD{1'b0}}, r_fwd_b_word_reg = {WORD{1'b0}};

// the line buffer write of the previous enabled cycle
reg wp_valid_reg = 1'b0;
reg [X_WIDTH-1:0] wp_addr_reg = {X_WIDTH{1'b0}};
reg [WORD-1:0] wp_word_reg = {WORD{1'b0}};

// stage 2: one column of the vertical filter
reg s2_valid_reg = 1'b0;
reg [18:0] s2_l_reg = 19'd0;
reg signed [16:0] s2_d_reg = 17'sd0;
reg s2_xfirst_reg = 1'b0, s2_xlast_reg = 1'b0, s2_xodd_reg = 1'b0;

// stage t: the same column with 3 L, 7 L, 3 D, 7 D
reg t_valid_reg = 1'b0;
reg [18:0] t_l_reg = 19'd0;
reg signed [16:0] t_d_reg = 17'sd0;
reg [20:0] t_l3_reg = 21'd0;
reg [21:0] t_l7_reg = 22'd0;
reg signed [19:0] t_d3_reg = 20'sd0;
reg signed [20:0] t_d7_reg = 21'sd0;
reg t_xfirst_reg = 1'b0, t_xlast_reg = 1'b0, t_xodd_reg = 1'b0;

// horizontal filter state (the recursion over a record row's columns)
reg [21:0] h_pl_reg = 22'd0;           // L[2j-1] + 3 L[2j] (+ 3 L[2j+1])
reg signed [20:0] h_pd_reg = 21'sd0;   // likewise for D
reg [18:0] h_ql_reg = 19'd0;           // L[2j]
reg signed [16:0] h_qd_reg = 17'sd0;   // D[2j]
reg [18:0] h_rl_reg = 19'd0;           // L[2j+1]
reg signed [16:0] h_rd_reg = 17'sd0;   // D[2j+1]
reg signed [19:0] h_e1_reg = 20'sd0;   // L[2j+1] - L[2j]
reg signed [17:0] h_e3_reg = 18'sd0;   // D[2j+1] - D[2j]

// stage 3: a record's sums, and the second record of an even last column
reg s3_valid_reg = 1'b0;
reg [21:0] s3_sl_reg = 22'd0;
reg signed [20:0] s3_sd_reg = 21'sd0;
reg signed [19:0] s3_e1_reg = 20'sd0;
reg signed [17:0] s3_e3_reg = 18'sd0;
reg hold_valid_reg = 1'b0;
reg [21:0] hold_sl_reg = 22'd0;
reg signed [20:0] hold_sd_reg = 21'sd0;

// input side
wire in_fire = en && in_valid && !flush_reg;
wire flush_fire = en && flush_reg;
wire rd_en = in_fire || flush_fire;
wire [X_WIDTH-1:0] rd_addr = flush_reg ? fx : x;

assign in_last = x_last && y_last;

haar_raster #(
    .X_WIDTH(X_WIDTH),
    .Y_WIDTH(Y_WIDTH)
)
pos_inst (
    .clk(clk),
    .rst(rst),
    .start(start),
    .cfg_wm1(cfg_wm1),
    .cfg_hm1(cfg_hm1),
    .step(in_fire),
    .x(x),
    .y(y),
    .x_last(x_last),
    .y_last(y_last)
);

// the flush's columns: one row of the same width
haar_raster #(
    .X_WIDTH(X_WIDTH),
    .Y_WIDTH(1)
)
flush_pos_inst (
    .clk(clk),
    .rst(rst),
    .start(start),
    .cfg_wm1(cfg_wm1),
    .cfg_hm1(1'b0),
    .step(flush_fire),
    .x(fx),
    .y(unused_fy),
    .x_last(fx_last),
    .y_last(unused_fy_last)
);

always @* begin
    flush_next = flush_reg;
    if (in_fire && x_last && y_last && !y[0] && y != {Y_WIDTH{1'b0}}) begin
        // the last row is even and not the first: record row k follows the input
        flush_next = 1'b1;
    end
    if (flush_fire && fx_last) begin
        flush_next = 1'b0;
    end
end

// stage r: the vertical filter
wire [WORD-1:0] rd_word;
wire [WORD-1:0] word = r_fwd_a_reg ? r_fwd_a_word_reg : r_fwd_b_reg ? r_fwd_b_word_reg : r_word_reg;
wire [18:0] p_old = word[50:32];
wire [15:0] q_old = word[31:16];
wire [15:0] r_old = word[15:0];
wire [18:0] v19 = {3'd0, r_v_reg};
wire [18:0] r19 = {3'd0, r_old};
wire [18:0] v3 = {1'b0, r_v3_reg};

reg v_valid;
reg [18:0] v_l;
reg signed [16:0] v_d;
reg [18:0] w_p;
reg [15:0] w_q, w_r;

always @* begin
    v_valid = 1'b0;
    v_l = p_old;
    v_d = 17'sd0;
    w_p = p_old;
    w_q = q_old;
    w_r = r_old;
    if (r_flush_reg) begin
        // record row k of an even last row: L = a[2k-1] + 7 a[2k] was stored as P, D = 0
        v_valid = 1'b1;
    end else if (!r_yodd_reg) begin
        if (r_yfirst_reg) begin
            // row 0: a[-1] = a[0]; a level of one row ends here with every tap clamped to it
            v_valid = r_ylast_reg;
            v_l = v19 << 3;
            w_p = v19 << 2;
        end else begin
            // row 2k: record row k - 1 is complete
            v_valid = 1'b1;
            v_l = p_old + v19;
            v_d = $signed({1'b0, r_old}) - $signed({1'b0, q_old});
            // the next record row's partial sum; on the last row its whole sum (taps below clamped)
            w_p = r19 + (r_ylast_reg ? r_v7_reg : v3);
        end
        w_q = r_v_reg;
    end else begin
        // row 2k+1
        w_p = p_old + v3;
        w_r = r_v_reg;
        if (r_ylast_reg) begin
            // the last row: both taps below clamped to it
            v_valid = 1'b1;
            v_l = p_old + (v19 << 2);
            v_d = $signed({1'b0, r_v_reg}) - $signed({1'b0, q_old});
        end
    end
end

wire wr_en = en && r_valid_reg && !r_flush_reg;
wire [WORD-1:0] wr_word = {w_p, w_q, w_r};

wm_linebuf #(
    .DEPTH(MAX_WIDTH),
    .ADDR_WIDTH(X_WIDTH),
    .DATA_WIDTH(WORD)
)
linebuf_inst (
    .clk(clk),
    .wr_en(wr_en),
    .wr_addr(r_addr_reg),
    .wr_data(wr_word),
    .rd_en(rd_en),
    .rd_addr(rd_addr),
    .rd_data(rd_word)
);

// stage 2: the column's multiples (shifts and one adder each)
wire [21:0] s2_l22 = {3'd0, s2_l_reg};
wire signed [20:0] s2_d21 = {{4{s2_d_reg[16]}}, s2_d_reg};
wire [21:0] s2_l3w = (s2_l22 << 1) + s2_l22;
wire signed [20:0] s2_d3w = (s2_d21 <<< 1) + s2_d21;
wire [20:0] s2_l3 = s2_l3w[20:0];
wire [21:0] s2_l7 = (s2_l22 << 3) - s2_l22;
wire signed [19:0] s2_d3 = s2_d3w[19:0];
wire signed [20:0] s2_d7 = (s2_d21 <<< 3) - s2_d21;
wire unused_s2_l3w = s2_l3w[21];
wire unused_s2_d3w = s2_d3w[20];

// stage t: the horizontal filter (the column's 3 L, 7 L, 3 D, 7 D made in stage 2: one adder deep)
wire [21:0] l22 = {3'd0, t_l_reg};
wire [21:0] rl22 = {3'd0, h_rl_reg};
wire [21:0] l3 = {1'b0, t_l3_reg};
wire signed [20:0] d21 = {{4{t_d_reg[16]}}, t_d_reg};
wire signed [20:0] rd21 = {{4{h_rd_reg[16]}}, h_rd_reg};
wire signed [20:0] d3x = {t_d3_reg[19], t_d3_reg};

reg r1_valid, r2_valid;
reg [21:0] r1_sl;
reg signed [20:0] r1_sd;
reg signed [19:0] r1_e1;
reg signed [17:0] r1_e3;
reg [21:0] r2_sl;
reg signed [20:0] r2_sd;

always @* begin
    r1_valid = 1'b0;
    r2_valid = 1'b0;
    r1_sl = h_pl_reg + l22;
    r1_sd = h_pd_reg + d21;
    r1_e1 = h_e1_reg;
    r1_e3 = h_e3_reg;
    r2_sl = rl22 + t_l7_reg;
    r2_sd = rd21 + t_d7_reg;
    if (t_valid_reg) begin
        if (!t_xodd_reg) begin
            if (t_xfirst_reg) begin
                // column 0: a level of one column ends here with every tap clamped to it
                r1_valid = t_xlast_reg;
                r1_sl = l22 << 3;
                r1_sd = d21 <<< 3;
                r1_e1 = 20'sd0;
                r1_e3 = 18'sd0;
            end else begin
                // column 2j: record j - 1 is complete; on the last column record j too
                r1_valid = 1'b1;
                r2_valid = t_xlast_reg;
            end
        end else if (t_xlast_reg) begin
            // column 2j+1, the last: both taps to the right clamped to it
            r1_valid = 1'b1;
            r1_sl = h_pl_reg + (l22 << 2);
            r1_sd = h_pd_reg + (d21 <<< 2);
            r1_e1 = $signed({1'b0, t_l_reg}) - $signed({1'b0, h_ql_reg});
            r1_e3 = $signed({t_d_reg[16], t_d_reg}) - $signed({h_qd_reg[16], h_qd_reg});
        end
    end
end

// stage 3: rounding and narrowing (every true value fits: the model's bounds)
wire [21:0] sl_round = s3_sl_reg + 22'd32;
wire signed [19:0] e1_round = s3_e1_reg + 20'sd2;
wire signed [20:0] sd_round = s3_sd_reg + 21'sd2;
wire [5:0] unused_sl_frac = sl_round[5:0];
wire [1:0] unused_e1_frac = e1_round[1:0];
wire [2:0] unused_sd_bits = {sd_round[20], sd_round[1:0]};

assign rec_valid = s3_valid_reg;
assign rec_a = sl_round[21:6];
assign rec_d1 = e1_round[19:2];
assign rec_d2 = sd_round[19:2];
assign rec_d3 = s3_e3_reg;

always @(posedge clk) begin
    if (en) begin
        flush_reg <= flush_next;

        // stage 1
        s1_valid_reg <= rd_en;
        s1_flush_reg <= flush_fire;
        s1_v_reg <= in_data;
        s1_addr_reg <= rd_addr;
        s1_xfirst_reg <= rd_addr == {X_WIDTH{1'b0}};
        s1_xlast_reg <= flush_reg ? fx_last : x_last;
        s1_xodd_reg <= rd_addr[0];
        s1_yfirst_reg <= y == {Y_WIDTH{1'b0}};
        s1_ylast_reg <= y_last;
        s1_yodd_reg <= y[0];

        // stage r
        r_valid_reg <= s1_valid_reg;
        r_flush_reg <= s1_flush_reg;
        r_v_reg <= s1_v_reg;
        r_v3_reg <= ({2'd0, s1_v_reg} << 1) + {2'd0, s1_v_reg};
        r_v7_reg <= ({3'd0, s1_v_reg} << 3) - {3'd0, s1_v_reg};
        r_addr_reg <= s1_addr_reg;
        r_xfirst_reg <= s1_xfirst_reg;
        r_xlast_reg <= s1_xlast_reg;
        r_xodd_reg <= s1_xodd_reg;
        r_yfirst_reg <= s1_yfirst_reg;
        r_ylast_reg <= s1_ylast_reg;
        r_yodd_reg <= s1_yodd_reg;
        r_word_reg <= rd_word;
        // the read (at the last edge) missed the write at its own edge (wp) and the one at this edge
        r_fwd_a_reg <= wr_en && r_addr_reg == s1_addr_reg;
        r_fwd_a_word_reg <= wr_word;
        r_fwd_b_reg <= wp_valid_reg && wp_addr_reg == s1_addr_reg;
        r_fwd_b_word_reg <= wp_word_reg;
        wp_valid_reg <= wr_en;
        wp_addr_reg <= r_addr_reg;
        wp_word_reg <= wr_word;

        // stage 2
        s2_valid_reg <= r_valid_reg && v_valid;
        s2_l_reg <= v_l;
        s2_d_reg <= v_d;
        s2_xfirst_reg <= r_xfirst_reg;
        s2_xlast_reg <= r_xlast_reg;
        s2_xodd_reg <= r_xodd_reg;

        // stage t: the multiples of the column's L and D the horizontal sums take
        t_valid_reg <= s2_valid_reg;
        t_l_reg <= s2_l_reg;
        t_d_reg <= s2_d_reg;
        t_l3_reg <= s2_l3;
        t_l7_reg <= s2_l7;
        t_d3_reg <= s2_d3;
        t_d7_reg <= s2_d7;
        t_xfirst_reg <= s2_xfirst_reg;
        t_xlast_reg <= s2_xlast_reg;
        t_xodd_reg <= s2_xodd_reg;

        // horizontal filter state
        if (t_valid_reg) begin
            if (!t_xodd_reg) begin
                // column 2j: start record j's sums
                h_pl_reg <= t_xfirst_reg ? l22 << 2 : rl22 + l3;
                h_pd_reg <= t_xfirst_reg ? d21 <<< 2 : rd21 + d3x;
                h_ql_reg <= t_l_reg;
                h_qd_reg <= t_d_reg;
            end else begin
                // column 2j+1
                h_pl_reg <= h_pl_reg + l3;
                h_pd_reg <= h_pd_reg + d3x;
                h_rl_reg <= t_l_reg;
                h_rd_reg <= t_d_reg;
                h_e1_reg <= $signed({1'b0, t_l_reg}) - $signed({1'b0, h_ql_reg});
                h_e3_reg <= $signed({t_d_reg[16], t_d_reg}) - $signed({h_qd_reg[16], h_qd_reg});
            end
        end

        // stage 3: a held record goes out in the cycle after its pair (which makes none)
        s3_valid_reg <= r1_valid || hold_valid_reg;
        if (hold_valid_reg) begin
            s3_sl_reg <= hold_sl_reg;
            s3_sd_reg <= hold_sd_reg;
            s3_e1_reg <= 20'sd0;
            s3_e3_reg <= 18'sd0;
        end else begin
            s3_sl_reg <= r1_sl;
            s3_sd_reg <= r1_sd;
            s3_e1_reg <= r1_e1;
            s3_e3_reg <= r1_e3;
        end
        hold_valid_reg <= r2_valid;
        hold_sl_reg <= r2_sl;
        hold_sd_reg <= r2_sd;
    end

    if (rst) begin
        flush_reg <= 1'b0;
        s1_valid_reg <= 1'b0;
        r_valid_reg <= 1'b0;
        r_fwd_a_reg <= 1'b0;
        r_fwd_b_reg <= 1'b0;
        wp_valid_reg <= 1'b0;
        s2_valid_reg <= 1'b0;
        t_valid_reg <= 1'b0;
        s3_valid_reg <= 1'b0;
        hold_valid_reg <= 1'b0;
    end
end

endmodule

`resetall
