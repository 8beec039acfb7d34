/*
 * wavemesh: small FIFO of the filter bank
 *
 * Between a level and the output merge (its records, while the merge serves lower levels) and
 * between two levels (approximations, while the deeper level waits).  First-word fall-through:
 * rd_data shows the head whenever empty is low.  full and empty are registers whose next values
 * depend on rd_en / wr_en through one LUT, so a level's enable (neither FIFO it writes full) and the
 * merge stay shallow.  The storage has no reset and an asynchronous read: LUT RAM on ECP5,
 * flip-flops on iCE40.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module haar_fifo #
(
    // Entry width in bits
    parameter WIDTH = 64,
    // Entries; a power of two >= 2
    parameter DEPTH = 4
)
(
    input  wire              clk,
    input  wire              rst,

    input  wire              wr_en,     // ignored when full
    input  wire [WIDTH-1:0]  wr_data,
    output wire              full,

    input  wire              rd_en,     // ignored when empty
    output wire [WIDTH-1:0]  rd_data,
    output wire              empty
);

localparam ADDR_WIDTH = $clog2(DEPTH);
localparam [ADDR_WIDTH:0] COUNT_ONE = 1;
localparam [ADDR_WIDTH:0] COUNT_FULL_M1 = DEPTH[ADDR_WIDTH:0] - 1'b1;  // one entry short of full

// check configuration
initial begin
    if (DEPTH < 2 || (1 << ADDR_WIDTH) != DEPTH) begin
        $error("Error: DEPTH must be a power of two >= 2 (instance %m)");
        $finish;
    end
end

reg [WIDTH-1:0] mem[0:DEPTH-1];

reg [ADDR_WIDTH-1:0] wr_addr_reg = {ADDR_WIDTH{1'b0}};
reg [ADDR_WIDTH-1:0] rd_addr_reg = {ADDR_WIDTH{1'b0}};
reg [ADDR_WIDTH:0] count_reg = {ADDR_WIDTH+1{1'b0}}, count_next;
// flags as registers, their next values from registered compares: one LUT after rd_en / wr_en
reg full_reg = 1'b0, full_next;
reg empty_reg = 1'b1, empty_next;

wire do_wr = wr_en && !full_reg;
wire do_rd = rd_en && !empty_reg;

assign full = full_reg;
assign empty = empty_reg;
assign rd_data = mem[rd_addr_reg];

always @* begin
    count_next = count_reg;
    full_next = full_reg;
    empty_next = empty_reg;

    if (do_wr && !do_rd) begin
        // one more
        count_next = count_reg + 1'b1;
        full_next = count_reg == COUNT_FULL_M1;
        empty_next = 1'b0;
    end else if (do_rd && !do_wr) begin
        // one less
        count_next = count_reg - 1'b1;
        full_next = 1'b0;
        empty_next = count_reg == COUNT_ONE;
    end
end

always @(posedge clk) begin
    if (do_wr) begin
        mem[wr_addr_reg] <= wr_data;
        wr_addr_reg <= wr_addr_reg + 1'b1;
    end
    if (do_rd) begin
        rd_addr_reg <= rd_addr_reg + 1'b1;
    end

    count_reg <= count_next;
    full_reg <= full_next;
    empty_reg <= empty_next;

    if (rst) begin
        wr_addr_reg <= {ADDR_WIDTH{1'b0}};
        rd_addr_reg <= {ADDR_WIDTH{1'b0}};
        count_reg <= {ADDR_WIDTH+1{1'b0}};
        full_reg <= 1'b0;
        empty_reg <= 1'b1;
    end
end

endmodule

`resetall
