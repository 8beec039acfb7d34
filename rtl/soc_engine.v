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
 *   0x38 SLOPE_X, 0x3C SLOPE_Y  rw  the slope scales: m in bits 15..0, e in 22..16
 *   0x40 SLOPE_GO               w   the slope unit (tri_slope) takes V0..Z2 and the scales (ignored while busy)
 *   0x44 SLOPE_STATUS           r   bit 0 DONE, 1 BUSY, bits 13..8 the result's k
 *   0x48 SLOPE_ROOT             r   the result's floor(sqrt(X)): the slope factor is SLOPE_ROOT << k
 *   0x4C SQRT_LO, 0x50 SQRT_HI  rw  x of a root command; a SQRT_HI write starts floor(sqrt(x)) (k 0)
 *   0x54 DIV_N_LO, 0x58 DIV_N_HI, 0x5C DIV_D_LO, 0x60 DIV_D_HI  rw  the divider's n and d (unsigned);
 *                               a DIV_D_HI write starts n / d (udiv64; ignored while busy)
 *   0x64 DIV_STATUS             r   bit 0 DONE, 1 BUSY
 *   0x68 DIV_Q_LO, 0x6C DIV_Q_HI, 0x70 DIV_R_LO, 0x74 DIV_R_HI  r  the last division's n / d, n % d
 *   0x78 ANGLE_X, 0x7C ANGLE_Y  rw  x (signed) and y (>= 0) of the angle unit; an ANGLE_Y write starts
 *                               atan2(y, x) (tri_angle; ignored while busy)
 *   0x80 ANGLE                  r   bits 17..0 the last command's angle (Q16 radians), 30 BUSY, 31 DONE
 *   0x84 POINT_P                rw  the point-error unit's sample: x in bits 15..0, y in 31..16
 *   0x88 POINT_R_LO, 0x8C POINT_R_HI  rw  mode 1's slope factor r
 *   0x90 POINT_GO               w   bits 15..0 the sample's height, 17..16 the mode: the point-error unit
 *                               (tri_point) takes V0..Z2 and POINT_P; mode 2 also starts the slope unit as
 *                               SLOPE_GO does and takes its r (ignored while either is busy)
 *   0x94 POINT                  r   the last command's point error e
 *   0x98 POINT_STATUS           r   bit 0 DONE, 1 BUSY
 *
 * The slope unit works beside the scan, from its own copy of the staging registers (taken at
 * SLOPE_GO); its result stays in SLOPE_ROOT and SLOPE_STATUS.K until the next SLOPE_GO.
 *
 * The words with fields are packed and unpacked by wm_memmap.vh's field macros (WM_ENGINE_<REG>_WORD,
 * _SHIFT), the positions the firmware's wm_memmap.h gives too.
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
    parameter [ADDR_BITS-1:0] HEIGHT_BASE = 0,
    // 1: the slope unit (tri_slope) is built; 0: SLOPE_GO is ignored and SLOPE_STATUS reads 0
    parameter SLOPE = 1,
    // 1: the 64-bit divider (udiv64) is built; 0: DIV_D_HI starts nothing and DIV_STATUS reads 0
    parameter DIV = 1,
    // 1: the angle unit (tri_angle) is built; 0: ANGLE_Y starts nothing and ANGLE reads 0
    parameter ANGLE = 1,
    // 1: the point-error unit (tri_point; needs SLOPE) is built; 0: POINT_GO starts nothing, POINT reads 0
    parameter POINT = 1
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
    if (POINT != 0 && (SLOPE == 0 || COORD_BITS > 14)) begin
        $error("Error: POINT needs SLOPE and COORD_BITS <= 14 (instance %m)");
        $finish;
    end
end

reg [31:0] v0_reg = 32'd0, v1_reg = 32'd0, v2_reg = 32'd0, z01_reg = 32'd0;
reg [15:0] z2_reg = 16'd0;
reg [31:0] limit_lo_reg = 32'hFFFF_FFFF, limit_hi_reg = 32'hFFFF_FFFF;
reg [CB:0] width_reg = {(CB+1){1'b0}};
reg overrun_reg = 1'b0;
reg [22:0] slope_x_reg = 23'd0, slope_y_reg = 23'd0;
reg [31:0] sqrt_lo_reg = 32'd0, sqrt_hi_reg = 32'd0;
reg [63:0] div_n_reg = 64'd0, div_q_reg = 64'd0, div_r_reg = 64'd0;
reg [31:0] div_d_lo_reg = 32'd0, div_d_hi_reg = 32'd0;
reg div_done_reg = 1'b0;
reg [31:0] angle_x_reg = 32'd0, angle_y_reg = 32'd0;
reg [17:0] angle_z_reg = 18'd0;
reg angle_done_reg = 1'b0;
reg [31:0] slope_root_reg = 32'd0;
reg [5:0] slope_k_reg = 6'd0;
reg slope_done_reg = 1'b0;
reg [31:0] point_p_reg = 32'd0, point_r_lo_reg = 32'd0, point_r_hi_reg = 32'd0, point_e_reg = 32'd0;
reg point_done_reg = 1'b0;
reg [31:0] rdata_reg = 32'd0;

assign bus_rdata = rdata_reg;

wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire reg_write = bus_valid && bus_wstrb != 4'd0;
wire push = reg_write && bus_addr == `WM_ENGINE_PUSH;
wire take = reg_read && bus_addr == `WM_ENGINE_RES_AT;
wire slope_go = reg_write && bus_addr == `WM_ENGINE_SLOPE_GO;
wire sqrt_go = reg_write && bus_addr == `WM_ENGINE_SQRT_HI;
wire div_go = reg_write && bus_addr == `WM_ENGINE_DIV_D_HI;
wire angle_go = reg_write && bus_addr == `WM_ENGINE_ANGLE_Y;
wire point_go = reg_write && bus_addr == `WM_ENGINE_POINT_GO;
wire [1:0] point_mode = bus_wdata[`WM_ENGINE_POINT_GO_MODE_SHIFT +: 2];
wire point_slope = point_mode == 2'd2;
wire point_ready, slope_ready;
// a point command is taken when its unit is idle, and in mode 2 the slope unit too (which it starts)
wire point_take = point_go && point_ready && (!point_slope || slope_ready);

// the corners' coordinates (V1 and V2 as V0) and heights, for the units that take the staged triangle
localparam VX = `WM_ENGINE_V0_X_SHIFT, VY = `WM_ENGINE_V0_Y_SHIFT;
wire [3*CB-1:0] corners_x = {v2_reg[VX +: CB], v1_reg[VX +: CB], v0_reg[VX +: CB]};
wire [3*CB-1:0] corners_y = {v2_reg[VY +: CB], v1_reg[VY +: CB], v0_reg[VY +: CB]};
wire [47:0] corners_z = {z2_reg, z01_reg[`WM_ENGINE_Z01_Z1_SHIFT +: 16],
                         z01_reg[`WM_ENGINE_Z01_Z0_SHIFT +: 16]};

wire cmd_ready;
wire [VW-1:0] res_vmax;
wire [CB-1:0] res_x, res_y;
wire res_valid;
wire [63:0] res_vmax64 = {{(64-VW){1'b0}}, res_vmax};
wire [15:0] res_x16 = {{(16-CB){1'b0}}, res_x};
wire [15:0] res_y16 = {{(16-CB){1'b0}}, res_y};
wire slope_busy, div_busy, angle_busy, point_busy;

`ifdef WM_SIM_ENGINE_GATE
// The simulator's clock gate of the units (sim/build.py defines WM_SIM_ENGINE_GATE; the bitstream has no
// gate and clocks every unit with clk itself, no other net): an edge reaches tri_engine, tri_slope,
// udiv64, tri_angle and tri_point only while one of them has work (busy: a command queued or in work, a
// result not yet handed out), while a command is written to one of them, or at reset.  An idle unit
// that is offered no command loads nothing that is read before its next command overwrites it
// (docs/soc.md, "The simulated board": why this is exact, and the test that compares the cycles and
// the meshes with the ungated build).  One gate for the five: each gated clock costs the model a
// trigger at every evaluation, and the units are seldom busy.  The enable is latched while the clock is
// low, so that the gated edge comes in the same evaluation as clk's and sees the values from before
// it, as every other register does (sim_clock_gate; soc_accel's stage gate likewise).
wire engine_clk_en = busy || push || slope_busy || slope_go || sqrt_go || div_busy || div_go || angle_busy
    || angle_go || point_busy || point_go || rst;
wire engine_clk;
sim_clock_gate engine_gate_inst (.clk(clk), .en(engine_clk_en), .gclk(engine_clk));
`endif

tri_engine #(
    .COORD_BITS(CB),
    .ADDR_BITS(ADDR_BITS),
    .CMD_DEPTH(CMD_DEPTH)
) engine_inst (
`ifdef WM_SIM_ENGINE_GATE
    .clk(engine_clk),
`else
    .clk(clk),
`endif
    .rst(rst),
    .cfg_base(HEIGHT_BASE),
    .cfg_width(width_reg),
    .s_cmd_x(corners_x),
    .s_cmd_y(corners_y),
    .s_cmd_z(corners_z),
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

/*
 * The slope unit: the staging registers and the scales at SLOPE_GO; its result into SLOPE_ROOT, K
 */
wire slope_res_valid;
wire [31:0] slope_res_root;
wire [5:0] slope_res_k;

generate
    if (SLOPE != 0) begin : g_slope
        tri_slope #(
            .COORD_BITS(CB)
        ) slope_inst (
`ifdef WM_SIM_ENGINE_GATE
            .clk(engine_clk),
`else
            .clk(clk),
`endif
            .rst(rst),
            .s_cmd_x(corners_x),
            .s_cmd_y(corners_y),
            .s_cmd_z(corners_z),
            .s_cmd_sx(slope_x_reg),
            .s_cmd_sy(slope_y_reg),
            .s_cmd_valid(slope_go || (point_take && point_slope)),
            .s_cmd_ready(slope_ready),
            .s_root_x({bus_wdata, sqrt_lo_reg}),
            .s_root_valid(sqrt_go),
            .m_res_root(slope_res_root),
            .m_res_k(slope_res_k),
            .m_res_valid(slope_res_valid),
            .m_res_ready(1'b1),
            .busy(slope_busy)
        );
    end else begin : g_no_slope
        assign slope_ready = 1'b0;
        assign slope_res_valid = 1'b0;
        assign slope_busy = 1'b0;
        assign slope_res_root = 32'd0;
        assign slope_res_k = 6'd0;
    end
endgenerate

/*
 * The divider: n and d at the DIV_D_HI write; its quotient and remainder into DIV_Q, DIV_R
 */
wire div_ready, div_res_valid;
wire [63:0] div_res_q, div_res_r;

generate
    if (DIV != 0) begin : g_div
        udiv64 div_inst (
`ifdef WM_SIM_ENGINE_GATE
            .clk(engine_clk),
`else
            .clk(clk),
`endif
            .rst(rst),
            .s_n(div_n_reg),
            .s_d({bus_wdata, div_d_lo_reg}),
            .s_valid(div_go),
            .s_ready(div_ready),
            .m_q(div_res_q),
            .m_r(div_res_r),
            .m_valid(div_res_valid),
            .m_ready(1'b1),
            .busy(div_busy)
        );
    end else begin : g_no_div
        assign div_ready = 1'b0;
        assign div_res_valid = 1'b0;
        assign div_busy = 1'b0;
        assign div_res_q = 64'd0;
        assign div_res_r = 64'd0;
    end
endgenerate

always @(posedge clk) begin
    if (div_go && div_ready) begin
        div_done_reg <= 1'b0;
    end
    if (div_res_valid) begin
        div_q_reg <= div_res_q;
        div_r_reg <= div_res_r;
        div_done_reg <= 1'b1;
    end
    if (rst) begin
        div_done_reg <= 1'b0;
    end
end

/*
 * The angle unit: x and y at the ANGLE_Y write; its result into ANGLE.Z
 */
wire angle_ready, angle_res_valid;
wire [17:0] angle_res_z;

generate
    if (ANGLE != 0) begin : g_angle
        tri_angle angle_inst (
`ifdef WM_SIM_ENGINE_GATE
            .clk(engine_clk),
`else
            .clk(clk),
`endif
            .rst(rst),
            .s_cmd_x(angle_x_reg),
            .s_cmd_y(bus_wdata[30:0]),
            .s_cmd_valid(angle_go),
            .s_cmd_ready(angle_ready),
            .m_res_angle(angle_res_z),
            .m_res_valid(angle_res_valid),
            .m_res_ready(1'b1),
            .busy(angle_busy)
        );
    end else begin : g_no_angle
        assign angle_ready = 1'b0;
        assign angle_res_valid = 1'b0;
        assign angle_busy = 1'b0;
        assign angle_res_z = 18'd0;
    end
endgenerate

always @(posedge clk) begin
    if (angle_go && angle_ready) begin
        angle_done_reg <= 1'b0;
    end
    if (angle_res_valid) begin
        angle_z_reg <= angle_res_z;
        angle_done_reg <= 1'b1;
    end
    if (rst) begin
        angle_done_reg <= 1'b0;
    end
end

/*
 * The point-error unit: the staging registers, POINT_P and the height and mode at the POINT_GO write; mode
 * 2's r is the slope unit's result once SLOPE_STATUS.DONE (cleared as the command is taken); e into POINT
 */
wire point_res_valid;
wire [31:0] point_res_e;

generate
    if (POINT != 0) begin : g_point
        tri_point #(
            .COORD_BITS(CB)
        ) point_inst (
`ifdef WM_SIM_ENGINE_GATE
            .clk(engine_clk),
`else
            .clk(clk),
`endif
            .rst(rst),
            .s_cmd_x(corners_x),
            .s_cmd_y(corners_y),
            .s_cmd_z(corners_z),
            .s_cmd_px(point_p_reg[`WM_ENGINE_POINT_P_X_SHIFT +: CB]),
            .s_cmd_py(point_p_reg[`WM_ENGINE_POINT_P_Y_SHIFT +: CB]),
            .s_cmd_h(bus_wdata[`WM_ENGINE_POINT_GO_H_SHIFT +: 16]),
            .s_cmd_r({point_r_hi_reg, point_r_lo_reg}),
            .s_cmd_mode(point_mode),
            .s_cmd_valid(point_take),
            .s_cmd_ready(point_ready),
            .s_r({32'd0, slope_root_reg} << slope_k_reg),
            .s_r_valid(slope_done_reg),
            .m_res_e(point_res_e),
            .m_res_valid(point_res_valid),
            .m_res_ready(1'b1),
            .busy(point_busy)
        );
    end else begin : g_no_point
        assign point_ready = 1'b0;
        assign point_res_valid = 1'b0;
        assign point_busy = 1'b0;
        assign point_res_e = 32'd0;
    end
endgenerate

always @(posedge clk) begin
    if (point_take) begin
        point_done_reg <= 1'b0;
    end
    if (point_res_valid) begin
        point_e_reg <= point_res_e;
        point_done_reg <= 1'b1;
    end
    if (rst) begin
        point_done_reg <= 1'b0;
    end
end

always @(posedge clk) begin
    if ((slope_go || sqrt_go || (point_take && point_slope)) && slope_ready) begin
        slope_done_reg <= 1'b0;
    end
    if (slope_res_valid) begin
        slope_root_reg <= slope_res_root;
        slope_k_reg <= slope_res_k;
        slope_done_reg <= 1'b1;
    end
    if (rst) begin
        slope_done_reg <= 1'b0;
    end
end

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
            `WM_ENGINE_STATUS: rdata_reg <= `WM_ENGINE_STATUS_WORD(res_valid, !cmd_ready, busy, overrun_reg);
            `WM_ENGINE_RES_VMAX_LO: rdata_reg <= res_vmax64[31:0];
            `WM_ENGINE_RES_VMAX_HI: rdata_reg <= res_vmax64[63:32];
            `WM_ENGINE_RES_AT: rdata_reg <= `WM_ENGINE_RES_AT_WORD(res_x16, res_y16[14:0], !res_valid);
            `WM_ENGINE_WIDTH: rdata_reg <= {{(31-CB){1'b0}}, width_reg};
            `WM_ENGINE_MAX_SIDE: rdata_reg <= MAX_SIDE;
            `WM_ENGINE_SLOPE_X: rdata_reg <= `WM_ENGINE_SLOPE_X_WORD(slope_x_reg[15:0], slope_x_reg[22:16]);
            `WM_ENGINE_SLOPE_Y: rdata_reg <= `WM_ENGINE_SLOPE_X_WORD(slope_y_reg[15:0], slope_y_reg[22:16]);
            `WM_ENGINE_SLOPE_STATUS:
                rdata_reg <= `WM_ENGINE_SLOPE_STATUS_WORD(slope_done_reg, slope_busy, slope_k_reg);
            `WM_ENGINE_SLOPE_ROOT: rdata_reg <= slope_root_reg;
            `WM_ENGINE_SQRT_LO: rdata_reg <= sqrt_lo_reg;
            `WM_ENGINE_SQRT_HI: rdata_reg <= sqrt_hi_reg;
            `WM_ENGINE_DIV_N_LO: rdata_reg <= div_n_reg[31:0];
            `WM_ENGINE_DIV_N_HI: rdata_reg <= div_n_reg[63:32];
            `WM_ENGINE_DIV_D_LO: rdata_reg <= div_d_lo_reg;
            `WM_ENGINE_DIV_D_HI: rdata_reg <= div_d_hi_reg;
            `WM_ENGINE_DIV_STATUS: rdata_reg <= `WM_ENGINE_DIV_STATUS_WORD(div_done_reg, div_busy);
            `WM_ENGINE_DIV_Q_LO: rdata_reg <= div_q_reg[31:0];
            `WM_ENGINE_DIV_Q_HI: rdata_reg <= div_q_reg[63:32];
            `WM_ENGINE_DIV_R_LO: rdata_reg <= div_r_reg[31:0];
            `WM_ENGINE_DIV_R_HI: rdata_reg <= div_r_reg[63:32];
            `WM_ENGINE_ANGLE_X: rdata_reg <= angle_x_reg;
            `WM_ENGINE_ANGLE_Y: rdata_reg <= angle_y_reg;
            `WM_ENGINE_ANGLE: rdata_reg <= `WM_ENGINE_ANGLE_WORD(angle_z_reg, angle_busy, angle_done_reg);
            `WM_ENGINE_POINT_P: rdata_reg <= point_p_reg;
            `WM_ENGINE_POINT_R_LO: rdata_reg <= point_r_lo_reg;
            `WM_ENGINE_POINT_R_HI: rdata_reg <= point_r_hi_reg;
            `WM_ENGINE_POINT: rdata_reg <= point_e_reg;
            `WM_ENGINE_POINT_STATUS: rdata_reg <= `WM_ENGINE_POINT_STATUS_WORD(point_done_reg, point_busy);
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
            `WM_ENGINE_SLOPE_X: slope_x_reg <= bus_wdata[22:0];
            `WM_ENGINE_SLOPE_Y: slope_y_reg <= bus_wdata[22:0];
            `WM_ENGINE_SQRT_LO: sqrt_lo_reg <= bus_wdata;
            `WM_ENGINE_SQRT_HI: sqrt_hi_reg <= bus_wdata;
            `WM_ENGINE_DIV_N_LO: div_n_reg[31:0] <= bus_wdata;
            `WM_ENGINE_DIV_N_HI: div_n_reg[63:32] <= bus_wdata;
            `WM_ENGINE_DIV_D_LO: div_d_lo_reg <= bus_wdata;
            `WM_ENGINE_DIV_D_HI: div_d_hi_reg <= bus_wdata;
            `WM_ENGINE_ANGLE_X: angle_x_reg <= bus_wdata;
            `WM_ENGINE_ANGLE_Y: angle_y_reg <= bus_wdata;
            `WM_ENGINE_POINT_P: point_p_reg <= bus_wdata;
            `WM_ENGINE_POINT_R_LO: point_r_lo_reg <= bus_wdata;
            `WM_ENGINE_POINT_R_HI: point_r_hi_reg <= bus_wdata;
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
                     v2_reg[15:CB], res_y16[15], bus_wdata[31:CB+1], point_p_reg[31:16+CB],
                     point_p_reg[15:CB]};

endmodule

`resetall
