/*
 * wavemesh: the FIFO of every stream in rtl/ (the filter bank's records and approximations, the
 * template stage's blocks, the UART's bytes)
 *
 * Synchronous, first-word fall-through, valid/ready on both sides (rtl/README.md, "Conventions"):
 * a beat moves on a rising edge where its valid and ready are both high.
 *
 *   s_data, s_valid, s_ready   write side; s_ready is "not full"
 *   m_data, m_valid, m_ready   read side; m_valid is "not empty", m_data is the oldest entry while
 *                              m_valid is high and stays put until it is taken
 *   count                      entries held, 0 .. DEPTH (optional: leave it on an unused wire)
 *
 * Timing.  s_ready, m_valid and count are registers: nothing combinational runs from one side's
 * inputs to the other side's outputs (no m_ready -> s_ready, no s_valid -> m_valid path), and
 * s_valid, m_ready reach only the next-state logic.  Latency 1: a beat written at the edge ending
 * cycle t is at the output (m_valid high) in cycle t + 1; a place freed by a read at the edge
 * ending cycle t is offered (s_ready high) in cycle t + 1.  So a FIFO that is full in cycle t
 * refuses a write in cycle t even when it is read in that cycle, and an empty FIFO does not pass a
 * beat through in the cycle it arrives.  Whenever the FIFO is neither full nor empty, a write and
 * a read in the same cycle both happen and count stays: with DEPTH >= 2 a stream passes at one
 * beat per cycle; DEPTH = 1 passes one beat every other cycle.
 *
 * m_data is not registered: it is the storage's asynchronous read at the registered read address
 * (LUT RAM on ECP5, flip-flops and a multiplexer on iCE40).  The storage has no reset; the
 * synchronous reset (active high) empties the FIFO.
 *
 * DEPTH may be any number of entries >= 1; a power of two saves the two address wrap comparisons.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module wm_fifo #
(
    // Entry width in bits, >= 1
    parameter DATA_WIDTH = 8,
    // Entries, >= 1 (any number; 2 or more for one beat per cycle)
    parameter DEPTH = 4
)
(
    input  wire                         clk,
    input  wire                         rst,

    /*
     * Write side
     */
    input  wire [DATA_WIDTH-1:0]        s_data,
    input  wire                         s_valid,
    output wire                         s_ready,

    /*
     * Read side
     */
    output wire [DATA_WIDTH-1:0]        m_data,
    output wire                         m_valid,
    input  wire                         m_ready,

    /*
     * Status
     */
    output wire [$clog2(DEPTH+1)-1:0]   count
);

localparam ADDR_WIDTH = DEPTH > 1 ? $clog2(DEPTH) : 1;
localparam COUNT_WIDTH = $clog2(DEPTH + 1);
// the addresses wrap by themselves when DEPTH fills their range, else at the last entry
localparam WRAP = (1 << ADDR_WIDTH) != DEPTH;
localparam [ADDR_WIDTH-1:0] ADDR_LAST = DEPTH[ADDR_WIDTH-1:0] - 1'b1;
localparam [COUNT_WIDTH-1:0] COUNT_ONE = 1;
localparam [COUNT_WIDTH-1:0] COUNT_LAST = DEPTH[COUNT_WIDTH-1:0] - 1'b1;  // one entry short of full

// check configuration
initial begin
    if (DATA_WIDTH < 1 || DEPTH < 1) begin
        $error("Error: DATA_WIDTH and DEPTH must be at least 1 (instance %m)");
        $finish;
    end
end

reg [DATA_WIDTH-1:0] mem[0:DEPTH-1];

reg [ADDR_WIDTH-1:0] wr_addr_reg = {ADDR_WIDTH{1'b0}}, wr_addr_next;
reg [ADDR_WIDTH-1:0] rd_addr_reg = {ADDR_WIDTH{1'b0}}, rd_addr_next;
reg [COUNT_WIDTH-1:0] count_reg = {COUNT_WIDTH{1'b0}}, count_next;
// the flags are registers too, their next values from the registered count: one LUT after
// s_valid / m_ready, so the writer's and the reader's enables stay shallow
reg full_reg = 1'b0, full_next;
reg empty_reg = 1'b1, empty_next;

wire do_wr = s_valid && !full_reg;
wire do_rd = m_ready && !empty_reg;

assign s_ready = !full_reg;
assign m_valid = !empty_reg;
assign m_data = mem[rd_addr_reg];
assign count = count_reg;

always @* begin
    wr_addr_next = wr_addr_reg;
    rd_addr_next = rd_addr_reg;
    count_next = count_reg;
    full_next = full_reg;
    empty_next = empty_reg;

    if (do_wr) begin
        // the next free entry
        wr_addr_next = WRAP && wr_addr_reg == ADDR_LAST ? {ADDR_WIDTH{1'b0}} : wr_addr_reg + 1'b1;
    end
    if (do_rd) begin
        // the next oldest entry
        rd_addr_next = WRAP && rd_addr_reg == ADDR_LAST ? {ADDR_WIDTH{1'b0}} : rd_addr_reg + 1'b1;
    end

    if (do_wr && !do_rd) begin
        // one more
        count_next = count_reg + 1'b1;
        full_next = count_reg == COUNT_LAST;
        empty_next = 1'b0;
    end else if (do_rd && !do_wr) begin
        // one less
        count_next = count_reg - 1'b1;
        full_next = 1'b0;
        empty_next = count_reg == COUNT_ONE;
    end
end

// storage: no reset (LUT RAM)
always @(posedge clk) begin
    if (do_wr) begin
        mem[wr_addr_reg] <= s_data;
    end
end

always @(posedge clk) begin
    wr_addr_reg <= wr_addr_next;
    rd_addr_reg <= rd_addr_next;
    count_reg <= count_next;
    full_reg <= full_next;
    empty_reg <= empty_next;

    if (rst) begin
        wr_addr_reg <= {ADDR_WIDTH{1'b0}};
        rd_addr_reg <= {ADDR_WIDTH{1'b0}};
        count_reg <= {COUNT_WIDTH{1'b0}};
        full_reg <= 1'b0;
        empty_reg <= 1'b1;
    end
end

endmodule

`resetall
