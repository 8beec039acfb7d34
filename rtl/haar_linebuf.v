/*
 * wavemesh: line buffer of one filter-bank level (single-port RAM, registered read)
 *
 * Holds the horizontal pairs of the even row of a level, as {sum, difference}, until the odd row
 * below reads them back.  A pair is either written or read in one cycle, never both, so one port is
 * enough; the read data stays on rd_data until the next read.  Written as the plain inference
 * template so that Yosys maps it to block RAM (ECP5 DP16KD, iCE40 SB_RAM40_4K) when it is large
 * enough to be worth it, and to LUT RAM or flip-flops when it is not.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module haar_linebuf #
(
    // Words stored: one per block column of the level (>= 1)
    parameter DEPTH = 256,
    // Address width in bits: $clog2(DEPTH), at least 1
    parameter ADDR_WIDTH = 8,
    // Word width in bits: a pair's 17-bit sum and 17-bit difference
    parameter DATA_WIDTH = 34
)
(
    input  wire                   clk,

    input  wire [ADDR_WIDTH-1:0]  addr,
    input  wire                   wr_en,
    input  wire [DATA_WIDTH-1:0]  wr_data,
    input  wire                   rd_en,
    output wire [DATA_WIDTH-1:0]  rd_data
);

// the RAM holds data only: no reset
reg [DATA_WIDTH-1:0] mem[0:DEPTH-1];
reg [DATA_WIDTH-1:0] rd_data_reg;

assign rd_data = rd_data_reg;

always @(posedge clk) begin
    if (wr_en) begin
        // even row: store the pair for the row below
        mem[addr] <= wr_data;
    end else if (rd_en) begin
        // odd row: fetch the pair above (never in a write cycle, so no read-during-write logic)
        rd_data_reg <= mem[addr];
    end
end

endmodule

`resetall
