/*
 * wavemesh: the template stage's per-block validity flag (--nodata hole, issue 20)
 *
 * Takes a height field's validity mask, a bit per sample in raster order (1: the sample is invalid),
 * and gives, for every block of the template stage, whether it holds an invalid sample: the blocks of
 * wavemesh.model.label, S = 2^levels grid steps a side, block (j, i) spanning samples
 * [iS, min((i+1)S, W-1)] x [jS, min((j+1)S, H-1)], closed, so a sample on a block boundary counts for
 * every block it bounds.  The reference model is wavemesh.model.holemask.block_flags; tests/rtl/test_tlut_holes.py
 * checks every flag against it.  The mesh does not need the flags (the templates see filled heights and
 * the refiner reads the mask itself, docs/model.md "Holes"); tlut_stage with HOLES = 1 puts it beside
 * each block's template (tuser[45]).
 *
 *   s_data, s_valid, s_ready   the mask, one bit a sample, row by row (W per row, H rows)
 *   m_data, m_valid, m_ready   the flags, block row by block row (cols = ceil((W-1)/S) per row)
 *   cfg_width, cfg_height,     the frame's W (2..), H (2..) and levels (1..MAX_LEVELS), held while a
 *   cfg_levels                 frame passes; a frame ends with its last flag
 *
 * Two rows of flags are kept: the block row being finished and, on its last sample row (which is also
 * the next block row's first), the next one.  After the last sample row of a block row the flags go
 * out, one per cycle while m_ready is high; the mask waits (s_ready low) meanwhile.
 *
 *     sample row y:   0 .. S-1 | S | S+1 .. 2S-1 | 2S ...
 *     block row:      0        |0,1| 1           |1,2 ...     (a boundary row feeds both)
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_holes #
(
    // Most block columns of a frame, ceil((W-1)/2) for the widest W at levels 1, >= 2
    parameter MAX_COLS = 16
)
(
    input  wire                  clk,
    input  wire                  rst,

    /*
     * Frame
     */
    input  wire [15:0]           cfg_width,
    input  wire [15:0]           cfg_height,
    input  wire [3:0]            cfg_levels,  // 1..15

    /*
     * Mask in
     */
    input  wire                  s_data,
    input  wire                  s_valid,
    output wire                  s_ready,

    /*
     * Flags out
     */
    output wire                  m_data,
    output wire                  m_valid,
    input  wire                  m_ready
);

localparam CW = 16;                // block column numbers and counts, as W
localparam IW = $clog2(MAX_COLS);  // bits that index a row of flags
localparam [CW-1:0] ONE = 1;

initial begin
    if (MAX_COLS < 2) $error("MAX_COLS must be at least 2");
end

// S - 1 and the number of block columns of this frame
wire [15:0]   s_mask = (16'd1 << cfg_levels) - 16'd1;
wire [CW-1:0] cols = (cfg_width - 16'd2 + (16'd1 << cfg_levels)) >> cfg_levels;

reg           emit_reg = 1'b0, emit_next;     // sending a block row's flags
reg           last_reg = 1'b0, last_next;     // ... and it is the frame's last block row
reg [15:0]    x_reg = 16'd0, x_next;          // the next sample's column and row
reg [15:0]    y_reg = 16'd0, y_next;
reg [15:0]    xoff_reg = 16'd0, xoff_next;    // x mod S
reg [CW-1:0]  xcol_reg = {CW{1'b0}}, xcol_next; // x div S
reg [15:0]    jrow_reg = 16'd0, jrow_next;    // j: the block row being finished
reg [CW-1:0]  ecol_reg = {CW{1'b0}}, ecol_next; // the flag being sent
reg [MAX_COLS-1:0] cur_reg = {MAX_COLS{1'b0}}, cur_next; // block row j
reg [MAX_COLS-1:0] nxt_reg = {MAX_COLS{1'b0}}, nxt_next; // block row j + 1 (from its first row)

assign s_ready = !emit_reg;
assign m_valid = emit_reg;
assign m_data = cur_reg[ecol_reg[IW-1:0]];

wire [15:0]        ybound = (jrow_reg + 16'd1) << cfg_levels;  // (j + 1) S, its last sample row
reg [MAX_COLS-1:0] hit;  // the block columns the sample bounds
wire [IW-1:0]      xcol_left = xcol_reg[IW-1:0] - 1'b1;  // left of a boundary sample (mod 2^IW: exact)
reg                row_end, in_next;

always @* begin
    emit_next = emit_reg;
    last_next = last_reg;
    x_next = x_reg;
    y_next = y_reg;
    xoff_next = xoff_reg;
    xcol_next = xcol_reg;
    jrow_next = jrow_reg;
    ecol_next = ecol_reg;
    cur_next = cur_reg;
    nxt_next = nxt_reg;
    hit = {MAX_COLS{1'b0}};
    row_end = 1'b0;
    in_next = 1'b0;

    if (!emit_reg) begin
        // a sample: its own block column, and the one on its left when it sits on their boundary
        if (s_valid) begin
            if (xcol_reg < cols) hit[xcol_reg[IW-1:0]] = 1'b1;
            if (xoff_reg == 16'd0 && x_reg != 16'd0) hit[xcol_left] = 1'b1;
            // a boundary row that more rows follow also starts the next block row
            in_next = y_reg == ybound && y_reg != cfg_height - 16'd1;
            if (s_data) begin
                cur_next = cur_reg | hit;
                if (in_next) nxt_next = nxt_reg | hit;
            end
            if (x_reg == cfg_width - 16'd1) begin
                // the row is done
                x_next = 16'd0;
                xoff_next = 16'd0;
                xcol_next = {CW{1'b0}};
                y_next = y_reg + 16'd1;
                row_end = y_reg == ybound || y_reg == cfg_height - 16'd1;
                if (row_end) begin
                    // the block row is complete: its flags go out
                    emit_next = 1'b1;
                    last_next = y_reg == cfg_height - 16'd1;
                    ecol_next = {CW{1'b0}};
                    jrow_next = jrow_reg + 16'd1;
                end
            end else begin
                x_next = x_reg + 16'd1;
                if (xoff_reg == s_mask) begin
                    xoff_next = 16'd0;
                    xcol_next = xcol_reg + ONE;
                end else begin
                    xoff_next = xoff_reg + 16'd1;
                end
            end
        end
    end else if (m_ready) begin
        // a flag taken
        if (ecol_reg == cols - ONE) begin
            // the block row is out: the next one becomes current
            emit_next = 1'b0;
            cur_next = nxt_reg;
            nxt_next = {MAX_COLS{1'b0}};
            if (last_reg) begin
                // the frame is done: the next one starts at sample (0, 0)
                y_next = 16'd0;
                jrow_next = 16'd0;
                cur_next = {MAX_COLS{1'b0}};
            end
        end else begin
            ecol_next = ecol_reg + ONE;
        end
    end
end

always @(posedge clk) begin
    emit_reg <= emit_next;
    last_reg <= last_next;
    x_reg <= x_next;
    y_reg <= y_next;
    xoff_reg <= xoff_next;
    xcol_reg <= xcol_next;
    jrow_reg <= jrow_next;
    ecol_reg <= ecol_next;
    cur_reg <= cur_next;
    nxt_reg <= nxt_next;

    if (rst) begin
        emit_reg <= 1'b0;
        last_reg <= 1'b0;
        x_reg <= 16'd0;
        y_reg <= 16'd0;
        xoff_reg <= 16'd0;
        xcol_reg <= {CW{1'b0}};
        jrow_reg <= 16'd0;
        ecol_reg <= {CW{1'b0}};
        cur_reg <= {MAX_COLS{1'b0}};
        nxt_reg <= {MAX_COLS{1'b0}};
    end
end

endmodule

`resetall
