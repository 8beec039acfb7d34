/*
 * wavemesh: the VexRiscv as the SoC's CPU, behind the PicoRV32's native memory interface
 *
 * The CPU is the IMAC VexRiscv of the pythondata-cpu-vexriscv package (VexRiscv_IMAC.v, never copied
 * here; its module is VexRiscv, as in the package's other variants): RV32IMAC, 5 stages, a 32 KiB
 * instruction cache and a 32 KiB write-through data cache (the package's 4 KiB ones made larger in a
 * derived copy of the file: host/wavemesh/device/soc_cpu.py, icache_resized and dcache_resized),
 * one-cycle multiplier, 33-cycle divider.  soc_top
 * instantiates this module instead of picorv32 when WM_CPU_VEXRISCV is defined
 * (host/wavemesh/device/soc_cpu.py chooses; docs/soc.md, "The CPU").
 *
 * Its two Wishbone buses use classic cycles; the caches refill 32-byte lines as bursts of 8 words, one
 * word per ACK.  The data bus is the native bus: mem_valid, mem_addr, mem_wdata, mem_wstrb are its
 * STB, ADR, DAT_MOSI, SEL (a read has wstrb 0), held until mem_ready, its ACK, with mem_rdata its
 * DAT_MISO; each word takes what the native bus takes (2 cycles in block RAM and on an SDRAM cache
 * hit).  The instruction bus reads the firmware RAM's port B (ibus_*, soc_ram): a word a cycle after
 * the first, 9 cycles a line refill, beside the data bus.
 *
 * The data cache treats only addresses with bit 31 set as I/O (uncached): the memory map puts the
 * I/O region there.  It does not see the FPGA stage's writes into the SDRAM: the firmware flushes it
 * after the stage (wm_sys.h, wm_dcache_flush).  mem_instr is low: no fetch uses the native bus
 * (sim/board_sim.v's profile counts the refills on port B).
 * trap: an instruction fetch outside the firmware RAM (the VexRiscv has no trap output; an
 * exception jumps to mtvec, which the firmware never sets; sim/board_sim.v adds the CPU's own
 * exception flag to the simulator's trap).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module soc_cpu_vexriscv #
(
    // reset vector
    parameter [31:0] PROGADDR_RESET = 32'h0000_0000,
    // instruction fetches at or above this address raise trap
    parameter [31:0] FETCH_LIMIT = 32'h0002_0000
)
(
    input  wire         clk,
    input  wire         rst,
    output wire         trap,

    /*
     * PicoRV32 native memory interface
     */
    output wire         mem_valid,
    output wire         mem_instr,
    input  wire         mem_ready,
    output wire [31:0]  mem_addr,
    output wire [31:0]  mem_wdata,
    output wire [3:0]   mem_wstrb,
    input  wire [31:0]  mem_rdata,

    /*
     * the instruction bus: a read port of the firmware RAM (soc_ram's port B; word address)
     */
    output wire         ibus_en,
    output wire [29:0]  ibus_addr,
    input  wire [31:0]  ibus_rdata
);

wire        i_cyc, i_stb, i_we;
wire [29:0] i_adr;
wire [31:0] i_dat_mosi_unused;
wire [3:0]  i_sel;
wire [2:0]  i_cti_unused;
wire [1:0]  i_bte_unused;
wire        d_cyc, d_stb, d_we;
wire [29:0] d_adr;
wire [31:0] d_dat_mosi;
wire [3:0]  d_sel;
wire [2:0]  d_cti_unused;
wire [1:0]  d_bte_unused;

// the data bus is the native bus's only master
assign mem_valid = d_cyc && d_stb;
assign mem_instr = 1'b0;
assign mem_addr = {d_adr, 2'b00};
assign mem_wdata = d_dat_mosi;
assign mem_wstrb = d_we ? d_sel : 4'd0;
wire d_ack = mem_ready;

// the instruction bus reads the firmware RAM's port B: the word addressed in one cycle is there in
// the next, acknowledged when it is the one the bus still asks for; with an acknowledge the port
// reads the next word of the line (the cache's refill asks for them in order), so a refill of 8
// words takes 9 cycles
wire       i_req = i_cyc && i_stb;
reg        i_rd_valid_reg = 1'b0;
reg [29:0] i_rd_addr_reg = 30'd0;
wire       i_ack = i_req && i_rd_valid_reg && i_rd_addr_reg == i_adr;
assign ibus_en = i_req;
assign ibus_addr = i_ack ? {i_adr[29:3], i_adr[2:0] + 3'd1} : i_adr;

always @(posedge clk) begin
    i_rd_valid_reg <= i_req;
    i_rd_addr_reg <= ibus_addr;
    if (rst) begin
        i_rd_valid_reg <= 1'b0;
    end
end

// the instruction bus only reads whole words
wire i_unused = i_we | ^i_sel;

assign trap = i_req && {i_adr, 2'b00} >= FETCH_LIMIT;

VexRiscv cpu_inst (
    .externalResetVector(PROGADDR_RESET),
    .timerInterrupt(1'b0),
    .softwareInterrupt(1'b0),
    .externalInterruptArray(32'd0),
    .iBusWishbone_CYC(i_cyc),
    .iBusWishbone_STB(i_stb),
    .iBusWishbone_ACK(i_ack),
    .iBusWishbone_WE(i_we),
    .iBusWishbone_ADR(i_adr),
    .iBusWishbone_DAT_MISO(ibus_rdata),
    .iBusWishbone_DAT_MOSI(i_dat_mosi_unused),
    .iBusWishbone_SEL(i_sel),
    .iBusWishbone_ERR(1'b0),
    .iBusWishbone_CTI(i_cti_unused),
    .iBusWishbone_BTE(i_bte_unused),
    .dBusWishbone_CYC(d_cyc),
    .dBusWishbone_STB(d_stb),
    .dBusWishbone_ACK(d_ack),
    .dBusWishbone_WE(d_we),
    .dBusWishbone_ADR(d_adr),
    .dBusWishbone_DAT_MISO(mem_rdata),
    .dBusWishbone_DAT_MOSI(d_dat_mosi),
    .dBusWishbone_SEL(d_sel),
    .dBusWishbone_ERR(1'b0),
    .dBusWishbone_CTI(d_cti_unused),
    .dBusWishbone_BTE(d_bte_unused),
    .clk(clk),
    .reset(rst)
);

endmodule

`resetall
