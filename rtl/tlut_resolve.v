/*
 * wavemesh template stage: the variant resolver (docs/model.md "Templates", variant resolution).
 *
 * A side of a block gets a midpoint when either block sharing it asks for one: V/v blocks split
 * their top and bottom sides, H/h blocks their left and right sides.  A block's split mask (bit 0
 * top, 1 left, 2 right, 3 bottom) therefore needs the labels of its four neighbours; the template
 * id is the look-up table entry wm_template_lut({label, mask}), read after this (tlut_stage).
 *
 * Streaming over labels in raster order with one row buffer of MAX_COLS entries
 * {label[2:0], vtop} (vtop: the block above is V/v), no frame buffer.  Item (j, i) carries the
 * label of block (j, i); it completes block (j - 1, i), whose right neighbour (j - 1, i + 1) is
 * still in the buffer.  So block row j - 1 comes out while row j goes in, and the caller appends
 * one row of flat items (row = block rows) to flush the last block row.  Items of row 0 only fill
 * the buffer.
 *
 * Per item, the buffer is read at column i + 1 (at 0 after the last column: the next row's first
 * block) and written at column i, so it maps to one simple dual-port block RAM.  The column is
 * counted here from the items' flags (raster order), the next item's i and i + 1 kept ready in
 * registers so that no adder sits in front of the RAM's address ports.
 *
 * Item in (one per cycle at most, no back-pressure):
 *
 *   | field       | meaning                                              |
 *   |-------------|------------------------------------------------------|
 *   | s_label     | label of block (j, i) (F/f for the flush row)         |
 *   | s_first_row | j == 0: nothing above, nothing comes out              |
 *   | s_first_col | i == 0: nothing to the left                           |
 *   | s_last_col  | i is the last block column: nothing to the right      |
 *   | s_user      | sideband, comes out with block (j - 1, i)             |
 *
 * Block out, 3 cycles after its completing item: m_label (block (j - 1, i)), m_mask and the
 * completing item's s_user.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_resolve #(
    // Row-buffer depth: the most block columns a frame may have (ceil((W - 1) / 2^M) <= MAX_COLS)
    parameter MAX_COLS = 1024,
    // Width of the sideband s_user (bits, >= 1)
    parameter USER_WIDTH = 1
) (
    input  wire                  clk,
    input  wire                  rst,

    /*
     * Label item in
     */
    input  wire                  s_valid,
    input  wire [2:0]            s_label,
    input  wire                  s_first_row,
    input  wire                  s_first_col,
    input  wire                  s_last_col,
    input  wire [USER_WIDTH-1:0] s_user,

    /*
     * Resolved block out
     */
    output wire                  m_valid,
    output wire [2:0]            m_label,
    output wire [3:0]            m_mask,
    output wire [USER_WIDTH-1:0] m_user
);

// row-buffer address width
localparam ADDR_WIDTH = MAX_COLS > 1 ? $clog2(MAX_COLS) : 1;

// split-mask bits
localparam [3:0] SIDE_TOP = 4'd1;
localparam [3:0] SIDE_LEFT = 4'd2;
localparam [3:0] SIDE_RIGHT = 4'd4;
localparam [3:0] SIDE_BOTTOM = 4'd8;

// check configuration
initial begin
    if (MAX_COLS < 1) begin
        $error("Error: MAX_COLS must be at least 1 (instance %m)");
        $finish;
    end
    if (USER_WIDTH < 1) begin
        $error("Error: USER_WIDTH must be at least 1 (instance %m)");
        $finish;
    end
end

// V/v and H/h label codes are 2, 3 and 4, 5: kind (label >> 1) 1 and 2
function is_vert;
    input [1:0] kind;
    begin
        is_vert = kind == 2'd1;
    end
endfunction

function is_horiz;
    input [1:0] kind;
    begin
        is_horiz = kind == 2'd2;
    end
endfunction

// Row buffer: entry i holds {label, vtop} of block (j - 1, i) before item (j, i), of (j, i) after
reg [3:0]            buf_mem[0:MAX_COLS-1];
reg [3:0]            buf_rd_reg = 4'd0;
// a read and a write of the same entry (one block column): take the written value
reg                  byp_reg = 1'b0;
reg [3:0]            byp_data_reg = 4'd0;
// H/h-ness of the block left of the current one, (j - 1, i - 1)
reg                  left_h_reg = 1'b0;

// stage R2: the block (j - 1, i) waiting for its right neighbour's read
reg                  r2_valid_reg = 1'b0;
reg [2:0]            r2_label_reg = 3'd0;
reg                  r2_vtop_reg = 1'b0;
reg                  r2_left_h_reg = 1'b0;
reg                  r2_bottom_v_reg = 1'b0;
reg                  r2_last_col_reg = 1'b0;
reg [USER_WIDTH-1:0] r2_user_reg = {USER_WIDTH{1'b0}};

// stage R3: the mask but for its right side, and the right neighbour's H/h-ness (short paths
// out of the row buffer's read port)
reg                  r3_valid_reg = 1'b0;
reg [2:0]            r3_label_reg = 3'd0;
reg [3:0]            r3_mask_reg = 4'd0;
reg                  r3_right_h_reg = 1'b0;
reg [USER_WIDTH-1:0] r3_user_reg = {USER_WIDTH{1'b0}};

// output registers
reg                  m_valid_reg = 1'b0;
reg [2:0]            m_label_reg = 3'd0;
reg [3:0]            m_mask_reg = 4'd0;
reg [USER_WIDTH-1:0] m_user_reg = {USER_WIDTH{1'b0}};

assign m_valid = m_valid_reg;
assign m_label = m_label_reg;
assign m_mask = m_mask_reg;
assign m_user = m_user_reg;

// the entry read by the last item: (j - 1, i) for the item in R1, (j - 1, i + 1) for R2's
wire [3:0]            cur = byp_reg ? byp_data_reg : buf_rd_reg;
wire [2:0]            cur_label = cur[3:1];
wire                  cur_vtop = cur[0];

// column i of the item and i + 1, i + 2 for the next one
reg  [ADDR_WIDTH-1:0] next_addr_reg = {ADDR_WIDTH{1'b0}};
reg  [ADDR_WIDTH-1:0] next2_addr_reg = {ADDR_WIDTH{1'b0}};
wire [ADDR_WIDTH-1:0] one = {{ADDR_WIDTH-1{1'b0}}, 1'b1};
wire [ADDR_WIDTH-1:0] wr_addr = s_first_col ? {ADDR_WIDTH{1'b0}} : next_addr_reg;
wire [ADDR_WIDTH-1:0] wr_addr_inc = s_first_col ? one : next2_addr_reg;  // i + 1
wire [ADDR_WIDTH-1:0] rd_addr = s_last_col ? {ADDR_WIDTH{1'b0}} : wr_addr_inc;
// block (j, i) has a V/v block above it: none on row 0
wire [3:0]            wr_data = {s_label, !s_first_row && is_vert(cur_label[2:1])};

// R2: the mask of block (j - 1, i); cur now holds its right neighbour
wire [3:0]            r2_mask = ((r2_vtop_reg || is_vert(r2_label_reg[2:1])) ? SIDE_TOP : 4'd0)
                              | ((r2_left_h_reg || is_horiz(r2_label_reg[2:1])) ? SIDE_LEFT : 4'd0)
                              | (is_horiz(r2_label_reg[2:1]) ? SIDE_RIGHT : 4'd0)
                              | ((r2_bottom_v_reg || is_vert(r2_label_reg[2:1])) ? SIDE_BOTTOM : 4'd0);

always @(posedge clk) begin
    // R1: write (j, i), read the entry the next item needs
    if (s_valid) begin
        buf_mem[wr_addr] <= wr_data;
        buf_rd_reg <= buf_mem[rd_addr];
        byp_reg <= rd_addr == wr_addr;
        byp_data_reg <= wr_data;
        left_h_reg <= is_horiz(cur_label[2:1]);
        next_addr_reg <= wr_addr_inc;
        next2_addr_reg <= wr_addr_inc + one;
    end

    r2_valid_reg <= s_valid && !s_first_row;
    r2_label_reg <= cur_label;
    r2_vtop_reg <= cur_vtop;
    r2_left_h_reg <= !s_first_col && left_h_reg;
    r2_bottom_v_reg <= is_vert(s_label[2:1]);
    r2_last_col_reg <= s_last_col;
    r2_user_reg <= s_user;

    // R2 -> R3
    r3_valid_reg <= r2_valid_reg;
    r3_label_reg <= r2_label_reg;
    r3_mask_reg <= r2_mask;
    r3_right_h_reg <= !r2_last_col_reg && is_horiz(cur_label[2:1]);
    r3_user_reg <= r2_user_reg;

    // R3 -> out
    m_valid_reg <= r3_valid_reg;
    m_label_reg <= r3_label_reg;
    m_mask_reg <= r3_mask_reg | (r3_right_h_reg ? SIDE_RIGHT : 4'd0);
    m_user_reg <= r3_user_reg;

    if (rst) begin
        r2_valid_reg <= 1'b0;
        r3_valid_reg <= 1'b0;
        m_valid_reg <= 1'b0;
    end
end


endmodule

`resetall
