/*
 * wavemesh: line buffer of a filter-bank level (simple dual-port RAM, registered read)
 *
 * One RAM for both wavelets.  A write and a read port, so simple dual-port block RAM (ECP5 DP16KD,
 * iCE40 SB_RAM40_4K) when it is large enough to be worth it, LUT RAM or flip-flops when it is not;
 * written as the plain inference template.  A read at the edge of a write to the same address returns
 * the old word.  The read data stays on rd_data until the next read.
 *
 * - haar_level.v: the horizontal pairs of a level's even row, {sum, difference}, one word per block
 *   column, until the odd row below reads them back (one address: a pair is written or read in a
 *   cycle, never both); and the pairs' validity flags beside them.
 * - spline_level.v: the vertical filter's partial sums, one word per input column, read back and
 *   rewritten on every row; a column is read at one edge and written two edges later while the next
 *   columns are read (spline_level forwards the newer words itself: only a level one or two columns
 *   wide reads a column again that soon).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module wm_linebuf #
(
    // Words stored (>= 1)
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
