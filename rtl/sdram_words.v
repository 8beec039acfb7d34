/*
 * wavemesh: 32-bit word writes from two entry streams, as halfword beats for sdram_ctrl's addressed
 * writer
 *
 * The FPGA stage hands out its coefficient and template entries with their word addresses (the
 * SDRAM's 32-bit words: halfwords 2w and 2w + 1).  Each word taken is written as two beats, its
 * low halfword at 2w and its high halfword at 2w + 1, so the CPU reads it back as one 32-bit word.
 * Stream A wins when both wait (either order would do: the SDRAM drains both).
 *
 *   s_axis_a/b  --> one word register --> m_axis (halfword, halfword address), 1 beat per clock
 *
 * busy is high while a word is held, so busy low with both inputs idle means every word taken has
 * reached the addressed writer's FIFO.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module sdram_words #
(
    // halfword address bits of the SDRAM (24 for 16 M x 16)
    parameter HW_ADDR_BITS = 24
)
(
    input  wire                      clk,
    input  wire                      rst,

    /*
     * Word streams: data and word address
     */
    input  wire [31:0]               s_axis_a_tdata,
    input  wire [HW_ADDR_BITS-2:0]   s_axis_a_tuser,
    input  wire                      s_axis_a_tvalid,
    output wire                      s_axis_a_tready,
    input  wire [31:0]               s_axis_b_tdata,
    input  wire [HW_ADDR_BITS-2:0]   s_axis_b_tuser,
    input  wire                      s_axis_b_tvalid,
    output wire                      s_axis_b_tready,

    /*
     * Halfword beats with their halfword address
     */
    output wire [15:0]               m_axis_tdata,
    output wire [HW_ADDR_BITS-1:0]   m_axis_tuser,
    output wire                      m_axis_tvalid,
    input  wire                      m_axis_tready,

    output wire                      busy
);

reg [31:0] word_reg = 32'd0;
reg [HW_ADDR_BITS-2:0] addr_reg = {(HW_ADDR_BITS-1){1'b0}};
reg valid_reg = 1'b0;
reg high_reg = 1'b0;  // the low halfword is out, the high one is next

// the register frees up when its high halfword goes out; a new word may enter in the same cycle
wire free = !valid_reg || (high_reg && m_axis_tready);

assign s_axis_a_tready = free;
assign s_axis_b_tready = free && !s_axis_a_tvalid;

assign m_axis_tdata = high_reg ? word_reg[31:16] : word_reg[15:0];
assign m_axis_tuser = {addr_reg, high_reg};
assign m_axis_tvalid = valid_reg;
assign busy = valid_reg;

always @(posedge clk) begin
    if (free) begin
        // take a word: A first
        valid_reg <= s_axis_a_tvalid || s_axis_b_tvalid;
        high_reg <= 1'b0;
        word_reg <= s_axis_a_tvalid ? s_axis_a_tdata : s_axis_b_tdata;
        addr_reg <= s_axis_a_tvalid ? s_axis_a_tuser : s_axis_b_tuser;
    end else if (m_axis_tready) begin
        // the low halfword went out
        high_reg <= 1'b1;
    end

    if (rst) begin
        valid_reg <= 1'b0;
        high_reg <= 1'b0;
    end
end

endmodule

`resetall
