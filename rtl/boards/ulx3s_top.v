/*
 * wavemesh: the ULX3S board top (Lattice ECP5-85F, CABGA381; 25 MHz oscillator)
 *
 * The whole SoC (rtl/soc_top.v: the CPU, firmware image in block RAM, FPGA stage) on the system clock
 * the ECP5's PLL makes from the board's 25 MHz oscillator (ecp5_pll: the memory map's CLK_HZ, 39 MHz;
 * the SoC stays in reset until the PLL locks); its UART on the FT231X's serial port (ftdi_txd in,
 * ftdi_rxd out: the names are the FTDI chip's), the eight LEDs, FIRE1 (btn[1]) as the reset button.
 * wifi_gpio0 is driven high: the ESP32 holds the board in reset or reconfigures it when this pin
 * floats low.
 * The SDRAM: the chip's clock is the inverted system clock, so it samples every command and datum
 * in the middle of its cycle (12.8 ns from either edge at 39 MHz: the inverter's and the pads' few ns
 * of skew leave far more than the chip's 1.5 ns setup and 0.8 ns hold; a read datum, valid 6 ns after
 * the chip's edge, is sampled 12.8 ns after it); DQ through the pads' tristate buffers; every other
 * pin straight from the controller's registers.
 * Pins: ulx3s.lpf.  `make bitstream BOARD=ulx3s` builds it with the firmware image as FW_HEX.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module ulx3s_top #
(
    // $readmemh image of the firmware RAM (set by tools/boards.mk)
    parameter FW_HEX = ""
)
(
    input  wire        clk_25mhz,
    input  wire        ftdi_txd,    // FTDI transmits, FPGA receives
    output wire        ftdi_rxd,    // FPGA transmits, FTDI receives
    input  wire [1:1]  btn,         // FIRE1, high when pressed
    output wire [`WM_LED_COUNT-1:0] led,  // D0..D7
    output wire        wifi_gpio0,

    // SDRAM
    output wire        sdram_clk,
    output wire        sdram_cke,
    output wire        sdram_csn,
    output wire        sdram_rasn,
    output wire        sdram_casn,
    output wire        sdram_wen,
    output wire [1:0]  sdram_ba,
    output wire [`WM_SDRAM_ROW_BITS-1:0] sdram_a,
    output wire [1:0]  sdram_dqm,
    inout  wire [15:0] sdram_d
);

wire clk;
wire pll_locked;
wire rst;

ecp5_pll #(
    .CLKI_DIV(`WM_PLL_CLKI_DIV),
    .CLKFB_DIV(`WM_PLL_CLKFB_DIV),
    .CLKOP_DIV(`WM_PLL_CLKOP_DIV),
    .CLKOP_CPHASE(`WM_PLL_CLKOP_CPHASE),
    .CLKOS_DIV(`WM_PLL_CLKOS_DIV),
    .CLKOS_CPHASE(`WM_PLL_CLKOS_CPHASE)
) pll_inst (
    .clk_in(clk_25mhz),
    .clk_out(clk),
    .locked(pll_locked)
);

// reset while the PLL has not locked, as while the button is pressed (and 2^16 clocks after either)
wm_por #(
    .BUTTON_ACTIVE_HIGH(1)
) por_inst (
    .clk(clk),
    .button(btn[1] || !pll_locked),
    .rst(rst)
);

assign wifi_gpio0 = 1'b1;

assign sdram_clk = !clk;

wire [15:0] sdram_dq_o;
wire        sdram_dq_oe;
assign sdram_d = sdram_dq_oe ? sdram_dq_o : 16'bz;

wire [7:0]  tx_tdata_unused;
wire        tx_tvalid_unused;
wire        rx_tready_unused;
wire [15:0] uart_div_unused;
wire        stage_valid_unused;
wire [31:0] stage_unused;
wire        halt_valid_unused;
wire [31:0] halt_code_unused;
wire        trap_unused;

// the simulated board's configuration (sim/board_sim.v): the memory map's clock (the PLL's output;
// tests/host/test_boards_flow.py checks they agree), sizes and LEDs; only the firmware comes in
// differently (here built in, there loaded at start-up from the same image)
soc_top #(
    .CLK_HZ(`WM_CLK_HZ),
    .FW_HEX(FW_HEX),
    .LED_COUNT(`WM_LED_COUNT)
) soc_inst (
    .clk(clk),
    .rst(rst),
    .uart_rxd(ftdi_txd),
    .uart_txd(ftdi_rxd),
    .led(led),
    .sdram_cke(sdram_cke),
    .sdram_cs_n(sdram_csn),
    .sdram_ras_n(sdram_rasn),
    .sdram_cas_n(sdram_casn),
    .sdram_we_n(sdram_wen),
    .sdram_ba(sdram_ba),
    .sdram_a(sdram_a),
    .sdram_dqm(sdram_dqm),
    .sdram_dq_o(sdram_dq_o),
    .sdram_dq_oe(sdram_dq_oe),
    .sdram_dq_i(sdram_d),
    .uart_bypass(1'b0),
    .s_axis_uart_rx_tdata(8'd0),
    .s_axis_uart_rx_tvalid(1'b0),
    .s_axis_uart_rx_tready(rx_tready_unused),
    .m_axis_uart_tx_tdata(tx_tdata_unused),
    .m_axis_uart_tx_tvalid(tx_tvalid_unused),
    .m_axis_uart_tx_tready(1'b0),
    .uart_div(uart_div_unused),
    .stage_valid(stage_valid_unused),
    .stage(stage_unused),
    .halt_valid(halt_valid_unused),
    .halt_code(halt_code_unused),
    .trap(trap_unused)
);

endmodule

`resetall
