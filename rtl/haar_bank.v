/*
 * wavemesh: streaming multi-level integer 2D Haar filter bank (docs/model.md, "Filter bank")
 *
 * Height samples enter in raster order, one per clock at most; for every level m = 1..cfg_levels
 * the bank emits one record per 2 x 2 block of level m-1's approximation: the approximation a and
 * the details d1, d2, d3, with the level and the block position.  Bit for bit the integers of
 * host/wavemesh/model/haar.py, padding included (an odd last column or row pairs with itself).
 *
 * Structure: a cascade of haar_level instances.  Level m's records go to a small record FIFO,
 * its approximations also to a 16-bit FIFO in front of level m+1; the output merge hands out one
 * record per clock from the record FIFOs, lowest level first, and a position counter per level
 * (haar_raster) tells each record's block position, since every level's records are in raster
 * order.  Each level advances all its pipeline registers together, only when neither FIFO it writes
 * is full, so back-pressure stalls a level as a whole and nothing is lost or repeated; a stalled
 * level m+1 stalls level m only once the approximation FIFO between them is full, and level 1
 * stalls the input.
 *
 * Throughput: on the odd rows the levels together make up to 1/2 + 1/4 + ... + 1 / 2^M records per
 * clock, plus one more per level at each row end when the widths are odd, slightly more than one
 * per clock over such a row.  The merge serves the lowest level first, so the backlog piles up in
 * the deepest levels, which then wait: their approximations queue in the cheap 16-bit FIFOs
 * (one entry there covers 2^(m-1) input clocks) while level 1 keeps taking one sample per clock.
 * With the output always ready the input is never stalled inside a frame (tests/rtl check this).
 *
 * Frame protocol:
 *   - idle: s_axis_tready is low.  The first cycle s_axis_tvalid is high while idle starts a
 *     frame and samples cfg_width, cfg_height and cfg_levels; they need be valid only then.
 *   - two set-up cycles later the bank takes exactly cfg_width * cfg_height samples (no tlast in),
 *     then drops s_axis_tready until the frame's last record (m_axis_tlast) has been handed out;
 *     busy is high from the frame's start to that hand-out, frame_done pulses with it.
 *   - out-of-range configuration saturates: width and height to 1..MAX_*, levels to 1..MAX_LEVELS.
 *   - a frame takes W * H + 3 * cfg_levels + 3 clocks from its start to its last record with the
 *     input always valid and the output always ready; busy drops one clock later.
 *
 * Output records (one per m_axis handshake):
 *
 *   signal         bits     field
 *   m_axis_tdata   [15:0]   a:  (p00 + p01 + p10 + p11 + 2) >> 2, unsigned
 *                  [33:16]  d1: (p01 + p11) - (p00 + p10), two's complement
 *                  [51:34]  d2: (p10 + p11) - (p00 + p01), two's complement
 *                  [69:52]  d3: (p00 + p11) - (p01 + p10), two's complement
 *   m_axis_tuser   [15:0]   bx: block column at level m, 0 .. ceil(W / 2^m) - 1
 *                  [31:16]  by: block row at level m, 0 .. ceil(H / 2^m) - 1
 *                  [35:32]  level m, 1 .. cfg_levels
 *                  [36]     HOLES = 1 only: an invalid sample (s_axis_tuser = 1) among the 2^m x 2^m
 *                           samples of the block (clipped at the frame's edge)
 *   m_axis_tlast            the frame's last record (level cfg_levels, bottom-right block)
 *
 * Records of one level come out in raster order (by, then bx); levels interleave.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module haar_bank #
(
    // Largest cfg_width in samples; 2 .. 65535
    parameter MAX_WIDTH = 512,
    // Largest cfg_height in rows; 2 .. 65535
    parameter MAX_HEIGHT = 512,
    // Levels built (largest cfg_levels); 1 .. 15
    parameter MAX_LEVELS = 7,
    // Records buffered per level between its pipeline and the output merge; >= 2 (any number)
    parameter FIFO_DEPTH = 2,
    // Approximations buffered in front of each level from the second on; >= 2 (any number)
    parameter APPROX_FIFO_DEPTH = 2,
    // The filters: 0 Haar (haar_level), 1 the spline wavelet (spline_level, host/wavemesh/model/spline.py)
    parameter WAVELET = 0,
    // 1: a validity mask beside the samples (s_axis_tuser, 1 = invalid; --nodata hole, issue 20) and
    // every record's flag on m_axis_tuser[36]: 1 when its block's samples hold an invalid one (the OR
    // over the coefficient's 2^m x 2^m samples, padding included); Haar only.  0: no flags
    parameter HOLES = 0
)
(
    input  wire         clk,
    input  wire         rst,

    /*
     * Configuration (sampled when a frame starts)
     */
    input  wire [15:0]  cfg_width,
    input  wire [15:0]  cfg_height,
    input  wire [3:0]   cfg_levels,

    /*
     * Height samples in, raster order
     */
    input  wire [15:0]  s_axis_tdata,
    input  wire         s_axis_tuser,   // HOLES = 1: the sample is invalid; else unused
    input  wire         s_axis_tvalid,
    output wire         s_axis_tready,

    /*
     * Coefficient records out
     */
    output wire [69:0]  m_axis_tdata,
    output wire [35+HOLES:0] m_axis_tuser,
    output wire         m_axis_tvalid,
    input  wire         m_axis_tready,
    output wire         m_axis_tlast,

    /*
     * Status
     */
    output wire         busy,
    output wire         frame_done
);

localparam X_WIDTH = $clog2(MAX_WIDTH);
localparam Y_WIDTH = $clog2(MAX_HEIGHT);
localparam [15:0] MAX_WIDTH_16 = MAX_WIDTH[15:0];
localparam [15:0] MAX_HEIGHT_16 = MAX_HEIGHT[15:0];
localparam [3:0] MAX_LEVELS_4 = MAX_LEVELS[3:0];
localparam [X_WIDTH-1:0] WM1_MAX = MAX_WIDTH[X_WIDTH-1:0] - 1'b1;
localparam [Y_WIDTH-1:0] HM1_MAX = MAX_HEIGHT[Y_WIDTH-1:0] - 1'b1;
// record in the output merge: {last, by[15:0], bx[15:0], d3, d2, d1, a}
// (HOLES = 1: the record's flag above d3, {last, by, bx, flag, d3, d2, d1, a})
localparam REC_WIDTH = 1 + 16 + 16 + 70 + HOLES;
localparam AW = 16 + HOLES;  // approximation FIFO entry: {flag, a}
localparam RW = 70 + HOLES;  // record FIFO entry

// check configuration
initial begin
    if (MAX_WIDTH < 2 || MAX_WIDTH > 65535 || MAX_HEIGHT < 2 || MAX_HEIGHT > 65535) begin
        $error("Error: MAX_WIDTH and MAX_HEIGHT must be 2 .. 65535 (instance %m)");
        $finish;
    end
    if (HOLES != 0 && (HOLES != 1 || WAVELET != 0)) begin
        $error("Error: HOLES must be 0, or 1 with the Haar filters (instance %m)");
        $finish;
    end
    if (WAVELET != 0 && WAVELET != 1) begin
        $error("Error: WAVELET must be 0 (Haar) or 1 (spline) (instance %m)");
        $finish;
    end
    if (MAX_LEVELS < 1 || MAX_LEVELS > 15) begin
        $error("Error: MAX_LEVELS must be 1 .. 15 (instance %m)");
        $finish;
    end
end

// frame state
localparam [1:0]
    STATE_IDLE = 2'd0,   // waiting for a frame's first sample
    STATE_INIT = 2'd1,   // configuration sampled: load the levels' counters
    STATE_RUN = 2'd2,    // taking samples
    STATE_DRAIN = 2'd3;  // all samples in: waiting for the last record to leave

reg [1:0] state_reg = STATE_IDLE, state_next;

// frame configuration
reg [X_WIDTH-1:0] wm1_reg = {X_WIDTH{1'b0}}, wm1_next;          // width - 1
reg [Y_WIDTH-1:0] hm1_reg = {Y_WIDTH{1'b0}}, hm1_next;          // height - 1
reg [MAX_LEVELS-1:0] lvl_on_reg = {MAX_LEVELS{1'b0}}, lvl_on_next;  // level i+1 is computed
reg [MAX_LEVELS-1:0] lvl_top_reg = {MAX_LEVELS{1'b0}}, lvl_top_next;  // level i+1 is the last one

// output register
reg [69:0] m_axis_tdata_reg = 70'd0, m_axis_tdata_next;
reg [35+HOLES:0] m_axis_tuser_reg = {(36+HOLES){1'b0}}, m_axis_tuser_next;
reg m_axis_tvalid_reg = 1'b0, m_axis_tvalid_next;
reg m_axis_tlast_reg = 1'b0, m_axis_tlast_next;

reg frame_done_reg = 1'b0, frame_done_next;

// per level (the FIFOs are wm_fifo: s_ready is "not full", m_valid "not empty", both registers)
wire frame_in_last;  // level 1's next input is the frame's last sample
wire [MAX_LEVELS-1:0] fifo_s_ready;  // record FIFOs
wire [MAX_LEVELS-1:0] fifo_m_valid;
wire [MAX_LEVELS:1] afifo_s_ready;   // approximation FIFO in front of level i+1 (none: 1)
wire [MAX_LEVELS*REC_WIDTH-1:0] fifo_rd_data;
wire [MAX_LEVELS-1:0] fifo_rd_en;

// cfg_levels saturated to 1 .. MAX_LEVELS
wire [3:0] levels_sat;

generate
    if (MAX_LEVELS < 15) begin : gen_levels_sat
        assign levels_sat = cfg_levels == 4'd0 ? 4'd1 :
                            cfg_levels > MAX_LEVELS_4 ? MAX_LEVELS_4 : cfg_levels;
    end else begin : gen_levels_sat15
        assign levels_sat = cfg_levels == 4'd0 ? 4'd1 : cfg_levels;
    end
endgenerate

wire start = state_reg == STATE_INIT;
wire in_fire = s_axis_tvalid && s_axis_tready;

assign s_axis_tready = (state_reg == STATE_RUN) && lvl[0].en;
assign afifo_s_ready[MAX_LEVELS] = 1'b1;

assign m_axis_tdata = m_axis_tdata_reg;
assign m_axis_tuser = m_axis_tuser_reg;
assign m_axis_tvalid = m_axis_tvalid_reg;
assign m_axis_tlast = m_axis_tlast_reg;

assign busy = state_reg != STATE_IDLE;
assign frame_done = frame_done_reg;

genvar i;

generate
    for (i = 0; i < MAX_LEVELS; i = i + 1) begin : lvl
        // level i+1 reads level i: at most ceil(MAX / 2^i) columns and rows
        localparam LMAX_W = ((MAX_WIDTH - 1) >> i) + 1;
        localparam LMAX_H = ((MAX_HEIGHT - 1) >> i) + 1;
        localparam LX_WIDTH = LMAX_W > 1 ? $clog2(LMAX_W) : 1;
        localparam LY_WIDTH = LMAX_H > 1 ? $clog2(LMAX_H) : 1;
        localparam LBX_WIDTH = LX_WIDTH > 1 ? LX_WIDTH - 1 : 1;
        localparam LBY_WIDTH = LY_WIDTH > 1 ? LY_WIDTH - 1 : 1;

        // this level's input size less one: ceil(W / 2^i) - 1 = (W - 1) >> i
        wire [LX_WIDTH-1:0] cfg_wm1;
        wire [LY_WIDTH-1:0] cfg_hm1;
        if (X_WIDTH > i) begin : gen_wm1
            assign cfg_wm1 = wm1_reg[X_WIDTH-1:i];
        end else begin : gen_wm1_0
            assign cfg_wm1 = 1'b0;
        end
        if (Y_WIDTH > i) begin : gen_hm1
            assign cfg_hm1 = hm1_reg[Y_WIDTH-1:i];
        end else begin : gen_hm1_0
            assign cfg_hm1 = 1'b0;
        end

        // the level advances when both FIFOs it writes have room
        wire en = fifo_s_ready[i] && afifo_s_ready[i+1];

        wire in_last;
        wire rec_valid;
        wire [15:0] rec_a;
        wire [17:0] rec_d1, rec_d2, rec_d3;
        wire rec_flag;

        wire in_valid;
        wire [15:0] in_data;
        wire in_flag;
        wire [AW-1:0] in_word;  // {flag, value} (HOLES = 1) or the value
        wire [AW-1:0] a_word;   // this level's approximation as the next level takes it
        wire [RW-1:0] r_word;   // this level's record as its FIFO takes it
        assign in_data = in_word[15:0];
        if (HOLES) begin : gen_words_flag
            assign in_flag = in_word[AW-1];
            assign a_word = {rec_flag, rec_a};
            assign r_word = {rec_flag, rec_d3, rec_d2, rec_d1, rec_a};
        end else begin : gen_words
            assign in_flag = 1'b0;
            assign a_word = rec_a;
            assign r_word = {rec_d3, rec_d2, rec_d1, rec_a};
            wire unused_rec_flag = rec_flag;
        end
        if (i == MAX_LEVELS - 1) begin : gen_a_last
            wire unused_a_word = ^a_word;  // no level after the last
        end
        if (i == 0) begin : gen_in_samples
            assign in_valid = s_axis_tvalid && state_reg == STATE_RUN;
            if (HOLES) begin : gen_in_flag
                assign in_word = {s_axis_tuser, s_axis_tdata};
            end else begin : gen_in_plain
                assign in_word = s_axis_tdata;
                wire unused_tuser = s_axis_tuser;
            end
        end else begin : gen_in_cascade
            // the previous level's approximations, when this level is on (the previous level
            // writes only when en, which includes s_ready; this level reads only when en)
            wire [$clog2(APPROX_FIFO_DEPTH+1)-1:0] afifo_count_unused;

            wm_fifo #(
                .DATA_WIDTH(AW),
                .DEPTH(APPROX_FIFO_DEPTH)
            )
            afifo_inst (
                .clk(clk),
                .rst(rst),
                .s_data(lvl[i-1].a_word),
                .s_valid(lvl[i-1].en && lvl[i-1].rec_valid && lvl_on_reg[i]),
                .s_ready(afifo_s_ready[i]),
                .m_data(in_word),
                .m_valid(in_valid),
                .m_ready(en),
                .count(afifo_count_unused)
            );
        end

        if (WAVELET == 1) begin : gen_spline
            spline_level #(
                .MAX_WIDTH(LMAX_W),
                .MAX_HEIGHT(LMAX_H),
                .X_WIDTH(LX_WIDTH),
                .Y_WIDTH(LY_WIDTH)
            )
            level_inst (
                .clk(clk),
                .rst(rst),
                .en(en),
                .start(start),
                .cfg_wm1(cfg_wm1),
                .cfg_hm1(cfg_hm1),
                .in_valid(in_valid),
                .in_data(in_data),
                .in_last(in_last),
                .rec_valid(rec_valid),
                .rec_a(rec_a),
                .rec_d1(rec_d1),
                .rec_d2(rec_d2),
                .rec_d3(rec_d3)
            );
            assign rec_flag = 1'b0;  // HOLES is Haar's only
            wire unused_in_flag = in_flag;
        end else begin : gen_haar
            haar_level #(
                .MAX_WIDTH(LMAX_W),
                .MAX_HEIGHT(LMAX_H),
                .X_WIDTH(LX_WIDTH),
                .Y_WIDTH(LY_WIDTH),
                .FLAG(HOLES)
            )
            level_inst (
                .clk(clk),
                .rst(rst),
                .en(en),
                .start(start),
                .cfg_wm1(cfg_wm1),
                .cfg_hm1(cfg_hm1),
                .in_valid(in_valid),
                .in_data(in_data),
                .in_flag(in_flag),
                .in_last(in_last),
                .rec_valid(rec_valid),
                .rec_a(rec_a),
                .rec_d1(rec_d1),
                .rec_d2(rec_d2),
                .rec_d3(rec_d3),
                .rec_flag(rec_flag)
            );
        end

        if (i == 0) begin : gen_frame_last
            assign frame_in_last = in_last;
        end else begin : gen_in_last_unused
            // deeper levels finish on their own; only the sample count ends a frame's input
            wire unused_in_last = in_last;
        end

        wire [RW-1:0] entry;
        wire [$clog2(FIFO_DEPTH+1)-1:0] fifo_count_unused;

        // written only when en (which includes s_ready); read only when granted (m_valid)
        wm_fifo #(
            .DATA_WIDTH(RW),
            .DEPTH(FIFO_DEPTH)
        )
        fifo_inst (
            .clk(clk),
            .rst(rst),
            .s_data(r_word),
            .s_valid(en && rec_valid),
            .s_ready(fifo_s_ready[i]),
            .m_data(entry),
            .m_valid(fifo_m_valid[i]),
            .m_ready(fifo_rd_en[i]),
            .count(fifo_count_unused)
        );

        // block position of the record at the head of the FIFO: records leave in raster order, so
        // a counter over this level's block grid, (W - 1) >> (i + 1) + 1 columns, tells it
        wire [LBX_WIDTH-1:0] cfg_bwm1;
        wire [LBY_WIDTH-1:0] cfg_bhm1;
        if (X_WIDTH > i + 1) begin : gen_bwm1
            assign cfg_bwm1 = wm1_reg[X_WIDTH-1:i+1];
        end else begin : gen_bwm1_0
            assign cfg_bwm1 = 1'b0;
        end
        if (Y_WIDTH > i + 1) begin : gen_bhm1
            assign cfg_bhm1 = hm1_reg[Y_WIDTH-1:i+1];
        end else begin : gen_bhm1_0
            assign cfg_bhm1 = 1'b0;
        end

        wire [LBX_WIDTH-1:0] bx;
        wire [LBY_WIDTH-1:0] by;
        wire bx_last, by_last;

        haar_raster #(
            .X_WIDTH(LBX_WIDTH),
            .Y_WIDTH(LBY_WIDTH)
        )
        pos_inst (
            .clk(clk),
            .rst(rst),
            .start(start),
            .cfg_wm1(cfg_bwm1),
            .cfg_hm1(cfg_bhm1),
            .step(fifo_rd_en[i]),
            .x(bx),
            .y(by),
            .x_last(bx_last),
            .y_last(by_last)
        );

        // the merge's view: {last, by, bx, record}, positions widened to 16 bits
        assign fifo_rd_data[i*REC_WIDTH +: REC_WIDTH] = {
            bx_last && by_last,
            {(16-LBY_WIDTH){1'b0}}, by,
            {(16-LBX_WIDTH){1'b0}}, bx,
            entry
        };
    end
endgenerate

// levels on for cfg_levels: bits 0 .. levels-1 (the highest of them marks the frame's last record)
reg [MAX_LEVELS-1:0] levels_mask;
integer j;

always @* begin
    for (j = 0; j < MAX_LEVELS; j = j + 1) begin
        levels_mask[j] = j < levels_sat;
    end
end

// output merge: the lowest level with a record waiting (one-hot grant, AND-OR data mux)
wire out_ready = !m_axis_tvalid_reg || m_axis_tready;
reg [MAX_LEVELS-1:0] grant;
reg [REC_WIDTH-1:0] sel_rec;
reg [3:0] sel_level;
reg sel_top;
integer k;

always @* begin
    grant = {MAX_LEVELS{1'b0}};
    sel_rec = {REC_WIDTH{1'b0}};
    sel_level = 4'd0;
    sel_top = 1'b0;
    for (k = 0; k < MAX_LEVELS; k = k + 1) begin
        // level k+1 wins when it has a record and no lower level has one
        grant[k] = fifo_m_valid[k] && ((fifo_m_valid & ((1 << k) - 1)) == 0);
        if (grant[k]) begin
            sel_rec = sel_rec | fifo_rd_data[k*REC_WIDTH +: REC_WIDTH];
            sel_level = sel_level | (k[3:0] + 4'd1);
            sel_top = sel_top | lvl_top_reg[k];
        end
    end
end

wire pop = (|fifo_m_valid) && out_ready;

// the handed-out record's tuser: {level, by, bx}, and with HOLES its flag above them
wire [35+HOLES:0] sel_user;
generate
    if (HOLES) begin : gen_user_flag
        assign sel_user = {sel_rec[70], sel_level, sel_rec[102:71]};
    end else begin : gen_user
        assign sel_user = {sel_level, sel_rec[101:70]};
    end
endgenerate
assign fifo_rd_en = grant & {MAX_LEVELS{out_ready}};

always @* begin
    state_next = state_reg;
    wm1_next = wm1_reg;
    hm1_next = hm1_reg;
    lvl_on_next = lvl_on_reg;
    lvl_top_next = lvl_top_reg;
    m_axis_tdata_next = m_axis_tdata_reg;
    m_axis_tuser_next = m_axis_tuser_reg;
    m_axis_tvalid_next = m_axis_tvalid_reg && !m_axis_tready;
    m_axis_tlast_next = m_axis_tlast_reg;
    frame_done_next = 1'b0;

    case (state_reg)
        STATE_IDLE: begin
            if (s_axis_tvalid) begin
                // a frame starts: sample the configuration, saturated to what was built
                state_next = STATE_INIT;
                if (cfg_width > MAX_WIDTH_16) begin
                    wm1_next = WM1_MAX;
                end else if (cfg_width == 16'd0) begin
                    wm1_next = {X_WIDTH{1'b0}};
                end else begin
                    // W - 1 < 2^X_WIDTH: the low bits are exact
                    wm1_next = cfg_width[X_WIDTH-1:0] - 1'b1;
                end
                if (cfg_height > MAX_HEIGHT_16) begin
                    hm1_next = HM1_MAX;
                end else if (cfg_height == 16'd0) begin
                    hm1_next = {Y_WIDTH{1'b0}};
                end else begin
                    hm1_next = cfg_height[Y_WIDTH-1:0] - 1'b1;
                end
                lvl_on_next = levels_mask;
                lvl_top_next = levels_mask & ~(levels_mask >> 1);
            end
        end
        STATE_INIT: begin
            // the levels load their counters (start)
            state_next = STATE_RUN;
        end
        STATE_RUN: begin
            if (in_fire && frame_in_last) begin
                // the frame's last sample is in
                state_next = STATE_DRAIN;
            end
        end
        STATE_DRAIN: begin
            if (m_axis_tvalid_reg && m_axis_tready && m_axis_tlast_reg) begin
                // the frame's last record is out
                state_next = STATE_IDLE;
                frame_done_next = 1'b1;
            end
        end
        default: begin
            state_next = STATE_IDLE;
        end
    endcase

    if (pop) begin
        // hand out the head of the granted FIFO
        m_axis_tdata_next = sel_rec[69:0];
        m_axis_tuser_next = sel_user;
        m_axis_tvalid_next = 1'b1;
        m_axis_tlast_next = sel_rec[REC_WIDTH-1] && sel_top;
    end
end

always @(posedge clk) begin
    state_reg <= state_next;
    wm1_reg <= wm1_next;
    hm1_reg <= hm1_next;
    lvl_on_reg <= lvl_on_next;
    lvl_top_reg <= lvl_top_next;
    m_axis_tdata_reg <= m_axis_tdata_next;
    m_axis_tuser_reg <= m_axis_tuser_next;
    m_axis_tvalid_reg <= m_axis_tvalid_next;
    m_axis_tlast_reg <= m_axis_tlast_next;
    frame_done_reg <= frame_done_next;

    if (rst) begin
        state_reg <= STATE_IDLE;
        lvl_on_reg <= {MAX_LEVELS{1'b0}};
        lvl_top_reg <= {MAX_LEVELS{1'b0}};
        m_axis_tvalid_reg <= 1'b0;
        m_axis_tlast_reg <= 1'b0;
        frame_done_reg <= 1'b0;
    end
end

endmodule

`resetall
