/*
 * wavemesh: the SoC, a PicoRV32 (RV32IMC) with its memories and peripherals
 *
 * The CPU comes from the pythondata-cpu-picorv32 package (picorv32.v, never copied here).  Memory
 * map (docs/soc.md; generated from host/wavemesh/memmap.py into wm_memmap.vh):
 *
 *   0x0000_0000  FW_RAM  firmware RAM, FW_RAM_BYTES, loaded from FW_HEX; reset vector 0
 *   0x1000_0000  HEIGHT  height memory, HEIGHT_SAMPLES x 16 bit (two samples per 32-bit word)
 *   0x2000_0000  COEF    coefficient memory, COEF_ENTRIES x 18 bit signed, one per word
 *   0x3000_0000  TOUT    template-stage output, TOUT_ENTRIES x 16 bit, one per word
 *   0x4000_0000  UART    soc_uart registers
 *   0x4000_0100  SYS     soc_sys registers (cycles, timer, LEDs, stage, halt, configuration)
 *   0x4000_0200  ACCEL   soc_accel registers: the FPGA stage (filter bank, template stage)
 *
 * The FPGA stage (soc_accel) reads HEIGHT and writes COEF and TOUT while it is busy: it then owns
 * those three memories' ports, and CPU accesses to them are dropped (reads return stale data).
 *
 * Address bits 31..28 select the region; an offset beyond a region's size, or any other address,
 * reads 0 and ignores writes.  Every access completes in two cycles (request, then mem_ready with
 * the registered read data), so a bad address never stalls the CPU.
 *
 * The simulation ports (uart_bypass and the two byte streams, the stage/halt strobes, uart_div,
 * trap) serve the Verilator board model in sim/; a board ties uart_bypass low and leaves the
 * others open.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_top #
(
    // system clock in Hz (reported by SYS.CLK_HZ)
    parameter CLK_HZ = `WM_CLK_HZ,
    // firmware RAM in bytes; a multiple of 4, <= 256 MiB
    parameter FW_RAM_BYTES = `WM_FW_RAM_ENTRIES * 4,
    // $readmemh image of the firmware RAM (one 32-bit word per line), "" for none
    parameter FW_HEX = "",
    // height memory in 16-bit samples; even, >= 2
    parameter HEIGHT_SAMPLES = `WM_HEIGHT_ENTRIES,
    // coefficient memory in 18-bit entries; >= 2
    parameter COEF_ENTRIES = `WM_COEF_ENTRIES,
    // template-stage output memory in 16-bit entries; >= 2
    parameter TOUT_ENTRIES = `WM_TOUT_ENTRIES,
    // UART FIFO depths in bytes; powers of two >= 2
    parameter UART_RX_DEPTH = `WM_UART_RX_DEPTH,
    parameter UART_TX_DEPTH = `WM_UART_TX_DEPTH,
    // UART baud divisor after reset (clock cycles per bit)
    parameter UART_DIV_RESET = `WM_UART_DIV_RESET,
    // LED outputs, 1..32
    parameter LED_COUNT = `WM_LED_COUNT
)
(
    input  wire                  clk,
    input  wire                  rst,

    /*
     * UART pins
     */
    input  wire                  uart_rxd,
    output wire                  uart_txd,

    /*
     * LEDs
     */
    output wire [LED_COUNT-1:0]  led,

    /*
     * Simulation: UART FIFO bypass (fast mode) and observation
     */
    input  wire                  uart_bypass,
    input  wire [7:0]            s_axis_uart_rx_tdata,
    input  wire                  s_axis_uart_rx_tvalid,
    output wire                  s_axis_uart_rx_tready,
    output wire [7:0]            m_axis_uart_tx_tdata,
    output wire                  m_axis_uart_tx_tvalid,
    input  wire                  m_axis_uart_tx_tready,
    output wire [15:0]           uart_div,       // current baud divisor
    output wire                  stage_valid,    // SYS.STAGE written
    output wire [31:0]           stage,
    output wire                  halt_valid,     // SYS.HALT written
    output wire [31:0]           halt_code,
    output wire                  trap            // the CPU trapped (illegal instruction, misaligned)
);


localparam FW_WORDS = FW_RAM_BYTES / 4;
localparam HEIGHT_WORDS = HEIGHT_SAMPLES / 2;
localparam FW_AW = $clog2(FW_WORDS);
localparam HEIGHT_AW = $clog2(HEIGHT_WORDS);
localparam COEF_AW = $clog2(COEF_ENTRIES);
localparam TOUT_AW = $clog2(TOUT_ENTRIES);

// region limits as byte offsets
localparam [31:0] FW_LIMIT = FW_RAM_BYTES;
localparam [31:0] HEIGHT_LIMIT = HEIGHT_SAMPLES * 2;
localparam [31:0] COEF_LIMIT = COEF_ENTRIES * 4;
localparam [31:0] TOUT_LIMIT = TOUT_ENTRIES * 4;

// check configuration
initial begin
    if (FW_RAM_BYTES < 8 || FW_RAM_BYTES % 4 != 0 || FW_RAM_BYTES > (1 << 28)) begin
        $error("Error: FW_RAM_BYTES must be a multiple of 4, 8 .. 256 MiB (instance %m)");
        $finish;
    end
    if (HEIGHT_SAMPLES < 4 || HEIGHT_SAMPLES % 2 != 0 || HEIGHT_SAMPLES > (1 << 27)) begin
        $error("Error: HEIGHT_SAMPLES must be even, 4 .. 2^27 (instance %m)");
        $finish;
    end
    if (COEF_ENTRIES < 2 || COEF_ENTRIES > (1 << 26) || TOUT_ENTRIES < 2 || TOUT_ENTRIES > (1 << 26)) begin
        $error("Error: COEF_ENTRIES and TOUT_ENTRIES must be 2 .. 2^26 (instance %m)");
        $finish;
    end
end

/*
 * CPU
 */
wire        mem_valid;
wire        mem_instr_unused;
wire [31:0] mem_addr;
wire [31:0] mem_wdata;
wire [3:0]  mem_wstrb;
reg         mem_ready_reg = 1'b0;
reg  [31:0] mem_rdata;

wire        mem_la_read_unused;
wire        mem_la_write_unused;
wire [31:0] mem_la_addr_unused;
wire [31:0] mem_la_wdata_unused;
wire [3:0]  mem_la_wstrb_unused;
wire        pcpi_valid_unused;
wire [31:0] pcpi_insn_unused;
wire [31:0] pcpi_rs1_unused;
wire [31:0] pcpi_rs2_unused;
wire [31:0] eoi_unused;
wire        trace_valid_unused;
wire [35:0] trace_data_unused;

picorv32 #(
    .ENABLE_COUNTERS(1),
    .ENABLE_COUNTERS64(1),
    .ENABLE_REGS_16_31(1),
    .ENABLE_REGS_DUALPORT(1),
    .BARREL_SHIFTER(1),
    .COMPRESSED_ISA(1),
    .CATCH_MISALIGN(1),
    .CATCH_ILLINSN(1),
    .ENABLE_PCPI(0),
    .ENABLE_MUL(0),
    .ENABLE_FAST_MUL(1),
    .ENABLE_DIV(1),
    .ENABLE_IRQ(0),
    .ENABLE_TRACE(0),
    .PROGADDR_RESET(32'h0000_0000),
    .STACKADDR(FW_LIMIT)
) cpu_inst (
    .clk(clk),
    .resetn(!rst),
    .trap(trap),
    .mem_valid(mem_valid),
    .mem_instr(mem_instr_unused),
    .mem_ready(mem_ready_reg),
    .mem_addr(mem_addr),
    .mem_wdata(mem_wdata),
    .mem_wstrb(mem_wstrb),
    .mem_rdata(mem_rdata),
    .mem_la_read(mem_la_read_unused),
    .mem_la_write(mem_la_write_unused),
    .mem_la_addr(mem_la_addr_unused),
    .mem_la_wdata(mem_la_wdata_unused),
    .mem_la_wstrb(mem_la_wstrb_unused),
    .pcpi_valid(pcpi_valid_unused),
    .pcpi_insn(pcpi_insn_unused),
    .pcpi_rs1(pcpi_rs1_unused),
    .pcpi_rs2(pcpi_rs2_unused),
    .pcpi_wr(1'b0),
    .pcpi_rd(32'd0),
    .pcpi_wait(1'b0),
    .pcpi_ready(1'b0),
    .irq(32'd0),
    .eoi(eoi_unused),
    .trace_valid(trace_valid_unused),
    .trace_data(trace_data_unused)
);

/*
 * Address decoding
 */
localparam [2:0]
    SEL_NONE   = 3'd0,
    SEL_FW     = 3'd1,
    SEL_HEIGHT = 3'd2,
    SEL_COEF   = 3'd3,
    SEL_TOUT   = 3'd4,
    SEL_UART   = 3'd5,
    SEL_SYS    = 3'd6,
    SEL_ACCEL  = 3'd7;

reg [2:0] sel_reg = SEL_NONE;

// a request is the first cycle of mem_valid; mem_ready answers it in the next cycle
wire req = mem_valid && !mem_ready_reg;
wire [3:0] region = mem_addr[31:28];
wire [31:0] offset = {4'd0, mem_addr[27:0]};
wire io_page = region == `WM_REGION_IO && mem_addr[27:12] == 16'd0;

wire fw_hit = region == `WM_REGION_FW_RAM && offset < FW_LIMIT;
wire height_hit = region == `WM_REGION_HEIGHT && offset < HEIGHT_LIMIT;
wire coef_hit = region == `WM_REGION_COEF && offset < COEF_LIMIT;
wire tout_hit = region == `WM_REGION_TOUT && offset < TOUT_LIMIT;
wire uart_hit = io_page && mem_addr[11:8] == `WM_IO_UART;
wire sys_hit = io_page && mem_addr[11:8] == `WM_IO_SYS;
wire accel_hit = io_page && mem_addr[11:8] == `WM_IO_ACCEL;

reg [2:0] sel;
always @* begin
    if (fw_hit) sel = SEL_FW;
    else if (height_hit) sel = SEL_HEIGHT;
    else if (coef_hit) sel = SEL_COEF;
    else if (tout_hit) sel = SEL_TOUT;
    else if (uart_hit) sel = SEL_UART;
    else if (sys_hit) sel = SEL_SYS;
    else if (accel_hit) sel = SEL_ACCEL;
    else sel = SEL_NONE;
end

always @(posedge clk) begin
    // every request is answered in the next cycle, mapped or not
    mem_ready_reg <= req;
    if (req) begin
        sel_reg <= sel;
    end

    if (rst) begin
        mem_ready_reg <= 1'b0;
        sel_reg <= SEL_NONE;
    end
end

wire [31:0] fw_rdata;
wire [31:0] height_rdata;
wire [31:0] coef_rdata;
wire [31:0] tout_rdata;
wire [31:0] uart_rdata;
wire [31:0] sys_rdata;
wire [31:0] accel_rdata;

always @* begin
    case (sel_reg)
        SEL_FW: mem_rdata = fw_rdata;
        SEL_HEIGHT: mem_rdata = height_rdata;
        SEL_COEF: mem_rdata = coef_rdata;
        SEL_TOUT: mem_rdata = tout_rdata;
        SEL_UART: mem_rdata = uart_rdata;
        SEL_SYS: mem_rdata = sys_rdata;
        SEL_ACCEL: mem_rdata = accel_rdata;
        default: mem_rdata = 32'd0;
    endcase
end

/*
 * The FPGA stage and its ports into HEIGHT, COEF and TOUT (it owns them while busy)
 */
wire                accel_busy;
wire                accel_height_en;
wire [HEIGHT_AW-1:0] accel_height_addr;
wire                accel_coef_en;
wire [COEF_AW-1:0]  accel_coef_addr;
wire [17:0]         accel_coef_wdata;
wire                accel_tout_en;
wire [TOUT_AW-1:0]  accel_tout_addr;
wire [15:0]         accel_tout_wdata;

soc_accel #(
    .HEIGHT_SAMPLES(HEIGHT_SAMPLES),
    .COEF_ENTRIES(COEF_ENTRIES),
    .TOUT_ENTRIES(TOUT_ENTRIES)
) accel_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && accel_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(accel_rdata),
    .busy(accel_busy),
    .height_en(accel_height_en),
    .height_addr(accel_height_addr),
    .height_rdata(height_rdata),
    .coef_en(accel_coef_en),
    .coef_addr(accel_coef_addr),
    .coef_wdata(accel_coef_wdata),
    .tout_en(accel_tout_en),
    .tout_addr(accel_tout_addr),
    .tout_wdata(accel_tout_wdata)
);

// port multiplexers: the stage while busy, else the CPU
wire                 height_en = accel_busy ? accel_height_en : req && height_hit;
wire [3:0]           height_wstrb = accel_busy ? 4'b0000 : mem_wstrb;
wire [HEIGHT_AW-1:0] height_addr = accel_busy ? accel_height_addr : mem_addr[HEIGHT_AW+1:2];
wire                 coef_en = accel_busy ? accel_coef_en : req && coef_hit;
wire [3:0]           coef_wstrb = accel_busy ? 4'b1111 : mem_wstrb;
wire [COEF_AW-1:0]   coef_addr = accel_busy ? accel_coef_addr : mem_addr[COEF_AW+1:2];
wire [31:0]          coef_wdata = accel_busy ? {{14{accel_coef_wdata[17]}}, accel_coef_wdata} : mem_wdata;
wire                 tout_en = accel_busy ? accel_tout_en : req && tout_hit;
wire [3:0]           tout_wstrb = accel_busy ? 4'b1111 : mem_wstrb;
wire [TOUT_AW-1:0]   tout_addr = accel_busy ? accel_tout_addr : mem_addr[TOUT_AW+1:2];
wire [31:0]          tout_wdata = accel_busy ? {16'd0, accel_tout_wdata} : mem_wdata;

/*
 * Memories
 */
soc_ram #(
    .WIDTH(32),
    .DEPTH(FW_WORDS),
    .INIT_FILE(FW_HEX)
) fw_ram_inst (
    .clk(clk),
    .en(req && fw_hit),
    .wstrb(mem_wstrb),
    .addr(mem_addr[FW_AW+1:2]),
    .wdata(mem_wdata),
    .rdata(fw_rdata)
);

soc_ram #(
    .WIDTH(32),
    .DEPTH(HEIGHT_WORDS)
) height_ram_inst (
    .clk(clk),
    .en(height_en),
    .wstrb(height_wstrb),
    .addr(height_addr),
    .wdata(mem_wdata),
    .rdata(height_rdata)
);

soc_ram #(
    .WIDTH(18),
    .DEPTH(COEF_ENTRIES),
    .SIGNED(1)
) coef_ram_inst (
    .clk(clk),
    .en(coef_en),
    .wstrb(coef_wstrb),
    .addr(coef_addr),
    .wdata(coef_wdata),
    .rdata(coef_rdata)
);

soc_ram #(
    .WIDTH(16),
    .DEPTH(TOUT_ENTRIES)
) tout_ram_inst (
    .clk(clk),
    .en(tout_en),
    .wstrb(tout_wstrb),
    .addr(tout_addr),
    .wdata(tout_wdata),
    .rdata(tout_rdata)
);

/*
 * Peripherals
 */
soc_uart #(
    .RX_DEPTH(UART_RX_DEPTH),
    .TX_DEPTH(UART_TX_DEPTH),
    .DIV_RESET(UART_DIV_RESET),
    .DIV_MIN(`WM_UART_DIV_MIN)
) uart_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && uart_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(uart_rdata),
    .rxd(uart_rxd),
    .txd(uart_txd),
    .bypass(uart_bypass),
    .s_axis_rx_tdata(s_axis_uart_rx_tdata),
    .s_axis_rx_tvalid(s_axis_uart_rx_tvalid),
    .s_axis_rx_tready(s_axis_uart_rx_tready),
    .m_axis_tx_tdata(m_axis_uart_tx_tdata),
    .m_axis_tx_tvalid(m_axis_uart_tx_tvalid),
    .m_axis_tx_tready(m_axis_uart_tx_tready),
    .div(uart_div)
);

soc_sys #(
    .LED_COUNT(LED_COUNT),
    .CLK_HZ(CLK_HZ),
    .FW_RAM_BYTES(FW_RAM_BYTES),
    .HEIGHT_SAMPLES(HEIGHT_SAMPLES),
    .COEF_ENTRIES(COEF_ENTRIES),
    .TOUT_ENTRIES(TOUT_ENTRIES)
) sys_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && sys_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(sys_rdata),
    .led(led),
    .stage_valid(stage_valid),
    .stage(stage),
    .halt_valid(halt_valid),
    .halt_code(halt_code)
);

endmodule

`resetall
