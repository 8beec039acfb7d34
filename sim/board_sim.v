/*
 * wavemesh: Verilator top of the simulated board (sim/board_main.cpp drives it)
 *
 * soc_top with every port brought out, built without a firmware image: the model loads one at
 * start-up with the same $readmemh the FPGA build uses, from the +firmware=FILE plusarg
 * (board_main.cpp's --firmware option), so one simulator build runs any firmware.  The SDRAM pins
 * go to sdram_chip, the chip's cycle model with the datasheet's timing checks, so the board model
 * is the bitstream's design (rtl/boards/ulx3s_top.v adds only the pads, the chip's inverted clock
 * and the reset).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module board_sim
(
    input  wire         clk,
    input  wire         rst,

    input  wire         uart_rxd,
    output wire         uart_txd,
    output wire [`WM_LED_COUNT-1:0] led,

    input  wire         uart_bypass,
    input  wire [7:0]   s_axis_uart_rx_tdata,
    input  wire         s_axis_uart_rx_tvalid,
    output wire         s_axis_uart_rx_tready,
    output wire [7:0]   m_axis_uart_tx_tdata,
    output wire         m_axis_uart_tx_tvalid,
    input  wire         m_axis_uart_tx_tready,
    output wire [15:0]  uart_div,
    output wire         stage_valid,
    output wire [31:0]  stage,
    output wire         halt_valid,
    output wire [31:0]  halt_code,
    output wire         trap,

    // for wmsim --profile: an instruction fetch completes this cycle, and its address (the PC)
    output wire         prof_fetch,
    output wire [31:0]  prof_pc
);

assign prof_fetch = soc_inst.mem_valid && soc_inst.mem_instr_unused && soc_inst.mem_ready;

wire        sdram_cke, sdram_cs_n, sdram_ras_n, sdram_cas_n, sdram_we_n;
wire [1:0]  sdram_ba, sdram_dqm;
wire [`WM_SDRAM_ROW_BITS-1:0] sdram_a;
wire [15:0] sdram_dq_o, sdram_dq_i;
wire        sdram_dq_oe;
assign prof_pc = soc_inst.mem_addr;

soc_top #(
    .FW_HEX(""),
    .LED_COUNT(`WM_LED_COUNT)
) soc_inst (
    .clk(clk),
    .rst(rst),
    .uart_rxd(uart_rxd),
    .uart_txd(uart_txd),
    .led(led),
    .sdram_cke(sdram_cke),
    .sdram_cs_n(sdram_cs_n),
    .sdram_ras_n(sdram_ras_n),
    .sdram_cas_n(sdram_cas_n),
    .sdram_we_n(sdram_we_n),
    .sdram_ba(sdram_ba),
    .sdram_a(sdram_a),
    .sdram_dqm(sdram_dqm),
    .sdram_dq_o(sdram_dq_o),
    .sdram_dq_oe(sdram_dq_oe),
    .sdram_dq_i(sdram_dq_i),
    .uart_bypass(uart_bypass),
    .s_axis_uart_rx_tdata(s_axis_uart_rx_tdata),
    .s_axis_uart_rx_tvalid(s_axis_uart_rx_tvalid),
    .s_axis_uart_rx_tready(s_axis_uart_rx_tready),
    .m_axis_uart_tx_tdata(m_axis_uart_tx_tdata),
    .m_axis_uart_tx_tvalid(m_axis_uart_tx_tvalid),
    .m_axis_uart_tx_tready(m_axis_uart_tx_tready),
    .uart_div(uart_div),
    .stage_valid(stage_valid),
    .stage(stage),
    .halt_valid(halt_valid),
    .halt_code(halt_code),
    .trap(trap)
);

sdram_chip sdram_inst (
    .clk(clk),
    .cke(sdram_cke),
    .cs_n(sdram_cs_n),
    .ras_n(sdram_ras_n),
    .cas_n(sdram_cas_n),
    .we_n(sdram_we_n),
    .ba(sdram_ba),
    .a(sdram_a),
    .dqm(sdram_dqm),
    .dq_o(sdram_dq_o),
    .dq_oe(sdram_dq_oe),
    .dq_i(sdram_dq_i)
);

// the firmware image, loaded before the first clock edge
reg [8*1024-1:0] firmware;

initial begin
    if ($value$plusargs("firmware=%s", firmware)) begin
        $readmemh(firmware, soc_inst.fw_ram_inst.mem);
    end
end

endmodule

`resetall
