/*
 * wavemesh template stage: a small synchronous first-word-fall-through FIFO.
 *
 * No s_ready: the writer keeps count of its own credits and never writes when full (the template
 * stage reserves a place for every block before its record enters the pipeline).  m_data shows
 * the oldest entry while m_valid is high; m_ready pops it.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_fifo #(
    // Entries (a power of two, >= 2)
    parameter DEPTH = 4,
    // Entry width (bits, >= 1)
    parameter DATA_WIDTH = 8
) (
    input  wire                  clk,
    input  wire                  rst,

    /*
     * Write side (never when full)
     */
    input  wire                  s_valid,
    input  wire [DATA_WIDTH-1:0] s_data,

    /*
     * Read side
     */
    output wire                  m_valid,
    input  wire                  m_ready,
    output wire [DATA_WIDTH-1:0] m_data
);

localparam PTR_WIDTH = $clog2(DEPTH);

// check configuration
initial begin
    if (DEPTH < 2 || (1 << PTR_WIDTH) != DEPTH) begin
        $error("Error: DEPTH must be a power of two, at least 2 (instance %m)");
        $finish;
    end
end

reg [DATA_WIDTH-1:0] mem[0:DEPTH-1];
// pointers one bit wider than the address: equal means empty
reg [PTR_WIDTH:0]    wr_ptr_reg = {PTR_WIDTH+1{1'b0}};
reg [PTR_WIDTH:0]    rd_ptr_reg = {PTR_WIDTH+1{1'b0}};

assign m_valid = wr_ptr_reg != rd_ptr_reg;
assign m_data = mem[rd_ptr_reg[PTR_WIDTH-1:0]];

always @(posedge clk) begin
    if (s_valid) begin
        // append
        mem[wr_ptr_reg[PTR_WIDTH-1:0]] <= s_data;
        wr_ptr_reg <= wr_ptr_reg + 1'b1;
    end

    if (m_valid && m_ready) begin
        // pop the oldest
        rd_ptr_reg <= rd_ptr_reg + 1'b1;
    end

    if (rst) begin
        wr_ptr_reg <= {PTR_WIDTH+1{1'b0}};
        rd_ptr_reg <= {PTR_WIDTH+1{1'b0}};
    end
end

endmodule

`resetall
