/*
 * wavemesh: byte FIFO of the UART (RX and TX)
 *
 * AXI-stream in and out, first-word fall-through: m_axis_tdata shows the oldest byte whenever
 * m_axis_tvalid is high.  A write and a read in the same cycle both happen (also when full: the
 * read frees the slot the write takes only in the next cycle, so a full FIFO refuses the write).
 * count is the number of bytes held.  Storage has no reset and an asynchronous read: LUT RAM on
 * ECP5.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module uart_fifo #
(
    // Entry width in bits
    parameter WIDTH = 8,
    // Entries; a power of two >= 2
    parameter DEPTH = 64
)
(
    input  wire                     clk,
    input  wire                     rst,

    /*
     * Input
     */
    input  wire [WIDTH-1:0]         s_axis_tdata,
    input  wire                     s_axis_tvalid,
    output wire                     s_axis_tready,

    /*
     * Output
     */
    output wire [WIDTH-1:0]         m_axis_tdata,
    output wire                     m_axis_tvalid,
    input  wire                     m_axis_tready,

    /*
     * Status
     */
    output wire [$clog2(DEPTH):0]   count
);

localparam ADDR_WIDTH = $clog2(DEPTH);

// check configuration
initial begin
    if (DEPTH < 2 || (1 << ADDR_WIDTH) != DEPTH) begin
        $error("Error: DEPTH must be a power of two >= 2 (instance %m)");
        $finish;
    end
end

reg [WIDTH-1:0] mem[0:DEPTH-1];

// pointers with one extra bit: equal is empty, differing only in the top bit is full
reg [ADDR_WIDTH:0] wr_ptr_reg = {ADDR_WIDTH+1{1'b0}}, wr_ptr_next;
reg [ADDR_WIDTH:0] rd_ptr_reg = {ADDR_WIDTH+1{1'b0}}, rd_ptr_next;

wire full = wr_ptr_reg == (rd_ptr_reg ^ {1'b1, {ADDR_WIDTH{1'b0}}});
wire empty = wr_ptr_reg == rd_ptr_reg;
wire do_wr = s_axis_tvalid && !full;
wire do_rd = m_axis_tready && !empty;

assign s_axis_tready = !full;
assign m_axis_tdata = mem[rd_ptr_reg[ADDR_WIDTH-1:0]];
assign m_axis_tvalid = !empty;
assign count = wr_ptr_reg - rd_ptr_reg;

always @* begin
    wr_ptr_next = wr_ptr_reg;
    rd_ptr_next = rd_ptr_reg;

    if (do_wr) begin
        // enqueue
        wr_ptr_next = wr_ptr_reg + 1'b1;
    end
    if (do_rd) begin
        // dequeue
        rd_ptr_next = rd_ptr_reg + 1'b1;
    end
end

always @(posedge clk) begin
    if (do_wr) begin
        mem[wr_ptr_reg[ADDR_WIDTH-1:0]] <= s_axis_tdata;
    end

    wr_ptr_reg <= wr_ptr_next;
    rd_ptr_reg <= rd_ptr_next;

    if (rst) begin
        wr_ptr_reg <= {ADDR_WIDTH+1{1'b0}};
        rd_ptr_reg <= {ADDR_WIDTH+1{1'b0}};
    end
end

endmodule

`resetall
