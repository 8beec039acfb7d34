/*
 * wavemesh: Verilator top of the simulated board (sim/board_main.cpp drives it)
 *
 * The ULX3S bitstream's top itself, rtl/boards/ulx3s_top.v, with its default parameters: its
 * power-on reset (rtl/boards/wm_por.v, 2^16 clocks), FIRE1 (btn[1]) as the reset button (the
 * program's `rst` presses it), the UART on the FTDI pins, the LEDs, wifi_gpio0, and the SDRAM pins,
 * which go to sdram_chip, the chip's cycle model with the datasheet's timing checks (it runs on the
 * falling edge of the system clock, as the chip on the board's inverted sdram_clk; DQ is the top's
 * tristate bus, driven by the chip while the controller's enable is low).  What a bitstream does not
 * have is added from outside, without changing the top:
 *
 * - the firmware image: the bitstream has it built in (FW_HEX); here the top is built without one
 *   (FW_HEX "", its default) and the same $readmemh loads it into the same memory at start-up from
 *   the +firmware=FILE plusarg (board_main.cpp's --firmware option), so one simulator runs any
 *   firmware;
 * - the fast mode (wmsim --fast): soc_top's UART bypass ports, which ulx3s_top ties off (bypass
 *   low, no bytes), are forced by board_main.cpp (board_sim.vlt makes them forceable: a force
 *   statement here would cost every read of them a lookup in Verilator's force table); in pin mode
 *   the forced values are the tie-offs' (uart_bypass low, no valid byte, tready low), so the top
 *   runs as on the board;
 * - the observation ports: soc_top's stage, halt, trap and uart_div outputs, which ulx3s_top leaves
 *   unconnected, the profile's fetch address, and the controller's DQ enable for the chip model,
 *   read through hierarchical references.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module board_sim
(
    input  wire         clk,
    input  wire         rst,        // FIRE1 held down

    input  wire         uart_rxd,
    output wire         uart_txd,
    output wire [`WM_LED_COUNT-1:0] led,

    output wire         s_axis_uart_rx_tready,
    output wire [7:0]   m_axis_uart_tx_tdata,
    output wire         m_axis_uart_tx_tvalid,
    output wire [15:0]  uart_div,
    output wire         stage_valid,
    output wire [31:0]  stage,
    output wire         halt_valid,
    output wire [31:0]  halt_code,
    output wire         trap,

    // for wmsim --profile: an instruction fetch completes this cycle, and its address (the PC); the
    // VexRiscv fetches through its cache, so there: the instruction in its last stage, and its PC
    output wire         prof_fetch,
    output wire [31:0]  prof_fetch_pc,
    output wire [31:0]  prof_pc,
    // for wmsim --data-profile: a bus access for data waits (request made, not answered) this cycle,
    // or completes; its address (prof_pc) and whether it writes
    output wire         prof_data_wait,
    output wire         prof_data_done,
    output wire         prof_data_write,
    // for wmsim --profile: an instruction fetch waits this cycle (the PicoRV32's on the memory bus;
    // the VexRiscv's instruction cache's line refills, on the firmware RAM's port B)
    output wire         prof_ibus,
    output wire [31:0]  prof_ibus_addr
);

wire        wifi_gpio0;
wire        sdram_clk_unused;
wire        sdram_cke, sdram_csn, sdram_rasn, sdram_casn, sdram_wen;
wire [1:0]  sdram_ba, sdram_dqm;
wire [`WM_SDRAM_ROW_BITS-1:0] sdram_a;
wire [15:0] sdram_d;

ulx3s_top top_inst (
    .clk_25mhz(clk),
    .ftdi_txd(uart_rxd),
    .ftdi_rxd(uart_txd),
    .btn(rst),
    .led(led),
    .wifi_gpio0(wifi_gpio0),
    .sdram_clk(sdram_clk_unused),
    .sdram_cke(sdram_cke),
    .sdram_csn(sdram_csn),
    .sdram_rasn(sdram_rasn),
    .sdram_casn(sdram_casn),
    .sdram_wen(sdram_wen),
    .sdram_ba(sdram_ba),
    .sdram_a(sdram_a),
    .sdram_dqm(sdram_dqm),
    .sdram_d(sdram_d)
);

// the chip on the pins; it drives DQ whenever the controller does not
wire        sdram_dq_oe = top_inst.sdram_dq_oe;
wire [15:0] chip_dq;

sdram_chip sdram_inst (
    .clk(clk),
    .cke(sdram_cke),
    .cs_n(sdram_csn),
    .ras_n(sdram_rasn),
    .cas_n(sdram_casn),
    .we_n(sdram_wen),
    .ba(sdram_ba),
    .a(sdram_a),
    .dqm(sdram_dqm),
    .dq_o(sdram_d),
    .dq_oe(sdram_dq_oe),
    .dq_i(chip_dq)
);

assign sdram_d = sdram_dq_oe ? 16'bz : chip_dq;

assign s_axis_uart_rx_tready = top_inst.rx_tready_unused;
assign m_axis_uart_tx_tdata = top_inst.tx_tdata_unused;
assign m_axis_uart_tx_tvalid = top_inst.tx_tvalid_unused;
assign uart_div = top_inst.uart_div_unused;
assign stage_valid = top_inst.stage_valid_unused;
assign stage = top_inst.stage_unused;
assign halt_valid = top_inst.halt_valid_unused;
assign halt_code = top_inst.halt_code_unused;
`ifdef WM_CPU_VEXRISCV
// the VexRiscv's trap output is only a fetch outside the firmware RAM (soc_cpu_vexriscv): here also
// every exception it takes (illegal instruction, misaligned access), which jumps to mtvec
assign trap = top_inst.trap_unused || top_inst.soc_inst.cpu_inst.cpu_inst.CsrPlugin_hadException;
`else
assign trap = top_inst.trap_unused;
`endif

`ifdef WM_CPU_VEXRISCV
assign prof_fetch = top_inst.soc_inst.cpu_inst.cpu_inst.lastStageIsValid;
assign prof_fetch_pc = top_inst.soc_inst.cpu_inst.cpu_inst.lastStagePc;
`else
assign prof_fetch = top_inst.soc_inst.mem_valid && top_inst.soc_inst.mem_instr_unused
                    && top_inst.soc_inst.mem_ready;
assign prof_fetch_pc = top_inst.soc_inst.mem_addr;
`endif
assign prof_pc = top_inst.soc_inst.mem_addr;
assign prof_data_wait = top_inst.soc_inst.mem_valid && !top_inst.soc_inst.mem_instr_unused
                        && !top_inst.soc_inst.mem_ready;
assign prof_data_done = top_inst.soc_inst.mem_valid && !top_inst.soc_inst.mem_instr_unused
                        && top_inst.soc_inst.mem_ready;
assign prof_data_write = |top_inst.soc_inst.mem_wstrb;
`ifdef WM_CPU_VEXRISCV
assign prof_ibus = top_inst.soc_inst.cpu_inst.i_req;
assign prof_ibus_addr = {top_inst.soc_inst.cpu_inst.i_adr, 2'b00};
`else
assign prof_ibus = top_inst.soc_inst.mem_valid && top_inst.soc_inst.mem_instr_unused;
assign prof_ibus_addr = top_inst.soc_inst.mem_addr;
`endif

// the ESP32 must see wifi_gpio0 high (docs/boards.md): a top that let it go low would fail here
always @(posedge clk) begin
    if (!wifi_gpio0) begin
        $error("ulx3s_top drives wifi_gpio0 low");
    end
end

// the firmware image, loaded before the first clock edge
reg [8*1024-1:0] firmware;

initial begin
    if ($value$plusargs("firmware=%s", firmware)) begin
        $readmemh(firmware, top_inst.soc_inst.fw_ram_inst.mem);
    end
end

endmodule

`resetall
