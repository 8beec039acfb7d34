/*
 * wavemesh: one level of the integer 2D Haar filter bank (docs/model.md, "Filter bank")
 *
 * Consumes the previous level's approximation (level 0: the height samples) in raster order, at
 * most one value per enabled cycle, and emits one record per 2 x 2 block, in raster order of the
 * blocks:
 *
 *         col 2j   col 2j+1
 *       +--------+--------+
 *       |  p00   |  p01   |   row 2i      (line buffer)
 *       +--------+--------+
 *       |  p10   |  p11   |   row 2i+1    (the row streaming in)
 *       +--------+--------+
 *
 *     a  = (p00 + p01 + p10 + p11 + 2) >> 2     16 bits unsigned
 *     d1 = (p01 + p11) - (p00 + p10)            18 bits two's complement
 *     d2 = (p10 + p11) - (p00 + p01)            18 bits two's complement
 *     d3 = (p00 + p11) - (p01 + p10)            18 bits two's complement
 *
 * Padding: the last value of a row of odd width pairs with itself (p01 = p00, p11 = p10), and the
 * last row of a level of odd height pairs with itself (p10 = p00, p11 = p01): such a row's records
 * come out while the row streams in, like an odd row's, so no level ever emits a burst.
 *
 * Each horizontal pair is reduced to its sum and difference as it completes,
 *
 *     s = left + right (17 bits unsigned),  t = right - left (17 bits two's complement),
 *
 * s0, t0 for the top pair (kept in the line buffer), s1, t1 for the bottom pair; then
 *
 *     a = (s0 + s1 + 2) >> 2,  d1 = t0 + t1,  d2 = s1 - s0,  d3 = t1 - t0.
 *
 * Pipeline; every register advances only when en is high, so a stall holds the level as a whole:
 *
 *   in  -> stage 1: s1, t1 of the completed bottom pair; line buffer read of {s0, t0}
 *       -> stage 2: the line buffer's word registered (block RAM output is slow on ECP5)
 *       -> record:  a, d1, d2, d3 from stage 2, one 18-bit add each, combinational: the bank
 *                   writes them into its FIFOs (valid for one cycle with en high)
 *
 * With FLAG = 1 (the filter bank's HOLES, issue 20) a flag travels beside every value: in_flag with
 * in_data, rec_flag with the record, the OR of the four values' flags (padding included: a value
 * paired with itself brings its own flag), kept in a one-bit line buffer of its own.  With FLAG = 0
 * rec_flag is 0 and in_flag unused; nothing else changes.
 *
 * The record arithmetic is 18-bit modulo 2^18: every true value fits 18 bits signed
 * (|d| <= 2 * 65535), so the wrapped result is the exact two's complement value.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module haar_level #
(
    // Largest number of input columns (the previous level's width) this level accepts; >= 1
    parameter MAX_WIDTH = 512,
    // Largest number of input rows; >= 1
    parameter MAX_HEIGHT = 512,
    // Width of the input column counter in bits: $clog2(MAX_WIDTH), at least 1
    parameter X_WIDTH = 9,
    // Width of the input row counter in bits: $clog2(MAX_HEIGHT), at least 1
    parameter Y_WIDTH = 9,
    // 1: carry a flag beside the values (in_flag, rec_flag: the OR over the block)
    parameter FLAG = 0
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
    input  wire                 in_flag,    // FLAG = 1: the value's flag (with in_data)
    output wire                 in_last,    // the next input is the last one of the frame

    /*
     * Record output (taken when en && rec_valid)
     */
    output wire                 rec_valid,
    output wire [15:0]          rec_a,
    output wire [17:0]          rec_d1,
    output wire [17:0]          rec_d2,
    output wire [17:0]          rec_d3,
    output wire                 rec_flag    // FLAG = 1: OR of the block's flags; else 0
);

// line buffer: one word {s0, t0} per block column, addressed by the block column x / 2
localparam PAIRS = (MAX_WIDTH + 1) / 2;
localparam BX_WIDTH = X_WIDTH > 1 ? X_WIDTH - 1 : 1;

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

// the even-column sample waiting for its right neighbour
reg [15:0] left_reg = 16'd0;

// stage 1: the bottom pair of a block (or the top pair of a self-paired last row)
reg st1_valid_reg = 1'b0;
reg st1_self_reg = 1'b0;               // last row of odd height: the top pair is the bottom pair
reg [16:0] st1_s1_reg = 17'd0;         // p10 + p11
reg [16:0] st1_t1_reg = 17'd0;         // p11 - p10

// stage 2: both pairs of the block
reg st2_valid_reg = 1'b0;
reg st2_self_reg = 1'b0;
reg [33:0] st2_top_reg = 34'd0;        // line buffer word {s0, t0}
reg [16:0] st2_s1_reg = 17'd0;
reg [16:0] st2_t1_reg = 17'd0;

// position of the next input sample
wire [X_WIDTH-1:0] x;
wire [Y_WIDTH-1:0] y;
wire x_last, y_last;
wire unused_y = ^y;  // only the row's parity matters here

// input side
wire in_fire = en && in_valid;
// a horizontal pair completes on an odd column, or on the last column when it is even (pairs with itself)
wire pair_done = in_fire && (x[0] || x_last);
wire [15:0] pair_left = x[0] ? left_reg : in_data;
wire [16:0] pair_s = {1'b0, pair_left} + {1'b0, in_data};
wire [16:0] pair_t = {1'b0, in_data} - {1'b0, pair_left};
// rows that make records: odd rows, and the last row when it is even (pairs with itself)
wire rec_row = y[0] || y_last;

// block column of the pair: x / 2
wire [BX_WIDTH-1:0] pair_bx;
wire [33:0] buf_rd_data;

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

generate
    if (X_WIDTH > 1) begin : gen_bx
        assign pair_bx = x[X_WIDTH-1:1];
    end else begin : gen_bx0
        assign pair_bx = 1'b0;
    end
endgenerate

// one address for both ports: a pair is written (even row) or read (odd row), never both in a cycle
wire buf_wr_en = pair_done && !rec_row;
wire buf_rd_en = pair_done && y[0] && !buf_wr_en;  // as one port: a write wins

wm_linebuf #(
    .DEPTH(PAIRS),
    .ADDR_WIDTH(BX_WIDTH),
    .DATA_WIDTH(34)
)
linebuf_inst (
    .clk(clk),
    // even row that is not the last: keep the pair for the row below
    .wr_en(buf_wr_en),
    .wr_addr(pair_bx),
    .wr_data({pair_s, pair_t}),
    // odd row: the pair above
    .rd_en(buf_rd_en),
    .rd_addr(pair_bx),
    .rd_data(buf_rd_data)
);

// record arithmetic, 18 bits modulo 2^18 (s zero-extended, t sign-extended)
wire [16:0] s0_17 = st2_self_reg ? st2_s1_reg : st2_top_reg[33:17];
wire [16:0] t0_17 = st2_self_reg ? st2_t1_reg : st2_top_reg[16:0];
wire [17:0] s0 = {1'b0, s0_17};
wire [17:0] t0 = {t0_17[16], t0_17};
wire [17:0] s1 = {1'b0, st2_s1_reg};
wire [17:0] t1 = {st2_t1_reg[16], st2_t1_reg};
// sum of the block plus the rounding constant: at most 4 * 65535 + 2 < 2^18
wire [17:0] sum = s0 + s1 + 18'd2;
wire [1:0] unused_sum_frac = sum[1:0];  // dropped by the >> 2

assign rec_valid = st2_valid_reg;
assign rec_a = sum[17:2];
assign rec_d1 = t0 + t1;
assign rec_d2 = s1 - s0;
assign rec_d3 = t1 - t0;

always @(posedge clk) begin
    if (in_fire && !x[0]) begin
        // even column: wait for the right neighbour
        left_reg <= in_data;
    end

    if (en) begin
        // stage 1: a block is complete when its bottom pair is (or its only pair, on a self-paired row)
        st1_valid_reg <= pair_done && rec_row;
        st1_self_reg <= !y[0];
        st1_s1_reg <= pair_s;
        st1_t1_reg <= pair_t;

        // stage 2
        st2_valid_reg <= st1_valid_reg;
        st2_self_reg <= st1_self_reg;
        st2_top_reg <= buf_rd_data;
        st2_s1_reg <= st1_s1_reg;
        st2_t1_reg <= st1_t1_reg;
    end

    if (rst) begin
        st1_valid_reg <= 1'b0;
        st2_valid_reg <= 1'b0;
    end
end

// the flags (FLAG = 1): the same pipeline as the values, one bit wide
generate
    if (FLAG) begin : gen_flag
        reg left_f_reg = 1'b0;   // flag of the even-column value waiting for its neighbour
        reg st1_f1_reg = 1'b0;   // the bottom pair's flag
        reg st2_f1_reg = 1'b0;
        reg st2_f0_reg = 1'b0;   // the top pair's (line buffer)
        wire pair_f = in_flag || (x[0] && left_f_reg);
        wire buf_rd_f;

        wm_linebuf #(
            .DEPTH(PAIRS),
            .ADDR_WIDTH(BX_WIDTH),
            .DATA_WIDTH(1)
        )
        flagbuf_inst (
            .clk(clk),
            .wr_en(buf_wr_en),
            .wr_addr(pair_bx),
            .wr_data(pair_f),
            .rd_en(buf_rd_en),
            .rd_addr(pair_bx),
            .rd_data(buf_rd_f)
        );

        always @(posedge clk) begin
            if (in_fire && !x[0]) begin
                left_f_reg <= in_flag;
            end
            if (en) begin
                st1_f1_reg <= pair_f;
                st2_f1_reg <= st1_f1_reg;
                st2_f0_reg <= buf_rd_f;
            end
        end

        // a self-paired last row: the top pair is the bottom pair
        assign rec_flag = st2_f1_reg || (!st2_self_reg && st2_f0_reg);
    end else begin : gen_no_flag
        assign rec_flag = 1'b0;
        wire unused_flag = in_flag;
    end
endgenerate

endmodule

`resetall
