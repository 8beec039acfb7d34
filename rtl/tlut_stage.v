/*
 * wavemesh template stage: level M's coefficients in, every block's template as triangles out
 * (docs/model.md "Blocks", "Labeller", "Templates", "Initial triangulation"; rtl/README.md).
 *
 *   haar_bank records -> [filter, input register] -> tlut_label -> tlut_resolve -> [template
 *   table] -> block FIFO (wm_fifo) -> tlut_expand -> triangles
 *
 * With S = 2^M there are ceil((W - 1) / S) x ceil((H - 1) / S) blocks; block (j, i) spans
 * x in [iS, min((i + 1)S, W - 1)] (likewise y) and takes its label from level M's coefficients
 * at (j, i).  The stage keeps the records of level M that have a block and drops every other
 * record at full speed (tready high: other levels, and level M's last coefficient column or row
 * when it has no block).  Block row j goes out once row j + 1 is in (its bottom neighbours); the
 * last block row goes out after the frame's last block record, from an internal flush row of
 * flat items.  Positions travel as four flags (first/last row/column) and are counted again
 * where they are needed: everything stays in raster order.
 *
 * Record in (the filter bank's output, haar_bank):
 *
 *   | signal        | bits  | field                                        |
 *   |---------------|-------|----------------------------------------------|
 *   | s_axis_tdata  | 15:0  | a, approximation (not used here)             |
 *   |               | 33:16 | d1, right minus left, two's complement       |
 *   |               | 51:34 | d2, bottom minus top                         |
 *   |               | 69:52 | d3, diagonal minus anti-diagonal             |
 *   | s_axis_tuser  | 15:0  | bx, coefficient column at that level         |
 *   |               | 31:16 | by, coefficient row                          |
 *   |               | 35:32 | level m                                      |
 *   | s_axis_tlast  | 1     | frame's last record (not used: frame ends    |
 *   |               |       | follow from the block coordinates)           |
 *
 * Records of one level come in raster order; levels may interleave.
 *
 * Triangle out, one beat per triangle, blocks in raster order, each block's triangles in
 * template order (tri_index 0..n-1), counter-clockwise:
 *
 *   | signal        | bits  | field                                        |
 *   |---------------|-------|----------------------------------------------|
 *   | m_axis_tdata  | 15:0  | x0  vertex 0 (grid column)                   |
 *   |               | 31:16 | y0  vertex 0 (grid row)                      |
 *   |               | 47:32 | x1  vertex 1                                 |
 *   |               | 63:48 | y1                                           |
 *   |               | 79:64 | x2  vertex 2                                 |
 *   |               | 95:80 | y2                                           |
 *   | m_axis_tuser  | 2:0   | tri_index, triangle in the template          |
 *   |               | 8:3   | template_id (wm_templates.vh)                |
 *   |               | 11:9  | label: F f V v H h D = 0..6                  |
 *   |               | 27:12 | bx, block column                             |
 *   |               | 43:28 | by, block row                                |
 *   |               | 44    | block_end: last triangle of this block       |
 *   | m_axis_tlast  | 1     | last triangle of the frame's last block      |
 *   | m_axis_tuser  | 45    | hole: the block holds an invalid sample      |
 *   |               |       | (only with HOLES = 1; tuser is 45 bits else) |
 *
 * Validity mask in (HOLES = 1 only, --nodata hole, issue 20): s_mask_tdata, one bit per sample in
 * raster order (1: invalid), W * H per frame, on its own valid/ready stream.  tlut_holes turns it
 * into one flag per block (wavemesh.model.holemask.block_flags, closed blocks), block row by block row; a
 * FIFO of HOLES_FIFO_DEPTH flags pairs them with the blocks, which leave in the same order: a beat
 * goes out only with its block's flag at the FIFO's head (tvalid = the triangle's valid AND the
 * flag's), and the flag is taken with the block's block_end beat.  The mask stream waits when that
 * FIFO is full, the triangles when the flag is not in yet; nothing else depends on the mask.  A block
 * row's flags are complete with its last sample row, its templates only with the next block row's
 * records: when the mask and the heights come from one source in lockstep, the FIFO must hold two
 * block rows of flags (HOLES_FIFO_DEPTH >= 2 x block columns, the default) or the two wait for
 * each other.  With
 * HOLES = 0 the mask ports are unused (s_mask_tready low) and the stage is exactly as without them.
 *
 * Throughput: one triangle per cycle; a block takes as many cycles as its template has triangles
 * (2..8), back to back (FIFO_DEPTH = 4 keeps even all-flat frames, 2 cycles per block, gap-free).
 * Kept records are taken one per cycle while the block FIFO has room (credits count every block
 * from the labeller's input to the FIFO's output); row-0 records need no room.  Dropped records
 * are always taken at once.  Latency: 11 cycles from the record that completes a block (the
 * block's bottom neighbour) to its first triangle; the last block row follows the frame's last
 * block record after about one triangle per cycle for the row plus 11.
 *
 * Configuration: hold cfg_* stable while a frame is in flight (change it between frames, with the
 * stage idle, at least 3 cycles before the next frame's first record).  status_cfg_error is high
 * when the configuration is unsupported (W or H < 2, M = 0, more than MAX_COLS block columns);
 * the stage then drops every record and produces nothing.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_stage #(
    // Row-buffer depth: the most block columns a frame may have, ceil((W - 1) / 2^M) <= MAX_COLS
    parameter MAX_COLS = 1024,
    // Blocks buffered between resolver and expander (>= 2, any number)
    parameter FIFO_DEPTH = 4,
    // 1: the expander puts every block's template on the grid (one beat per triangle, as above);
    // 0: no expander (no triangle ROM, no site arithmetic): one beat per block, the block-end beat
    //    alone, with tuser's template id and label, tri_index 0, bx = by = 0 (not counted) and
    //    tdata 0; tlast on the frame's last block.  For a consumer that wants only the templates
    //    (the SoC's TOUT writer, rtl/boards/stage_uart.v).
    parameter EXPAND = 1,
    // 1: take a validity mask and put each block's hole flag on tuser[45] (above); 0: no mask
    parameter HOLES = 0,
    // block flags buffered ahead of their blocks (HOLES = 1), >= 2; a source that sends the mask
    // and the records' samples in lockstep needs two block rows' worth (the default)
    parameter HOLES_FIFO_DEPTH = 2 * MAX_COLS
) (
    input  wire         clk,
    input  wire         rst,

    /*
     * Coefficient records in (from haar_bank)
     */
    input  wire [69:0]  s_axis_tdata,
    input  wire [35:0]  s_axis_tuser,
    input  wire         s_axis_tvalid,
    output wire         s_axis_tready,
    input  wire         s_axis_tlast,

    /*
     * Triangles out
     */
    output wire [95:0]  m_axis_tdata,
    output wire [44+(HOLES ? 1 : 0):0] m_axis_tuser,
    output wire         m_axis_tvalid,
    input  wire         m_axis_tready,
    output wire         m_axis_tlast,

    /*
     * Validity mask in (HOLES = 1): a bit per sample, raster order, 1 = invalid
     */
    input  wire         s_mask_tdata,
    input  wire         s_mask_tvalid,
    output wire         s_mask_tready,

    /*
     * Configuration
     */
    input  wire [15:0]  cfg_width,   // W, samples per row (>= 2)
    input  wire [15:0]  cfg_height,  // H, rows (>= 2)
    input  wire [3:0]   cfg_levels,  // M, blocks are 2^M grid steps (>= 1)
    input  wire [17:0]  cfg_tau,     // threshold in detail units: |d| > tau is significant

    /*
     * Status
     */
    output wire         status_cfg_error
);

`include "wm_templates.vh"

// check configuration
initial begin
    if (MAX_COLS < 1 || MAX_COLS > 32768) begin
        $error("Error: MAX_COLS must be 1..32768 (instance %m)");
        $finish;
    end
    if (WM_TEMPLATE_COUNT > 64 || WM_TEMPLATE_MAX_TRIANGLES > 8) begin
        $error("Error: template ids need 6 bits and triangle counts 4 bits (instance %m)");
        $finish;
    end
end

// credit counter width: counts 0..FIFO_DEPTH
localparam CRED_WIDTH = $clog2(FIFO_DEPTH) + 1;
// resolver sideband, for the block it completes: {top row, first column, last row, last column}
// (positions are counted again where they are needed: blocks stay in raster order)
localparam RES_USER_WIDTH = 4;
// labeller sideband: {item in row 0, item in column 0, resolver sideband}
localparam LABEL_USER_WIDTH = 2 + RES_USER_WIDTH;
// FIFO entry: {resolver sideband, label, template id, number of triangles}: 17 bits
localparam FIFO_WIDTH = RES_USER_WIDTH + 3 + 6 + 4;

/*
 * Block geometry from the configuration.  The configuration is static, so it goes through three
 * register stages instead of one long path: it must be in place 3 cycles before the first record.
 */
reg [15:0] xmax_reg = 16'd0;          // W - 1
reg [15:0] ymax_reg = 16'd0;          // H - 1
reg [15:0] wm2_reg = 16'd0;           // W - 2
reg [15:0] hm2_reg = 16'd0;           // H - 2
reg [15:0] step_mask_reg = 16'd0;     // S - 1
reg        size_ok_reg = 1'b0;        // W, H >= 2, M >= 1

reg [15:0] cols_m1_reg = 16'd0;       // block columns - 1 = (W - 2) >> M
reg [15:0] rows_m1_reg = 16'd0;       // block rows - 1
reg        narrow_last_reg = 1'b0;    // the last block column is 1 grid step wide
reg        low_last_reg = 1'b0;       // the last block row is 1 grid step high
reg        cfg_ok_reg = 1'b0;

reg [15:0] last_x0_reg = 16'd0;       // x0 of the last block column
reg [15:0] last_y0_reg = 16'd0;       // y0 of the last block row
reg [15:0] last_xw_reg = 16'd0;       // its width, W - 1 - x0
reg [15:0] last_yw_reg = 16'd0;
reg [15:0] last_xm_reg = 16'd0;       // its middle, x0 + (W - 1 - x0) / 2
reg [15:0] last_ym_reg = 16'd0;

always @(posedge clk) begin
    // stage 1
    xmax_reg <= cfg_width - 16'd1;
    ymax_reg <= cfg_height - 16'd1;
    wm2_reg <= cfg_width - 16'd2;
    hm2_reg <= cfg_height - 16'd2;
    step_mask_reg <= 16'hffff >> (5'd16 - {1'b0, cfg_levels});
    size_ok_reg <= cfg_width >= 16'd2 && cfg_height >= 16'd2 && cfg_levels != 4'd0;
    // stage 2
    cols_m1_reg <= wm2_reg >> cfg_levels;
    rows_m1_reg <= hm2_reg >> cfg_levels;
    narrow_last_reg <= (xmax_reg & step_mask_reg) == 16'd1;
    low_last_reg <= (ymax_reg & step_mask_reg) == 16'd1;
    cfg_ok_reg <= size_ok_reg && (wm2_reg >> cfg_levels) < MAX_COLS;
    last_x0_reg <= wm2_reg & ~step_mask_reg;  // (W - 2) >> M << M
    last_y0_reg <= hm2_reg & ~step_mask_reg;
    last_xw_reg <= (wm2_reg & step_mask_reg) + 16'd1;  // its width, W - 1 - x0: 1 .. S
    last_yw_reg <= (hm2_reg & step_mask_reg) + 16'd1;
    // stage 3: x0 + width / 2, an OR: x0 is a multiple of S, width / 2 < S
    last_xm_reg <= last_x0_reg | (last_xw_reg >> 1);
    last_ym_reg <= last_y0_reg | (last_yw_reg >> 1);
end

assign status_cfg_error = !cfg_ok_reg;

/*
 * Input register, flush row and credits
 */
wire [15:0] in_bx = s_axis_tuser[15:0];
wire [15:0] in_by = s_axis_tuser[31:16];
wire [3:0]  in_level = s_axis_tuser[35:32];

// a record with a mesh block at the configured level (all others are dropped on arrival)
wire in_block = cfg_ok_reg && in_level == cfg_levels && in_by <= rows_m1_reg && in_bx <= cols_m1_reg;

// the kept record waiting for the labeller, with its position decoded on arrival
reg         rec_valid_reg = 1'b0, rec_valid_next;
reg [53:0]  rec_d_reg = 54'd0;          // {d3, d2, d1}
reg         rec_first_row_reg = 1'b0;   // by = 0: completes no block
reg         rec_top_row_reg = 1'b0;     // by = 1: completes a block of row 0
reg         rec_first_col_reg = 1'b0;
reg         rec_last_row_reg = 1'b0;
reg         rec_last_col_reg = 1'b0;

reg                  flush_reg = 1'b0, flush_next;     // feeding the flush row
reg [15:0]           flush_col_reg = 16'd0, flush_col_next;
reg [CRED_WIDTH-1:0] cred_reg = {CRED_WIDTH{1'b0}}, cred_next;  // blocks in flight or in the FIFO

wire fifo_pop;

wire cred_ok = cred_reg != FIFO_DEPTH[CRED_WIDTH-1:0];
// the waiting record goes to the labeller: row-0 records complete no block and need no credit;
// the flush row goes first
wire take = rec_valid_reg && !flush_reg && (rec_first_row_reg || cred_ok);
wire inject = flush_reg && cred_ok;
wire flush_last_col = flush_col_reg == cols_m1_reg;
// the register takes a kept record when it is (being) emptied; its data registers load whatever
// arrives then (short enable path: no comparison), and only a kept record makes it valid
wire rec_free = !rec_valid_reg || take;
wire rec_load = s_axis_tvalid && in_block && rec_free;

assign s_axis_tready = !in_block || rec_free;

always @* begin
    rec_valid_next = rec_valid_reg && !take;
    flush_next = flush_reg;
    flush_col_next = flush_col_reg;
    cred_next = cred_reg;

    if (rec_load) begin
        // a kept record arrives
        rec_valid_next = 1'b1;
    end

    if (take && rec_last_row_reg && rec_last_col_reg) begin
        // the frame's last block is in: flush its last block row
        flush_next = 1'b1;
        flush_col_next = 16'd0;
    end

    if (inject) begin
        // one flush item per cycle, across every block column
        flush_col_next = flush_col_reg + 16'd1;
        if (flush_last_col) begin
            flush_next = 1'b0;
        end
    end

    // a place in the FIFO for every item that completes a block
    if (((take && !rec_first_row_reg) || inject) && !fifo_pop) begin
        cred_next = cred_reg + 1'b1;
    end else if (!((take && !rec_first_row_reg) || inject) && fifo_pop) begin
        cred_next = cred_reg - 1'b1;
    end
end

always @(posedge clk) begin
    rec_valid_reg <= rec_valid_next;
    flush_reg <= flush_next;
    flush_col_reg <= flush_col_next;
    cred_reg <= cred_next;

    if (rec_free) begin
        rec_d_reg <= s_axis_tdata[69:16];
        rec_first_row_reg <= in_by == 16'd0;
        rec_top_row_reg <= in_by == 16'd1;
        rec_first_col_reg <= in_bx == 16'd0;
        rec_last_row_reg <= in_by == rows_m1_reg;
        rec_last_col_reg <= in_bx == cols_m1_reg;
    end

    if (rst) begin
        rec_valid_reg <= 1'b0;
        flush_reg <= 1'b0;
        flush_col_reg <= 16'd0;
        cred_reg <= {CRED_WIDTH{1'b0}};
    end
end

// the item entering the labeller: the taken record or a flush-row item (all details 0: flat);
// a record of row j completes block (j - 1, i), a flush item block (rows - 1, i)
wire [53:0] item_d = flush_reg ? 54'd0 : rec_d_reg;
wire        item_first_col = flush_reg ? flush_col_reg == 16'd0 : rec_first_col_reg;
wire        item_last_col = flush_reg ? flush_last_col : rec_last_col_reg;
wire        item_last_row = !flush_reg && rec_last_row_reg;

/*
 * Labeller
 */
wire                        lab_valid;
wire [2:0]                  lab_label;
wire [LABEL_USER_WIDTH-1:0] lab_user;

tlut_label #(
    .USER_WIDTH(LABEL_USER_WIDTH)
)
label_inst (
    .clk(clk),
    .rst(rst),
    .s_valid(take || inject),
    .s_d1(item_d[17:0]),
    .s_d2(item_d[35:18]),
    .s_d3(item_d[53:36]),
    .s_narrow(item_last_col && narrow_last_reg),
    .s_low(item_last_row && low_last_reg),
    .s_user({
        !flush_reg && rec_first_row_reg,                     // item in row 0
        item_first_col,                                      // item in column 0
        flush_reg ? rows_m1_reg == 16'd0 : rec_top_row_reg,  // block in row 0
        item_first_col,                                      // block in column 0
        flush_reg,                                           // block in the last row
        item_last_col                                        // block in the last column
    }),
    .m_valid(lab_valid),
    .m_label(lab_label),
    .m_user(lab_user),
    .cfg_tau(cfg_tau)
);

/*
 * Variant resolver
 */
wire                      res_valid;
wire [2:0]                res_label;
wire [3:0]                res_mask;
wire [RES_USER_WIDTH-1:0] res_user;

tlut_resolve #(
    .MAX_COLS(MAX_COLS),
    .USER_WIDTH(RES_USER_WIDTH)
)
resolve_inst (
    .clk(clk),
    .rst(rst),
    .s_valid(lab_valid),
    .s_label(lab_label),
    .s_first_row(lab_user[5]),
    .s_first_col(lab_user[4]),
    .s_last_col(lab_user[0]),
    .s_user(lab_user[3:0]),
    .m_valid(res_valid),
    .m_label(res_label),
    .m_mask(res_mask),
    .m_user(res_user)
);

/*
 * Template look-up (before the FIFO: short paths on both sides of it), block FIFO and expansion
 */
// {template id, number of triangles} per {label, mask}: the generated table and ROM folded into one
// 128-entry table at elaboration (a 7-input function instead of two chained ones)
function [9:0] template_entry;
    input [6:0] index;
    reg [7:0] id;
    reg [WM_TPL_WORD_BITS-1:0] word;
    begin
        id = wm_template_lut(index);  // 0xFF (no template) only for pairs that cannot occur
        word = wm_template_rom(id[5:0]);
        template_entry = {id[5:0], word[WM_TPL_WORD_BITS-1 -: 4]};
    end
endfunction

reg [9:0] template_table[0:127];

integer n;

initial begin
    for (n = 0; n < 128; n = n + 1) begin
        template_table[n] = template_entry(n[6:0]);
    end
end

wire [9:0] res_template = template_table[{res_label, res_mask}];

wire                  fifo_ready;
wire                  fifo_valid;
wire [FIFO_WIDTH-1:0] fifo_data;
wire [$clog2(FIFO_DEPTH+1)-1:0] fifo_count_unused;
wire                  exp_ready;

// the triangle stream before the hole flags join it (HOLES = 0: the output itself)
wire [95:0] st_tdata;
wire [44:0] st_tuser;
wire        st_tvalid;
wire        st_tready;
wire        st_tlast;

assign fifo_pop = fifo_valid && exp_ready;

// The resolver cannot wait: the credits guarantee the FIFO room for every block it writes
// (credits count blocks from the labeller's input to the FIFO's output, at most FIFO_DEPTH, so
// the FIFO holds at most FIFO_DEPTH - 1 when a block arrives and s_ready is high).
wm_fifo #(
    .DATA_WIDTH(FIFO_WIDTH),
    .DEPTH(FIFO_DEPTH)
)
fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data({res_user, res_label, res_template}),
    .s_valid(res_valid),
    .s_ready(fifo_ready),
    .m_data(fifo_data),
    .m_valid(fifo_valid),
    .m_ready(exp_ready),
    .count(fifo_count_unused)
);

`ifndef SYNTHESIS
// simulation only: a block the FIFO refused would be lost (a credit-accounting error)
always @(posedge clk) begin
    if (!rst && res_valid && !fifo_ready) begin
        $error("Error: block FIFO full when the resolver wrote (instance %m)");
    end
end
`endif

generate
if (EXPAND) begin : g_expand

tlut_expand
expand_inst (
    .clk(clk),
    .rst(rst),
    .s_valid(fifo_valid),
    .s_ready(exp_ready),
    .s_first_row(fifo_data[16]),
    .s_first_col(fifo_data[15]),
    .s_last_row(fifo_data[14]),
    .s_last_col(fifo_data[13]),
    .s_label(fifo_data[12:10]),
    .s_tid(fifo_data[9:4]),
    .s_ntri(fifo_data[3:0]),
    .m_axis_tdata(st_tdata),
    .m_axis_tuser(st_tuser),
    .m_axis_tvalid(st_tvalid),
    .m_axis_tready(st_tready),
    .m_axis_tlast(st_tlast),
    .cfg_levels(cfg_levels),
    .cfg_xmax(xmax_reg),
    .cfg_ymax(ymax_reg),
    .cfg_last_xm(last_xm_reg),
    .cfg_last_ym(last_ym_reg)
);

end else begin : g_blocks

// one beat per block, straight from the block FIFO (its flags are registers, its data the FIFO's
// read port)
assign exp_ready = st_tready;
assign st_tvalid = fifo_valid;
assign st_tdata = 96'd0;
assign st_tuser = {1'b1, 32'd0, fifo_data[12:10], fifo_data[9:4], 3'd0};
assign st_tlast = fifo_data[14] && fifo_data[13];

// the expander's inputs that are not needed: the other flags, the triangle count, the geometry
wire unused_blocks = &{1'b0, fifo_data[16:15], fifo_data[3:0], last_xm_reg, last_ym_reg};

end
endgenerate

/*
 * Hole flags (HOLES = 1): the mask's block flags, in block order, joined to the triangles
 */
generate
if (HOLES) begin : g_holes

wire hole_flag;
wire hole_valid;
wire hole_ready;
wire flag_valid;
wire flag_data;
wire [$clog2(HOLES_FIFO_DEPTH+1)-1:0] flag_count_unused;

tlut_holes #(
    .MAX_COLS(MAX_COLS < 2 ? 2 : MAX_COLS)
)
holes_inst (
    .clk(clk),
    .rst(rst),
    .cfg_width(cfg_width),
    .cfg_height(cfg_height),
    .cfg_levels(cfg_levels),
    .s_data(s_mask_tdata),
    .s_valid(s_mask_tvalid),
    .s_ready(s_mask_tready),
    .m_data(hole_flag),
    .m_valid(hole_valid),
    .m_ready(hole_ready)
);

wm_fifo #(
    .DATA_WIDTH(1),
    .DEPTH(HOLES_FIFO_DEPTH)
)
flag_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(hole_flag),
    .s_valid(hole_valid),
    .s_ready(hole_ready),
    .m_data(flag_data),
    .m_valid(flag_valid),
    .m_ready(m_axis_tvalid && m_axis_tready && st_tuser[44]),  // the block's last beat moves
    .count(flag_count_unused)
);

// a beat leaves only beside its block's flag; both valids hold until taken, so their AND does too
assign m_axis_tvalid = st_tvalid && flag_valid;
assign st_tready = m_axis_tready && flag_valid;
assign m_axis_tdata = st_tdata;
assign m_axis_tuser = {flag_data, st_tuser};
assign m_axis_tlast = st_tlast;

end else begin : g_no_holes

assign m_axis_tvalid = st_tvalid;
assign st_tready = m_axis_tready;
assign m_axis_tdata = st_tdata;
assign m_axis_tuser = st_tuser;
assign m_axis_tlast = st_tlast;
assign s_mask_tready = 1'b0;

// no mask without HOLES
wire unused_mask = &{1'b0, s_mask_tdata, s_mask_tvalid};

end
endgenerate

// the approximation and the input tlast are not needed
wire unused_in = &{1'b0, s_axis_tdata[15:0], s_axis_tlast};

endmodule

`resetall
