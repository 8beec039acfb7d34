/*
 * wavemesh: line buffer of one spline filter-bank level (simple dual-port RAM, registered read)
 *
 * One word per column of the level's input: the vertical filter's partial sums, read back and
 * rewritten on every row (spline_level.v).  A column is read at one edge and written two edges
 * later, while the next columns are read: one read port and one write port, so simple dual-port
 * block RAM (ECP5 DP16KD, iCE40 SB_RAM40_4K) or LUT RAM.  A read at the edge of a write to the same
 * address returns the old word; spline_level forwards the newer words itself (only a level one or
 * two columns wide reads a column again that soon).  The read data stays on rd_data until the next
 * read.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module spline_linebuf #
(
    // Words stored: one per input column of the level (>= 1)
    parameter DEPTH = 512,
    // Address width in bits: $clog2(DEPTH), at least 1
    parameter ADDR_WIDTH = 9,
    // Word width in bits
    parameter DATA_WIDTH = 51
)
(
    input  wire                   clk,

    input  wire                   wr_en,
    input  wire [ADDR_WIDTH-1:0]  wr_addr,
    input  wire [DATA_WIDTH-1:0]  wr_data,

    input  wire                   rd_en,
    input  wire [ADDR_WIDTH-1:0]  rd_addr,
    output wire [DATA_WIDTH-1:0]  rd_data
);

// the RAM holds data only: no reset
reg [DATA_WIDTH-1:0] mem[0:DEPTH-1];
reg [DATA_WIDTH-1:0] rd_data_reg;

assign rd_data = rd_data_reg;

always @(posedge clk) begin
    if (wr_en) begin
        mem[wr_addr] <= wr_data;
    end
end

always @(posedge clk) begin
    if (rd_en) begin
        rd_data_reg <= mem[rd_addr];
    end
end

endmodule

`resetall
