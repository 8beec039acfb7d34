/*
 * wavemesh: UART receiver, 8N1, run-time baud divisor
 *
 * The line is synchronised by two flip-flops.  A falling edge starts a frame; the start bit is
 * checked at its middle (a shorter low pulse is a glitch and ignored), then the 8 data bits (LSB
 * first) and the stop bit are sampled one divisor apart, each at its middle.  A good frame puts
 * the byte on m_axis_tdata with m_axis_tvalid high for one cycle (there is no back-pressure: the
 * caller's FIFO takes it or counts an overrun).  A stop bit of 0 drops the byte, pulses
 * frame_error, and the receiver waits for the line to return high before it looks for the next
 * start bit (a break does not produce a stream of frames).
 *
 *   line:  ~~~~\_start_/ d0 | d1 | d2 | d3 | d4 | d5 | d6 | d7 |~stop~~
 *   sample:          ^      ^    ^    ^    ^    ^    ^    ^    ^     ^   (middle of each bit)
 *
 * div is the bit time in clock cycles (>= 4), read at the start of every bit.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module uart_rx
(
    input  wire        clk,
    input  wire        rst,

    /*
     * Serial line and configuration
     */
    input  wire        rxd,            // the pin, idle high
    input  wire [15:0] div,            // clock cycles per bit, >= 4

    /*
     * Received bytes (one-cycle strobe, no back-pressure)
     */
    output wire [7:0]  m_axis_tdata,
    output wire        m_axis_tvalid,

    /*
     * Status
     */
    output wire        busy,           // inside a frame
    output wire        frame_error     // one-cycle strobe: a stop bit was 0
);

localparam [1:0]
    STATE_IDLE  = 2'd0,
    STATE_START = 2'd1,
    STATE_DATA  = 2'd2,
    STATE_STOP  = 2'd3;

reg [1:0] state_reg = STATE_IDLE, state_next;

// two-stage synchroniser; reset to the idle level
reg rxd_meta_reg = 1'b1;
reg rxd_reg = 1'b1;

reg [15:0] count_reg = 16'd0, count_next;   // cycles left until the next sample
reg [2:0] bit_reg = 3'd0, bit_next;         // data bit being received
reg [7:0] data_reg = 8'd0, data_next;
reg valid_reg = 1'b0, valid_next;
reg frame_error_reg = 1'b0, frame_error_next;
reg wait_high_reg = 1'b0, wait_high_next;   // after a frame error: wait for an idle line

assign m_axis_tdata = data_reg;
assign m_axis_tvalid = valid_reg;
assign busy = state_reg != STATE_IDLE;
assign frame_error = frame_error_reg;

always @* begin
    state_next = state_reg;
    count_next = count_reg;
    bit_next = bit_reg;
    data_next = data_reg;
    valid_next = 1'b0;
    frame_error_next = 1'b0;
    wait_high_next = wait_high_reg;

    if (count_reg != 16'd0) begin
        // between samples
        count_next = count_reg - 16'd1;
    end

    case (state_reg)
        STATE_IDLE: begin
            if (wait_high_reg) begin
                // after a frame error: only an idle (high) line re-arms the receiver
                if (rxd_reg) begin
                    wait_high_next = 1'b0;
                end
            end else if (!rxd_reg) begin
                // falling edge: sample the start bit in its middle
                count_next = {1'b0, div[15:1]} - 16'd1;
                state_next = STATE_START;
            end
        end
        STATE_START: begin
            if (count_reg == 16'd0) begin
                if (!rxd_reg) begin
                    // a real start bit: first data bit one bit time later
                    count_next = div - 16'd1;
                    bit_next = 3'd0;
                    state_next = STATE_DATA;
                end else begin
                    // glitch shorter than half a bit
                    state_next = STATE_IDLE;
                end
            end
        end
        STATE_DATA: begin
            if (count_reg == 16'd0) begin
                // sample a data bit, LSB first
                data_next = {rxd_reg, data_reg[7:1]};
                count_next = div - 16'd1;
                bit_next = bit_reg + 3'd1;
                if (bit_reg == 3'd7) begin
                    state_next = STATE_STOP;
                end
            end
        end
        STATE_STOP: begin
            if (count_reg == 16'd0) begin
                if (rxd_reg) begin
                    // good stop bit: deliver the byte; half a stop bit remains for the next edge
                    valid_next = 1'b1;
                end else begin
                    // framing error (or break): drop the byte, wait for the line to go high
                    frame_error_next = 1'b1;
                    wait_high_next = 1'b1;
                end
                state_next = STATE_IDLE;
            end
        end
        default: begin
            state_next = STATE_IDLE;
        end
    endcase
end

always @(posedge clk) begin
    rxd_meta_reg <= rxd;
    rxd_reg <= rxd_meta_reg;

    state_reg <= state_next;
    count_reg <= count_next;
    bit_reg <= bit_next;
    data_reg <= data_next;
    valid_reg <= valid_next;
    frame_error_reg <= frame_error_next;
    wait_high_reg <= wait_high_next;

    if (rst) begin
        rxd_meta_reg <= 1'b1;
        rxd_reg <= 1'b1;
        state_reg <= STATE_IDLE;
        count_reg <= 16'd0;
        valid_reg <= 1'b0;
        frame_error_reg <= 1'b0;
        wait_high_reg <= 1'b0;
    end
end

endmodule

`resetall
