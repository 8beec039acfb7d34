/*
 * wavemesh: Verilator top of the simulated iCEBreaker (sim/icebreaker_main.cpp drives it)
 *
 * The iCEBreaker bitstream's top itself, rtl/boards/icebreaker_top.v, with its default parameters
 * (12 MHz, 115200 baud, the 2^16-clock power-on reset, the 0.7 s silence timeout): the FPGA stage
 * behind its UART pins.  Only the UART's divisor is brought out (read through a hierarchical
 * reference), so the program's line model runs at the stage's own bit time.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module icebreaker_sim
(
    input  wire         clk,
    input  wire         btn_n,      // the user button, low when pressed
    input  wire         rxd,
    output wire         txd,
    output wire         ledr_n,
    output wire         ledg_n,
    output wire [15:0]  uart_div    // clock cycles per bit
);

icebreaker_top top_inst (
    .CLK(clk),
    .RX(rxd),
    .TX(txd),
    .BTN_N(btn_n),
    .LEDR_N(ledr_n),
    .LEDG_N(ledg_n)
);

assign uart_div = top_inst.stage_inst.DIV16;

endmodule

`resetall
