/*
 * wavemesh: the iCEBreaker board top (Lattice iCE40 UP5K, SG48; 12 MHz oscillator)
 *
 * The whole SoC does not fit the UP5K (docs/boards.md has the measurements), so the iCEBreaker
 * carries the FPGA stage alone behind its UART (stage_uart.v: filter bank and template stage, the
 * samples streamed in and every block's TOUT entry streamed back, HELLO answered; the host
 * refines).  UART on the
 * FT2232H's second channel at 115200 baud; the user button (BTN_N) resets; the red LED is on while
 * a job runs, the green LED after an RX overrun (a job was lost).  Pins: icebreaker.pcf.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module icebreaker_top #
(
    // the oscillator's frequency in Hz, and the UART's baud rate: 104 clocks per bit (0.16 % off
    // 115200); the test bench's rate is higher
    parameter CLK_HZ = 12_000_000,
    parameter BAUD = 115_200,
    // reset lasts 2^POR_BITS clocks (5.5 ms at 12 MHz)
    parameter POR_BITS = 16,
    // a header or job is dropped after 2^TIMEOUT_BITS clocks without a byte (0.7 s at 12 MHz)
    parameter TIMEOUT_BITS = 23
)
(
    input  wire  CLK,      // 12 MHz
    input  wire  RX,       // FTDI transmits, FPGA receives
    output wire  TX,       // FPGA transmits
    input  wire  BTN_N,    // user button, low when pressed
    output wire  LEDR_N,   // red LED, low to light
    output wire  LEDG_N    // green LED, low to light
);

wire rst;

wm_por #(
    .POR_BITS(POR_BITS),
    .BUTTON_ACTIVE_HIGH(0)
) por_inst (
    .clk(CLK),
    .button(BTN_N),
    .rst(rst)
);

wire busy;
wire overrun;

stage_uart #(
    .CLK_HZ(CLK_HZ),
    .BAUD(BAUD),
    .TIMEOUT_BITS(TIMEOUT_BITS)
) stage_inst (
    .clk(CLK),
    .rst(rst),
    .rxd(RX),
    .txd(TX),
    .busy(busy),
    .rx_overrun(overrun)
);

assign LEDR_N = !busy;
assign LEDG_N = !overrun;

endmodule

`resetall
