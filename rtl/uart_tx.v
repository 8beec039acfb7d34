/*
 * wavemesh: UART transmitter, 8N1, run-time baud divisor
 *
 * Takes one byte from s_axis when idle and shifts out a start bit (0), the 8 data bits LSB first
 * and a stop bit (1), each div clock cycles long (div is read at the start of every bit).  The
 * next byte is accepted in the cycle after the stop bit ends, so back-to-back bytes leave no gap.
 *
 *   txd:  ~~~~\_start_/ d0 | d1 | d2 | d3 | d4 | d5 | d6 | d7 |~stop~~
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module uart_tx
(
    input  wire        clk,
    input  wire        rst,

    /*
     * Bytes to send
     */
    input  wire [7:0]  s_axis_tdata,
    input  wire        s_axis_tvalid,
    output wire        s_axis_tready,

    /*
     * Serial line and configuration
     */
    output wire        txd,            // the pin, idle high
    input  wire [15:0] div,            // clock cycles per bit, >= 1

    /*
     * Status
     */
    output wire        busy            // a frame is on the line
);

reg [8:0] shift_reg = 9'h1ff, shift_next;  // bits still to send after the current one, LSB next
reg txd_reg = 1'b1, txd_next;
reg [3:0] bits_reg = 4'd0, bits_next;      // bits still to send after the current one
reg [15:0] count_reg = 16'd0, count_next;  // cycles left in the current bit
reg busy_reg = 1'b0, busy_next;

// ready when idle, and in the last cycle of a stop bit (back-to-back frames)
wire last_cycle = busy_reg && count_reg == 16'd0 && bits_reg == 4'd0;

assign s_axis_tready = !busy_reg || last_cycle;
assign txd = txd_reg;
assign busy = busy_reg;

always @* begin
    shift_next = shift_reg;
    txd_next = txd_reg;
    bits_next = bits_reg;
    count_next = count_reg;
    busy_next = busy_reg;

    if (!busy_reg || last_cycle) begin
        busy_next = 1'b0;
        if (s_axis_tvalid) begin
            // idle, or the stop bit ends: accept a byte and send its start bit now
            txd_next = 1'b0;
            shift_next = {1'b1, s_axis_tdata};
            bits_next = 4'd9;
            count_next = div - 16'd1;
            busy_next = 1'b1;
        end
    end else if (count_reg != 16'd0) begin
        // inside a bit
        count_next = count_reg - 16'd1;
    end else begin
        // next bit (bits_reg != 0 here: the end of the stop bit is last_cycle above)
        txd_next = shift_reg[0];
        shift_next = {1'b1, shift_reg[8:1]};
        bits_next = bits_reg - 4'd1;
        count_next = div - 16'd1;
    end
end

always @(posedge clk) begin
    shift_reg <= shift_next;
    txd_reg <= txd_next;
    bits_reg <= bits_next;
    count_reg <= count_next;
    busy_reg <= busy_next;

    if (rst) begin
        txd_reg <= 1'b1;
        bits_reg <= 4'd0;
        count_reg <= 16'd0;
        busy_reg <= 1'b0;
    end
end

endmodule

`resetall
