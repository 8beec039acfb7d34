/*
 * wavemesh: the SoC's FPGA stage, the filter bank and the template stage between the memories
 *
 *   HEIGHT --stream--> haar_bank --records--> fork --writer--> COEF  (d1 d2 d3 of every level)
 *                                                \--> tlut_stage --block_end beats--> TOUT
 *
 * The memories are areas of the SDRAM (soc_top): the stage asks for one stream of the W H samples
 * (height_start, height_count) and hands out coefficient and template entries with their indices
 * on two valid/ready streams, which soc_top turns into SDRAM writes; every port may stall.
 *
 * START (ACCEL.CTRL) runs one frame: the W H samples stream into haar_bank; every record {d3, d2,
 * d1, a} of levels 1..M is held in a one-entry fork register until the coefficient writer has
 * handed out its three details (three beats) and tlut_stage has taken it.  tlut_stage keeps the
 * records of level M and, built without its expander (EXPAND = 0: no triangle ROM, no site
 * arithmetic), emits one beat per block, handed out as the block's entry for TOUT (the firmware
 * expands the block's template itself, with the
 * generated wm_templates.h).
 *
 * Memory layouts (docs/soc.md, "The FPGA stage"):
 *
 *   COEF  the layout of wm_details_offset (firmware/include/wavemesh.h) and wavemesh.model.haar: level by
 *         level from m = 1, each level ceil(H / 2^m) rows of ceil(W / 2^m) cells, each cell three
 *         entries d1, d2, d3; so the firmware hands the memory to the refiner as its int32 array
 *   TOUT  one entry per block (by, bx) of level M at by * ceil((W-1) / 2^M) + bx:
 *         bits 5..0 template id, 8..6 label (F f V v H h D = 0..6)
 *
 * Registers (ACCEL block, wm_memmap.vh):
 *
 *   0x00 CTRL          w   bit 0 START (ignored while busy)
 *   0x04 STATUS        r   bit 0 BUSY, bit 1 DONE (cleared by START), bit 2 ERROR (START refused)
 *   0x08 WIDTH         rw  W        0x0C HEIGHT  rw  H
 *   0x10 LEVELS        rw  M        0x14 TAU     rw  tau_M, 18 bits
 *   0x18 CYC_FILTER    r   cycles from START to the last coefficient stored
 *   0x1C CYC_TEMPLATE  r   cycles from START to the last template entry stored
 *   0x20 CYC_TOTAL     r   cycles from START to DONE
 *   0x24 COEFS         r   coefficient entries stored     0x28 BLOCKS  r  template entries stored
 *   0x30 MAX_WIDTH, 0x34 MAX_HEIGHT, 0x38 MAX_LEVELS  r   what the stage is built for
 *
 * Configuration writes are ignored while busy.  DONE waits for mem_idle too (soc_top: every entry
 * handed out is in the SDRAM), so the CPU reads the results once it sees DONE.
 *
 * START first spends MAX_LEVELS + 2 set-up clocks: the base of each level in COEF (3 cw ch per
 * level, the cell counts halving with rounding up), the block counts, the checks (W, H, M in range,
 * W H <= HEIGHT_SAMPLES, the details <= COEF_ENTRIES, the blocks <= TOUT_ENTRIES, the block columns
 * <= MAX_COLS); a refused START sets DONE and ERROR at once and touches nothing.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_accel #
(
    // largest W and H, samples; 2..65535 (haar_bank MAX_WIDTH, MAX_HEIGHT)
    parameter MAX_WIDTH = `WM_GRID_MAX_W,
    parameter MAX_HEIGHT = `WM_GRID_MAX_H,
    // largest M; 1..15 (haar_bank MAX_LEVELS)
    parameter MAX_LEVELS = `WM_STAGE_MAX_LEVELS,
    // most block columns, ceil((W-1) / 2^M); tlut_stage MAX_COLS, >= 1
    parameter MAX_COLS = `WM_STAGE_MAX_COLS,
    // memory sizes in entries (soc_top's); HEIGHT_SAMPLES even
    parameter HEIGHT_SAMPLES = `WM_HEIGHT_ENTRIES,
    parameter COEF_ENTRIES = `WM_COEF_ENTRIES,
    parameter TOUT_ENTRIES = `WM_TOUT_ENTRIES
)
(
    input  wire                               clk,
    input  wire                               rst,

    /*
     * Register bus (one-cycle request, registered read data)
     */
    input  wire                               bus_valid,
    input  wire [7:0]                         bus_addr,
    input  wire [31:0]                        bus_wdata,
    input  wire [3:0]                         bus_wstrb,
    output wire [31:0]                        bus_rdata,

    /*
     * Memory streams
     */
    output wire                               busy,
    output wire                               height_start,  // one cycle: stream height_count samples
    output wire [31:0]                        height_count,
    input  wire [15:0]                        s_axis_height_tdata,
    input  wire                               s_axis_height_tvalid,
    output wire                               s_axis_height_tready,
    output wire [17:0]                        m_axis_coef_tdata,   // a detail ...
    output wire [$clog2(COEF_ENTRIES)-1:0]    m_axis_coef_tuser,   // ... and its entry in COEF
    output wire                               m_axis_coef_tvalid,
    input  wire                               m_axis_coef_tready,
    output wire [15:0]                        m_axis_tout_tdata,   // a template entry ...
    output wire [$clog2(TOUT_ENTRIES)-1:0]    m_axis_tout_tuser,   // ... and its entry in TOUT
    output wire                               m_axis_tout_tvalid,
    input  wire                               m_axis_tout_tready,
    input  wire                               mem_idle      // every entry handed out is stored
);

localparam CAW = $clog2(COEF_ENTRIES);
localparam TAW = $clog2(TOUT_ENTRIES);
localparam [31:0] MAX_WIDTH_W = MAX_WIDTH;
localparam [31:0] MAX_HEIGHT_W = MAX_HEIGHT;
localparam [31:0] MAX_LEVELS_W = MAX_LEVELS;
localparam [31:0] MAX_COLS_W = MAX_COLS;
localparam [31:0] HEIGHT_SAMPLES_W = HEIGHT_SAMPLES;
localparam [31:0] COEF_ENTRIES_W = COEF_ENTRIES;
localparam [31:0] TOUT_ENTRIES_W = TOUT_ENTRIES;
localparam [4:0] SETUP_END = MAX_LEVELS[4:0] + 5'd1;

// check configuration
initial begin
    if (MAX_WIDTH < 2 || MAX_WIDTH > 65535 || MAX_HEIGHT < 2 || MAX_HEIGHT > 65535) begin
        $error("Error: MAX_WIDTH and MAX_HEIGHT must be 2..65535 (instance %m)");
        $finish;
    end
    if (MAX_LEVELS < 1 || MAX_LEVELS > 15 || MAX_COLS < 1) begin
        $error("Error: need 1 <= MAX_LEVELS <= 15 and MAX_COLS >= 1 (instance %m)");
        $finish;
    end
    if (HEIGHT_SAMPLES < 4 || HEIGHT_SAMPLES % 2 != 0 || COEF_ENTRIES < 2 || TOUT_ENTRIES < 2) begin
        $error("Error: HEIGHT_SAMPLES must be even >= 4, COEF_ENTRIES and TOUT_ENTRIES >= 2 (instance %m)");
        $finish;
    end
end

localparam [1:0]
    STATE_IDLE = 2'd0,
    STATE_SETUP = 2'd1,
    STATE_RUN = 2'd2;

reg [1:0] state_reg = STATE_IDLE;
reg done_reg = 1'b0;
reg error_reg = 1'b0;

// configuration
reg [15:0] width_reg = 16'd0;
reg [15:0] height_reg = 16'd0;
reg [3:0] levels_reg = 4'd0;
reg [17:0] tau_reg = 18'd0;

// statistics
reg [31:0] cyc_reg = 32'd0;
reg [31:0] cyc_filter_reg = 32'd0;
reg [31:0] cyc_template_reg = 32'd0;
reg [31:0] cyc_total_reg = 32'd0;
reg [31:0] coefs_reg = 32'd0;
reg [31:0] blocks_reg = 32'd0;
reg [31:0] rdata_reg = 32'd0;

// set-up: level m's base in COEF, cells halving with rounding up
reg [4:0] setup_level_reg = 5'd0;
reg [15:0] cw_reg = 16'd0, ch_reg = 16'd0;   // cells of the level being set up
reg [15:0] bw_reg = 16'd0, bh_reg = 16'd0;   // ceil((W-1) / 2^m), ceil((H-1) / 2^m)
reg [15:0] cols_reg = 16'd0, rows_reg = 16'd0; // block columns and rows of level M
reg [33:0] coef_total_reg = 34'd0;
reg [CAW:0] ptr_reg [0:15];                   // next entry of each level's details

// frame
reg filter_done_reg = 1'b0;
reg template_done_reg = 1'b0;

integer k;
initial begin
    for (k = 0; k < 16; k = k + 1) begin
        ptr_reg[k] = {(CAW+1){1'b0}};
    end
end

assign busy = state_reg != STATE_IDLE;
assign bus_rdata = rdata_reg;

/*
 * Register bus
 */
wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire reg_write = bus_valid && bus_wstrb != 4'd0;
wire start = reg_write && bus_addr == `WM_ACCEL_CTRL && bus_wdata[`WM_ACCEL_CTRL_START] && !busy;

always @(posedge clk) begin
    rdata_reg <= 32'd0;
    if (reg_read) begin
        // read: registered data for the next cycle
        case (bus_addr)
            `WM_ACCEL_STATUS: rdata_reg <= {29'd0, error_reg, done_reg, busy};
            `WM_ACCEL_WIDTH: rdata_reg <= {16'd0, width_reg};
            `WM_ACCEL_HEIGHT: rdata_reg <= {16'd0, height_reg};
            `WM_ACCEL_LEVELS: rdata_reg <= {28'd0, levels_reg};
            `WM_ACCEL_TAU: rdata_reg <= {14'd0, tau_reg};
            `WM_ACCEL_CYC_FILTER: rdata_reg <= cyc_filter_reg;
            `WM_ACCEL_CYC_TEMPLATE: rdata_reg <= cyc_template_reg;
            `WM_ACCEL_CYC_TOTAL: rdata_reg <= cyc_total_reg;
            `WM_ACCEL_COEFS: rdata_reg <= coefs_reg;
            `WM_ACCEL_BLOCKS: rdata_reg <= blocks_reg;
            `WM_ACCEL_MAX_WIDTH: rdata_reg <= MAX_WIDTH_W;
            `WM_ACCEL_MAX_HEIGHT: rdata_reg <= MAX_HEIGHT_W;
            `WM_ACCEL_MAX_LEVELS: rdata_reg <= MAX_LEVELS_W;
            default: rdata_reg <= 32'd0;
        endcase
    end

    if (reg_write && !busy) begin
        // configuration: held while busy
        case (bus_addr)
            `WM_ACCEL_WIDTH: width_reg <= bus_wdata[15:0];
            `WM_ACCEL_HEIGHT: height_reg <= bus_wdata[15:0];
            `WM_ACCEL_LEVELS: levels_reg <= bus_wdata[3:0];
            `WM_ACCEL_TAU: tau_reg <= bus_wdata[17:0];
            default: begin
                // CTRL is handled below; read-only and unmapped: ignored
            end
        endcase
    end

    if (rst) begin
        rdata_reg <= 32'd0;
        width_reg <= 16'd0;
        height_reg <= 16'd0;
        levels_reg <= 4'd0;
        tau_reg <= 18'd0;
    end
end

/*
 * Height stream: the W H samples in raster order, asked for in the last set-up cycle
 */
reg [31:0] rd_left_reg = 32'd0;  // samples still to take

wire smp_tvalid = state_reg == STATE_RUN && rd_left_reg != 32'd0 && s_axis_height_tvalid;
wire smp_tready;
wire smp_fire = smp_tvalid && smp_tready;
assign s_axis_height_tready = state_reg == STATE_RUN && rd_left_reg != 32'd0 && smp_tready;

wire setup_last = state_reg == STATE_SETUP && setup_level_reg == SETUP_END;

/*
 * Fork register and coefficient writer
 */
wire [69:0] rec_tdata;
wire [35:0] rec_tuser;
wire rec_tvalid, rec_tready, rec_tlast;

reg [69:0] buf_data_reg = 70'd0;
reg [35:0] buf_user_reg = 36'd0;
wire [3:0] buf_level = buf_user_reg[35:32];
reg buf_last_reg = 1'b0;
reg buf_valid_reg = 1'b0;
reg [1:0] wr_cnt_reg = 2'd0;   // details written (3: all)
reg tl_sent_reg = 1'b0;        // tlut_stage has taken the record

wire tl_tready;
wire tl_tvalid = buf_valid_reg && !tl_sent_reg;
wire tl_fire = tl_tvalid && tl_tready;
wire wr_active = buf_valid_reg && wr_cnt_reg != 2'd3;
wire wr_fire = wr_active && m_axis_coef_tready;
wire wr_last = (wr_cnt_reg == 2'd2 && wr_fire) || wr_cnt_reg == 2'd3;
wire buf_finish = buf_valid_reg && wr_last && (tl_sent_reg || tl_fire);
assign rec_tready = !buf_valid_reg || buf_finish;

reg [17:0] wr_detail;
always @* begin
    case (wr_cnt_reg)
        2'd0: wr_detail = buf_data_reg[33:16];  // d1
        2'd1: wr_detail = buf_data_reg[51:34];  // d2
        default: wr_detail = buf_data_reg[69:52]; // d3
    endcase
end

wire [CAW:0] wr_base = ptr_reg[buf_level];
wire [CAW:0] wr_addr = wr_base + {{(CAW-1){1'b0}}, wr_cnt_reg};

assign m_axis_coef_tvalid = wr_active;
assign m_axis_coef_tuser = wr_addr[CAW-1:0];
assign m_axis_coef_tdata = wr_detail;

/*
 * Template entries
 */
wire [95:0] tri_tdata;
wire [44:0] tri_tuser;
wire tri_tvalid, tri_tlast;
wire tl_cfg_error;

wire block_end = tri_tvalid && tri_tuser[44];
// a block's last beat waits for TOUT's stream; the other beats are dropped at once
wire tri_tready = !block_end || (state_reg == STATE_RUN && m_axis_tout_tready);
wire tri_fire = tri_tvalid && tri_tready;

assign m_axis_tout_tvalid = state_reg == STATE_RUN && block_end;
assign m_axis_tout_tuser = blocks_reg[TAW-1:0];
assign m_axis_tout_tdata = {7'd0, tri_tuser[11:9], tri_tuser[8:3]};

/*
 * Set-up checks (valid in the last set-up cycle)
 */
wire [31:0] samples = width_reg * height_reg;
wire [31:0] blocks = cols_reg * rows_reg;
wire cfg_bad = width_reg < 16'd2 || height_reg < 16'd2 || {16'd0, width_reg} > MAX_WIDTH_W
    || {16'd0, height_reg} > MAX_HEIGHT_W || levels_reg == 4'd0 || {28'd0, levels_reg} > MAX_LEVELS_W
    || samples > HEIGHT_SAMPLES_W || coef_total_reg > {2'd0, COEF_ENTRIES_W} || blocks > TOUT_ENTRIES_W
    || {16'd0, cols_reg} > MAX_COLS_W || tl_cfg_error;

wire [31:0] cells = cw_reg * ch_reg;

assign height_start = setup_last && !cfg_bad;
assign height_count = samples;

always @(posedge clk) begin
    if (busy) begin
        cyc_reg <= cyc_reg + 32'd1;
    end

    case (state_reg)
        STATE_IDLE: begin
            // wait for START
            if (start) begin
                state_reg <= STATE_SETUP;
                done_reg <= 1'b0;
                error_reg <= 1'b0;
                cyc_reg <= 32'd1;
                setup_level_reg <= 5'd1;
                cw_reg <= (width_reg + 16'd1) >> 1;
                ch_reg <= (height_reg + 16'd1) >> 1;
                bw_reg <= width_reg >> 1;   // ceil((W-1) / 2)
                bh_reg <= height_reg >> 1;
                cols_reg <= 16'd0;
                rows_reg <= 16'd0;
                coef_total_reg <= 34'd0;
                coefs_reg <= 32'd0;
                blocks_reg <= 32'd0;
                cyc_filter_reg <= 32'd0;
                cyc_template_reg <= 32'd0;
                cyc_total_reg <= 32'd0;
            end
        end
        STATE_SETUP: begin
            if (setup_last) begin
                // checks done: run, or refuse
                if (cfg_bad) begin
                    state_reg <= STATE_IDLE;
                    done_reg <= 1'b1;
                    error_reg <= 1'b1;
                    cyc_total_reg <= cyc_reg;
                end else begin
                    state_reg <= STATE_RUN;
                    rd_left_reg <= samples;
                    filter_done_reg <= 1'b0;
                    template_done_reg <= 1'b0;
                end
            end else begin
                // level setup_level: its base, then the next level's cells
                setup_level_reg <= setup_level_reg + 5'd1;
                if (setup_level_reg <= {1'b0, levels_reg}) begin
                    ptr_reg[setup_level_reg[3:0]] <= coef_total_reg[CAW:0];
                    coef_total_reg <= coef_total_reg + {cells, 1'b0} + {2'd0, cells};
                end
                if (setup_level_reg == {1'b0, levels_reg}) begin
                    cols_reg <= bw_reg;
                    rows_reg <= bh_reg;
                end
                cw_reg <= (cw_reg + 16'd1) >> 1;
                ch_reg <= (ch_reg + 16'd1) >> 1;
                bw_reg <= (bw_reg + 16'd1) >> 1;
                bh_reg <= (bh_reg + 16'd1) >> 1;
            end
        end
        default: begin
            // STATE_RUN: the reader, the writer and the template entries (below) until both ends
            // and the SDRAM has every entry
            if (filter_done_reg && template_done_reg && mem_idle) begin
                state_reg <= STATE_IDLE;
                done_reg <= 1'b1;
                cyc_total_reg <= cyc_reg;
            end
        end
    endcase

    if (state_reg == STATE_RUN) begin
        // height stream
        if (smp_fire) begin
            rd_left_reg <= rd_left_reg - 32'd1;
        end

        // fork register: load, write three details, hand to tlut_stage, free
        if (rec_tvalid && rec_tready) begin
            buf_data_reg <= rec_tdata;
            buf_user_reg <= rec_tuser;
            buf_last_reg <= rec_tlast;
            buf_valid_reg <= 1'b1;
            wr_cnt_reg <= 2'd0;
            tl_sent_reg <= 1'b0;
        end else if (buf_finish) begin
            buf_valid_reg <= 1'b0;
        end else begin
            if (wr_fire) begin
                wr_cnt_reg <= wr_cnt_reg + 2'd1;
            end
            if (tl_fire) begin
                tl_sent_reg <= 1'b1;
            end
        end
        if (wr_fire) begin
            coefs_reg <= coefs_reg + 32'd1;
        end
        if (buf_finish) begin
            ptr_reg[buf_level] <= wr_base + 3;
            if (buf_last_reg) begin
                filter_done_reg <= 1'b1;
                cyc_filter_reg <= cyc_reg;
            end
        end

        // template entries: one per block, at its block_end beat
        if (block_end && tri_fire) begin
            blocks_reg <= blocks_reg + 32'd1;
        end
        if (tri_fire && tri_tlast) begin
            template_done_reg <= 1'b1;
            cyc_template_reg <= cyc_reg;
        end
    end

    if (rst) begin
        state_reg <= STATE_IDLE;
        done_reg <= 1'b0;
        error_reg <= 1'b0;
        buf_valid_reg <= 1'b0;
        rd_left_reg <= 32'd0;
        filter_done_reg <= 1'b0;
        template_done_reg <= 1'b0;
    end
end

/*
 * The filter bank and the template stage
 */
wire bank_busy_unused, bank_frame_done_unused;

`ifdef WM_SIM_STAGE_GATE
// The simulator's clock gate (sim/build.py defines WM_SIM_STAGE_GATE; the bitstream has no gate and
// clocks both units with clk itself, no other net): an edge reaches haar_bank and tlut_stage only
// while the stage runs (SETUP, RUN) or resets.  Outside a frame neither unit takes a beat (their
// valids and readies are low) and what their registers would load there is never read (docs/soc.md,
// "The simulated board": why this is exact, and the test that compares the cycles and the meshes with
// the ungated build).  The enable is latched while the clock is low, so that the gated edge comes in
// the same evaluation as clk's and sees the values from before the edge, as every other register does
// (sim_clock_gate).
wire stage_clk_en = state_reg != STATE_IDLE || rst;
wire stage_clk;
sim_clock_gate stage_gate_inst (.clk(clk), .en(stage_clk_en), .gclk(stage_clk));
`endif

haar_bank #(
    .MAX_WIDTH(MAX_WIDTH),
    .MAX_HEIGHT(MAX_HEIGHT),
    .MAX_LEVELS(MAX_LEVELS)
) bank_inst (
`ifdef WM_SIM_STAGE_GATE
    .clk(stage_clk),
`else
    .clk(clk),
`endif
    .rst(rst),
    .cfg_width(width_reg),
    .cfg_height(height_reg),
    .cfg_levels(levels_reg),
    .s_axis_tdata(s_axis_height_tdata),
    .s_axis_tvalid(smp_tvalid),
    .s_axis_tready(smp_tready),
    .m_axis_tdata(rec_tdata),
    .m_axis_tuser(rec_tuser),
    .m_axis_tvalid(rec_tvalid),
    .m_axis_tready(rec_tready && state_reg == STATE_RUN),
    .m_axis_tlast(rec_tlast),
    .busy(bank_busy_unused),
    .frame_done(bank_frame_done_unused)
);

// the triangles' coordinates and block positions are not needed (the firmware expands the template)
wire tri_bits_unused = ^{tri_tdata, tri_tuser[43:12], tri_tuser[2:0]};
// configuration registers are narrower than the bus
wire wdata_bits_unused = ^bus_wdata[31:18];
// the level pointers carry one more bit than the memory's address (the end of the last level)
wire wr_addr_bit_unused = wr_addr[CAW];

tlut_stage #(
    .MAX_COLS(MAX_COLS),
    .EXPAND(0)
) stage_inst (
`ifdef WM_SIM_STAGE_GATE
    .clk(stage_clk),
`else
    .clk(clk),
`endif
    .rst(rst),
    .s_axis_tdata(buf_data_reg),
    .s_axis_tuser(buf_user_reg),
    .s_axis_tvalid(tl_tvalid && state_reg == STATE_RUN),
    .s_axis_tready(tl_tready),
    .s_axis_tlast(buf_last_reg),
    .m_axis_tdata(tri_tdata),
    .m_axis_tuser(tri_tuser),
    .m_axis_tvalid(tri_tvalid),
    .m_axis_tready(tri_tready),
    .m_axis_tlast(tri_tlast),
    .cfg_width(width_reg),
    .cfg_height(height_reg),
    .cfg_levels(levels_reg),
    .cfg_tau(tau_reg),
    .status_cfg_error(tl_cfg_error)
);

endmodule

`resetall
