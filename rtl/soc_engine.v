/*
 * wavemesh: the SoC's triangle error engine, tri_engine behind the ENGINE registers
 *
 * The CPU writes a triangle's corners, corner heights and limit into staging registers and queues it
 * with a PUSH write (the staging keeps its values, so a triangle that differs in a few registers takes
 * only those writes); tri_engine scans it, reading HEIGHT through the read port (soc_top hands it the
 * SDRAM controller's stream reader), and the result waits in its FIFO until the CPU reads RES_VMAX_LO,
 * RES_VMAX_HI and then RES_AT, whose read takes it.
 *
 * Registers (ENGINE block, wm_memmap.vh; docs/soc.md has the bit tables):
 *
 *   0x00 V0, 0x04 V1, 0x08 V2   rw  corner k: x in bits 15..0, y in 31..16 (counter-clockwise)
 *   0x0C Z01                    rw  z0 in bits 15..0, z1 in 31..16      0x10 Z2  rw  z2 in 15..0
 *   0x14 LIMIT_LO, 0x18 LIMIT_HI rw the 64-bit limit (all ones: none)
 *   0x1C PUSH                   w   queue the staged triangle (lost, OVERRUN set, while the queue is full)
 *   0x20 STATUS                 r   bit 0 RES_VALID, 1 CMD_FULL, 2 BUSY; bit 8 OVERRUN (w1c)
 *   0x24 RES_VMAX_LO, 0x28 RES_VMAX_HI  r  the oldest result's Vmax
 *   0x2C RES_AT                 r   its sample: x in 15..0, y in 30..16, bit 31 EMPTY; the read takes it
 *   0x30 WIDTH                  rw  W, samples per row of HEIGHT       0x34 MAX_SIDE  r  2^COORD_BITS
 *
 * Every access is answered in the next cycle (registered read data), as the other register blocks.
 * The corners' coordinates are taken modulo 2^COORD_BITS: the firmware gives the engine only grids of
 * at most MAX_SIDE a side.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_engine #
(
    // grid coordinate bits (tri_engine COORD_BITS): W, H <= 2^COORD_BITS; 2..15
    parameter COORD_BITS = `WM_ENGINE_COORD_BITS,
    // triangles the CPU may queue, >= 1
    parameter CMD_DEPTH = `WM_ENGINE_CMD_DEPTH,
    // halfword address bits of the read port (the SDRAM's); COORD_BITS + 2 .. 32
    parameter ADDR_BITS = 24,
    // halfword address of HEIGHT's sample 0
    parameter [ADDR_BITS-1:0] HEIGHT_BASE = 0
)
(
    input  wire                   clk,
    input  wire                   rst,

    /*
     * Register bus (the SoC's request cycle; the read data in the next)
     */
    input  wire                   bus_valid,
    input  wire [7:0]             bus_addr,
    input  wire [31:0]            bus_wdata,
    input  wire [3:0]             bus_wstrb,
    output wire [31:0]            bus_rdata,

    /*
     * Read port: a row span's request, its samples
     */
    output wire [ADDR_BITS-1:0]   m_rd_addr,
    output wire [COORD_BITS:0]    m_rd_len,
    output wire                   m_rd_valid,
    input  wire                   m_rd_ready,
    input  wire [15:0]            s_rd_data,
    input  wire                   s_rd_valid,
    output wire                   s_rd_ready,

    output wire                   busy
);

localparam CB = COORD_BITS;
localparam VW = 2 * CB + 18;
localparam [31:0] MAX_SIDE = 32'd1 << CB;

// check configuration
initial begin
    if (COORD_BITS < 2 || COORD_BITS > 15 || VW > 64) begin
        $error("Error: COORD_BITS must be 2..15 (instance %m)");
        $finish;
    end
end

reg [31:0] v0_reg = 32'd0, v1_reg = 32'd0, v2_reg = 32'd0, z01_reg = 32'd0;
reg [15:0] z2_reg = 16'd0;
reg [31:0] limit_lo_reg = 32'hFFFF_FFFF, limit_hi_reg = 32'hFFFF_FFFF;
reg [CB:0] width_reg = {(CB+1){1'b0}};
reg overrun_reg = 1'b0;
reg [31:0] rdata_reg = 32'd0;

assign bus_rdata = rdata_reg;

wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire reg_write = bus_valid && bus_wstrb != 4'd0;
wire push = reg_write && bus_addr == `WM_ENGINE_PUSH;
wire take = reg_read && bus_addr == `WM_ENGINE_RES_AT;

wire cmd_ready;
wire [VW-1:0] res_vmax;
wire [CB-1:0] res_x, res_y;
wire res_valid;
wire [63:0] res_vmax64 = {{(64-VW){1'b0}}, res_vmax};
wire [15:0] res_x16 = {{(16-CB){1'b0}}, res_x};
wire [15:0] res_y16 = {{(16-CB){1'b0}}, res_y};

tri_engine #(
    .COORD_BITS(CB),
    .ADDR_BITS(ADDR_BITS),
    .CMD_DEPTH(CMD_DEPTH)
) engine_inst (
    .clk(clk),
    .rst(rst),
    .cfg_base(HEIGHT_BASE),
    .cfg_width(width_reg),
    .s_cmd_x({v2_reg[CB-1:0], v1_reg[CB-1:0], v0_reg[CB-1:0]}),
    .s_cmd_y({v2_reg[16 +: CB], v1_reg[16 +: CB], v0_reg[16 +: CB]}),
    .s_cmd_z({z2_reg, z01_reg}),
    .s_cmd_limit({limit_hi_reg, limit_lo_reg}),
    .s_cmd_valid(push),         // one cycle: the command FIFO takes it or it is lost (OVERRUN)
    .s_cmd_ready(cmd_ready),
    .m_res_vmax(res_vmax),
    .m_res_x(res_x),
    .m_res_y(res_y),
    .m_res_valid(res_valid),
    .m_res_ready(take),
    .m_rd_addr(m_rd_addr),
    .m_rd_len(m_rd_len),
    .m_rd_valid(m_rd_valid),
    .m_rd_ready(m_rd_ready),
    .s_rd_data(s_rd_data),
    .s_rd_valid(s_rd_valid),
    .s_rd_ready(s_rd_ready),
    .busy(busy)
);

always @(posedge clk) begin
    // reads: registered, answered in the next cycle
    rdata_reg <= 32'd0;
    if (reg_read) begin
        case (bus_addr)
            `WM_ENGINE_V0: rdata_reg <= v0_reg;
            `WM_ENGINE_V1: rdata_reg <= v1_reg;
            `WM_ENGINE_V2: rdata_reg <= v2_reg;
            `WM_ENGINE_Z01: rdata_reg <= z01_reg;
            `WM_ENGINE_Z2: rdata_reg <= {16'd0, z2_reg};
            `WM_ENGINE_LIMIT_LO: rdata_reg <= limit_lo_reg;
            `WM_ENGINE_LIMIT_HI: rdata_reg <= limit_hi_reg;
            `WM_ENGINE_STATUS: rdata_reg <= {23'd0, overrun_reg, 5'd0, busy, !cmd_ready, res_valid};
            `WM_ENGINE_RES_VMAX_LO: rdata_reg <= res_vmax64[31:0];
            `WM_ENGINE_RES_VMAX_HI: rdata_reg <= res_vmax64[63:32];
            `WM_ENGINE_RES_AT: rdata_reg <= {!res_valid, res_y16[14:0], res_x16};
            `WM_ENGINE_WIDTH: rdata_reg <= {{(31-CB){1'b0}}, width_reg};
            `WM_ENGINE_MAX_SIDE: rdata_reg <= MAX_SIDE;
            default: rdata_reg <= 32'd0;
        endcase
    end

    // writes: whole words
    if (reg_write) begin
        case (bus_addr)
            `WM_ENGINE_V0: v0_reg <= bus_wdata;
            `WM_ENGINE_V1: v1_reg <= bus_wdata;
            `WM_ENGINE_V2: v2_reg <= bus_wdata;
            `WM_ENGINE_Z01: z01_reg <= bus_wdata;
            `WM_ENGINE_Z2: z2_reg <= bus_wdata[15:0];
            `WM_ENGINE_LIMIT_LO: limit_lo_reg <= bus_wdata;
            `WM_ENGINE_LIMIT_HI: limit_hi_reg <= bus_wdata;
            `WM_ENGINE_WIDTH: width_reg <= bus_wdata[CB:0];
            `WM_ENGINE_STATUS: if (bus_wdata[`WM_ENGINE_STATUS_OVERRUN]) overrun_reg <= 1'b0;
            default: ;
        endcase
    end
    if (push && !cmd_ready) begin
        // the queue was full: the triangle is lost
        overrun_reg <= 1'b1;
    end

    if (rst) begin
        rdata_reg <= 32'd0;
        overrun_reg <= 1'b0;
    end
end

// bits the engine does not take: the corners' beyond COORD_BITS, the top of RES_AT's row
wire bits_unused = ^{v0_reg[31:16+CB], v0_reg[15:CB], v1_reg[31:16+CB], v1_reg[15:CB], v2_reg[31:16+CB],
                     v2_reg[15:CB], res_y16[15], bus_wdata[31:CB+1]};

endmodule

`resetall
