/*
 * wavemesh template stage: template expansion (docs/model.md "Initial triangulation").
 *
 * Takes one block (its template id from wm_template_lut, looked up by the caller) per handshake,
 * reads its triangles from the generated template ROM wm_template_rom(id) (wm_templates.vh,
 * `make gen`), and puts the template on the block's grid positions: one output beat per triangle,
 * counter-clockwise as in the template.  Sites in column 0, 1, 2 sit at x0, xm, x1:
 *
 *   x0 = col * 2^M,  x1 = min(x0 + 2^M, W - 1),  xm = x0 + (x1 - x0) / 2 (floor); likewise y.
 *
 * Blocks come in raster order, so their row and column are counted here from their flags, x0 is
 * the previous block's x1 (0 at a row's start) and y0 the previous row's y1; only the last block
 * column (row) can be cut short, and its middle comes precomputed with the configuration
 * (cfg_last_xm, cfg_last_ym).  Other blocks have x1 = x0 + 2^M, xm = x0 + 2^(M-1) (x0 is a
 * multiple of 2^M).  The sums x1 + 2^M, y1 + 2^M, i + 1, j + 1 for the next block are registered
 * while a block is in the block stage (every template has at least 2 triangles, so it stays there
 * 2 cycles or more; checked at elaboration), which keeps adders out of the block-loading path.
 *
 * Triangle ROM: wm_template_rom's words rearranged at elaboration into one 12-bit entry {c, b, a}
 * per (template id, triangle index), 512 x 12 bits read synchronously: one block RAM (ECP5
 * DP16KD; two SB_RAM40_4K on iCE40).  The number of triangles comes with the block.
 *
 * Pipeline: block stage (the block whose triangles are being issued, triangle index k) -> ROM read
 * stage (the triangle's sites) -> output register.  Each stage holds when the next one is full.
 *
 * Block in (valid/ready):
 *
 *   | field       | bits | meaning                                         |
 *   |-------------|------|-------------------------------------------------|
 *   | s_first_row | 1    | j = 0                                           |
 *   | s_first_col | 1    | i = 0                                           |
 *   | s_last_row  | 1    | j is the last block row                         |
 *   | s_last_col  | 1    | i is the last block column                      |
 *   | s_label     | 3    | label code (F f V v H h D = 0..6)               |
 *   | s_tid       | 6    | template id                                     |
 *   | s_ntri      | 4    | its number of triangles (1..8)                  |
 *
 * Triangle out (valid/ready):
 *
 *   | signal             | bits    | field                                                 |
 *   |--------------------|---------|-------------------------------------------------------|
 *   | m_axis_tdata       | 15:0    | x of vertex 0 (site a)                                |
 *   |                    | 31:16   | y of vertex 0                                         |
 *   |                    | 47:32   | x of vertex 1 (site b)                                |
 *   |                    | 63:48   | y of vertex 1                                         |
 *   |                    | 79:64   | x of vertex 2 (site c)                                |
 *   |                    | 95:80   | y of vertex 2                                         |
 *   | m_axis_tuser       | 2:0     | triangle index k in the template (0..ntri - 1)        |
 *   |                    | 8:3     | template id                                           |
 *   |                    | 11:9    | label code                                            |
 *   |                    | 27:12   | block column i                                        |
 *   |                    | 43:28   | block row j                                           |
 *   |                    | 44      | last triangle of this block                           |
 *   | m_axis_tlast       | 1       | last triangle of the frame's last block               |
 *
 * One triangle per cycle with no gap between blocks: a block of n triangles takes n cycles
 * (2..8).  A block is taken in the cycle its predecessor's last triangle is issued.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_expand (
    input  wire         clk,
    input  wire         rst,

    /*
     * Resolved block in
     */
    input  wire         s_valid,
    output wire         s_ready,
    input  wire         s_first_row,
    input  wire         s_first_col,
    input  wire         s_last_row,
    input  wire         s_last_col,
    input  wire [2:0]   s_label,
    input  wire [5:0]   s_tid,
    input  wire [3:0]   s_ntri,

    /*
     * Triangle out
     */
    output wire [95:0]  m_axis_tdata,
    output wire [44:0]  m_axis_tuser,
    output wire         m_axis_tvalid,
    input  wire         m_axis_tready,
    output wire         m_axis_tlast,

    /*
     * Configuration (stable while a frame is in flight)
     */
    input  wire [3:0]   cfg_levels,   // M: blocks are 2^M grid steps (>= 1)
    input  wire [15:0]  cfg_xmax,     // W - 1
    input  wire [15:0]  cfg_ymax,     // H - 1
    input  wire [15:0]  cfg_last_xm,  // middle of the last block column: x0 + (W - 1 - x0) / 2
    input  wire [15:0]  cfg_last_ym   // middle of the last block row
);

`include "wm_templates.vh"

// check the generated template set against this ROM layout, the output format and the block
// stage's timing (a block stays 2 cycles or more)
function [3:0] fewest_triangles;
    input integer count;  // templates 0 .. count - 1
    integer id;
    reg [WM_TPL_WORD_BITS-1:0] word;
    begin
        fewest_triangles = 4'd15;
        for (id = 0; id < count; id = id + 1) begin
            word = wm_template_rom(id[5:0]);
            if (word[WM_TPL_WORD_BITS-1 -: 4] < fewest_triangles) begin
                fewest_triangles = word[WM_TPL_WORD_BITS-1 -: 4];
            end
        end
    end
endfunction

initial begin
    if (WM_TEMPLATE_COUNT > 64 || WM_TEMPLATE_MAX_TRIANGLES > 8) begin
        $error("Error: template ids need 6 bits and triangle indices 3 bits (instance %m)");
        $finish;
    end
    if (fewest_triangles(WM_TEMPLATE_COUNT) < 4'd2) begin
        $error("Error: a template with fewer than 2 triangles (instance %m)");
        $finish;
    end
end

// Triangle k of template id: the ROM entry {id, k}
function [11:0] triangle_sites;
    input [8:0] index;
    reg [WM_TPL_WORD_BITS-1:0] word;
    begin
        word = wm_template_rom(index[8:3]);
        triangle_sites = word[index[2:0] * 12 +: 12];
    end
endfunction

reg [11:0] tri_rom[0:511];

integer n;

initial begin
    for (n = 0; n < 512; n = n + 1) begin
        tri_rom[n] = triangle_sites(n[8:0]);
    end
end

// Block stage: the block whose triangles are issued, and the next triangle's index
reg         a_valid_reg = 1'b0, a_valid_next;
reg [15:0]  a_row_reg = 16'd0, a_col_reg = 16'd0;
reg [2:0]   a_label_reg = 3'd0;
reg [5:0]   a_tid_reg = 6'd0;
reg [3:0]   a_ntri_reg = 4'd0;
reg         a_last_reg = 1'b0;
reg [15:0]  a_x0_reg = 16'd0, a_xm_reg = 16'd0, a_x1_reg = 16'd0;
reg [15:0]  a_y0_reg = 16'd0, a_ym_reg = 16'd0, a_y1_reg = 16'd0;
reg [2:0]   a_k_reg = 3'd0, a_k_next;
reg         a_end_reg = 1'b0, a_end_next;  // triangle k is the block's last
reg [15:0]  a_x1_step_reg = 16'd0;  // a_x1_reg + 2^M
reg [15:0]  a_y1_step_reg = 16'd0;  // a_y1_reg + 2^M
reg [15:0]  a_col_inc_reg = 16'd0;  // a_col_reg + 1
reg [15:0]  a_row_inc_reg = 16'd0;  // a_row_reg + 1

// ROM read stage: one triangle's sites (from the ROM's output register) and its block
reg         b_valid_reg = 1'b0, b_valid_next;
reg [11:0]  b_sites_reg = 12'd0;
reg [15:0]  b_row_reg = 16'd0, b_col_reg = 16'd0;
reg [2:0]   b_label_reg = 3'd0;
reg [5:0]   b_tid_reg = 6'd0;
reg [2:0]   b_k_reg = 3'd0;
reg         b_end_reg = 1'b0;
reg         b_last_reg = 1'b0;
reg [15:0]  b_x0_reg = 16'd0, b_xm_reg = 16'd0, b_x1_reg = 16'd0;
reg [15:0]  b_y0_reg = 16'd0, b_ym_reg = 16'd0, b_y1_reg = 16'd0;

// Output register
reg [95:0]  m_axis_tdata_reg = 96'd0;
reg [44:0]  m_axis_tuser_reg = 45'd0;
reg         m_axis_tvalid_reg = 1'b0, m_axis_tvalid_next;
reg         m_axis_tlast_reg = 1'b0;

assign m_axis_tdata = m_axis_tdata_reg;
assign m_axis_tuser = m_axis_tuser_reg;
assign m_axis_tvalid = m_axis_tvalid_reg;
assign m_axis_tlast = m_axis_tlast_reg;

// The grid positions of the block coming in
wire [15:0] step = 16'h0001 << cfg_levels;                    // 2^M
wire [15:0] half = 16'h8000 >> (5'd16 - {1'b0, cfg_levels});  // 2^(M-1)
wire [15:0] s_x0 = s_first_col ? 16'd0 : a_x1_reg;
wire [15:0] s_x1 = s_first_col ? step : a_x1_step_reg;   // unless the last column
wire [15:0] s_y0 = s_first_row ? 16'd0 : a_y1_reg;       // at a row's start
wire [15:0] s_y1 = s_first_row ? step : a_y1_step_reg;   // unless the last row

// x (column 0, 1, 2) and y (row 0, 1, 2) of a site 0..8
function [15:0] site_x;
    input [3:0] site;
    input [15:0] x0, xm, x1;
    begin
        case (site)
            4'd0, 4'd3, 4'd6: site_x = x0;
            4'd1, 4'd4, 4'd7: site_x = xm;
            default: site_x = x1;
        endcase
    end
endfunction

function [15:0] site_y;
    input [3:0] site;
    input [15:0] y0, ym, y1;
    begin
        case (site)
            4'd0, 4'd1, 4'd2: site_y = y0;
            4'd3, 4'd4, 4'd5: site_y = ym;
            default: site_y = y1;
        endcase
    end
endfunction

// handshakes
wire out_ready = !m_axis_tvalid_reg || m_axis_tready;
wire b_fire = b_valid_reg && out_ready;                 // a triangle moves to the output register
wire a_fire = a_valid_reg && (!b_valid_reg || b_fire);  // a triangle is issued to the ROM
wire a_end = a_end_reg;                                 // ... and it is the block's last
wire a_load = s_valid && (!a_valid_reg || (a_fire && a_end));

assign s_ready = !a_valid_reg || (a_fire && a_end);

always @* begin
    a_valid_next = a_valid_reg;
    a_k_next = a_k_reg;
    a_end_next = a_end_reg;
    b_valid_next = b_valid_reg && !b_fire;
    m_axis_tvalid_next = m_axis_tvalid_reg && !m_axis_tready;

    if (a_fire) begin
        // triangle k goes to the ROM
        b_valid_next = 1'b1;
        a_k_next = a_k_reg + 3'd1;
        a_end_next = {1'b0, a_k_reg} + 4'd2 == a_ntri_reg;
        if (a_end) begin
            // the block is done
            a_valid_next = 1'b0;
        end
    end

    if (a_load) begin
        // the next block, from its first triangle
        a_valid_next = 1'b1;
        a_k_next = 3'd0;
        a_end_next = s_ntri == 4'd1;
    end

    if (b_fire) begin
        // one more triangle out
        m_axis_tvalid_next = 1'b1;
    end
end

always @(posedge clk) begin
    a_valid_reg <= a_valid_next;
    a_k_reg <= a_k_next;
    a_end_reg <= a_end_next;
    b_valid_reg <= b_valid_next;
    m_axis_tvalid_reg <= m_axis_tvalid_next;

    if (a_load) begin
        a_col_reg <= s_first_col ? 16'd0 : a_col_inc_reg;
        a_label_reg <= s_label;
        a_tid_reg <= s_tid;
        a_ntri_reg <= s_ntri;
        a_last_reg <= s_last_row && s_last_col;
        a_x0_reg <= s_x0;
        a_xm_reg <= s_last_col ? cfg_last_xm : s_x0 | half;
        a_x1_reg <= s_last_col ? cfg_xmax : s_x1;
        if (s_first_col) begin
            // a new block row
            a_row_reg <= s_first_row ? 16'd0 : a_row_inc_reg;
            a_y0_reg <= s_y0;
            a_ym_reg <= s_last_row ? cfg_last_ym : s_y0 | half;
            a_y1_reg <= s_last_row ? cfg_ymax : s_y1;
        end
    end
    a_x1_step_reg <= a_x1_reg + step;
    a_y1_step_reg <= a_y1_reg + step;
    a_col_inc_reg <= a_col_reg + 16'd1;
    a_row_inc_reg <= a_row_reg + 16'd1;

    if (a_fire) begin
        b_sites_reg <= tri_rom[{a_tid_reg, a_k_reg}];
        b_row_reg <= a_row_reg;
        b_col_reg <= a_col_reg;
        b_label_reg <= a_label_reg;
        b_tid_reg <= a_tid_reg;
        b_k_reg <= a_k_reg;
        b_end_reg <= a_end;
        b_last_reg <= a_last_reg;
        b_x0_reg <= a_x0_reg;
        b_xm_reg <= a_xm_reg;
        b_x1_reg <= a_x1_reg;
        b_y0_reg <= a_y0_reg;
        b_ym_reg <= a_ym_reg;
        b_y1_reg <= a_y1_reg;
    end

    if (b_fire) begin
        m_axis_tdata_reg <= {
            site_y(b_sites_reg[11:8], b_y0_reg, b_ym_reg, b_y1_reg),
            site_x(b_sites_reg[11:8], b_x0_reg, b_xm_reg, b_x1_reg),
            site_y(b_sites_reg[7:4], b_y0_reg, b_ym_reg, b_y1_reg),
            site_x(b_sites_reg[7:4], b_x0_reg, b_xm_reg, b_x1_reg),
            site_y(b_sites_reg[3:0], b_y0_reg, b_ym_reg, b_y1_reg),
            site_x(b_sites_reg[3:0], b_x0_reg, b_xm_reg, b_x1_reg)
        };
        m_axis_tuser_reg <= {b_end_reg, b_row_reg, b_col_reg, b_label_reg, b_tid_reg, b_k_reg};
        m_axis_tlast_reg <= b_end_reg && b_last_reg;
    end

    if (rst) begin
        a_valid_reg <= 1'b0;
        a_k_reg <= 3'd0;
        b_valid_reg <= 1'b0;
        m_axis_tvalid_reg <= 1'b0;
    end
end

endmodule

`resetall
