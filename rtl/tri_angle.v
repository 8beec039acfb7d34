/*
 * wavemesh: the angle unit, atan2(y, x) in Q16 radians by CORDIC in hardware
 *
 * The regularisation measures a triangle's smallest angle as the atan2 of the dot and cross products
 * at its corner (firmware/src/fixed.c's wm_min_corner and wm_angle_q16).  For x (signed) and y >= 0,
 * both of 32 bits, this unit computes exactly what wm_angle_q16 does (wavemesh.model.angle the Python
 * model):
 *
 *     1. while |x| > 2^28 or y > 2^28: x, y halved toward zero (magnitudes shifted right)
 *     2. x < 0: (x, y) = (y, -x) and z = pi/2 (102,944); else z = 0
 *     3. x, y below 2^27 and not both 0: both shifted left by 28 - bit length of (x | y)
 *     4. 17 rotations i = 0..16 while y != 0: y > 0: x += y >> i, y -= x >> i, z += atan 2^-i;
 *        y < 0: x -= y >> i, y += x >> i, z -= atan 2^-i (y >> i toward zero)
 *     5. the result max(z, 0), 0 .. pi in Q16 (18 bits)
 *
 * In step 4 x never falls (it gains |y| >> i either way) and stays below 2^30, so x is unsigned and
 * both updates take |y| >> i and x >> i: two shifters and three adders, one rotation a clock.
 *
 *   command -> halvings (a clock each, at most 3) -> the quadrant and the doubling -> rotations -> result
 *
 * Timing: 1 clock to take the command, 1 + h of halvings (h = 0 for |x|, y <= 2^28; at most 3), 1
 * of doubling, one a rotation while y != 0 (17 at most; y reaches 0 early only on an axis), 1 to
 * hand out the result: 21 clocks for most commands.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tri_angle
(
    input  wire         clk,
    input  wire         rst,

    /*
     * Command: x (signed) and y (>= 0)
     */
    input  wire [31:0]  s_cmd_x,
    input  wire [30:0]  s_cmd_y,
    input  wire         s_cmd_valid,
    output wire         s_cmd_ready,

    /*
     * Result: the angle in Q16 radians, 0 .. 205,888
     */
    output wire [17:0]  m_res_angle,
    output wire         m_res_valid,
    input  wire         m_res_ready,

    output wire         busy
);

localparam [2:0]
    ST_IDLE = 3'd0,
    ST_DOWN = 3'd1,
    ST_UP = 3'd2,
    ST_ROT = 3'd3,
    ST_DONE = 3'd4;

reg [2:0] state_reg = ST_IDLE;

// the magnitudes while halving, x's sign
reg [31:0] mx_reg = 32'd0, my_reg = 32'd0;
reg neg_reg = 1'b0;
// the rotations' x (>= 0), y (signed), z (signed: -114,248 .. 217,192) and step
reg [31:0] ux_reg = 32'd0;
reg signed [31:0] iy_reg = 0;
reg signed [18:0] z_reg = 0;
reg [4:0] i_reg = 5'd0;

assign s_cmd_ready = state_reg == ST_IDLE;
// the result: max(z, 0) (z held in ST_DONE)
assign m_res_angle = z_reg[18] ? 18'd0 : z_reg[17:0];
assign m_res_valid = state_reg == ST_DONE;
assign busy = state_reg != ST_IDLE;

// atan(2^-i) in Q16 radians (wm_atan_q16(i), i = 0..16), the last i (WM_ANGLE_LAST = 16) and pi / 2
// (WM_HALF_PI_Q16): the generated wm_angle.vh (host/wavemesh/model/angle.py, their one source and fixed.c's)
`include "wm_angle.vh"

/*
 * The halvings (ST_DOWN): one while either magnitude is above 2^28; then the quadrant
 */
wire big = mx_reg > 32'h1000_0000 || my_reg > 32'h1000_0000;
wire rot90 = neg_reg && mx_reg != 32'd0;
// after the quadrant: x, y in [0, 2^28]
wire [28:0] qx = rot90 ? my_reg[28:0] : mx_reg[28:0];
wire [28:0] qy = rot90 ? mx_reg[28:0] : my_reg[28:0];

/*
 * The doubling (ST_UP): x, y (in ux_reg, iy_reg) below 2^27 and not both 0 shifted left by 28 - bit
 * length of (x | y)
 */
wire [28:0] qxy = ux_reg[28:0] | iy_reg[28:0];
reg [4:0] qlen;
integer j;

always @* begin
    qlen = 5'd0;
    for (j = 0; j < 29; j = j + 1) begin
        if (qxy[j]) qlen = j[4:0] + 5'd1;
    end
end

wire up = qxy != 29'd0 && qxy[28:27] == 2'd0;
wire [4:0] up_sh = 5'd28 - qlen;

/*
 * A rotation (ST_ROT): |y| >> i and x >> i
 */
wire [31:0] ay = iy_reg[31] ? -iy_reg : iy_reg;
wire [31:0] ys = ay >> i_reg;
wire [31:0] xs = ux_reg >> i_reg;

always @(posedge clk) begin
    case (state_reg)
        ST_IDLE: begin
            if (s_cmd_valid) begin
                mx_reg <= s_cmd_x[31] ? -s_cmd_x : s_cmd_x;
                my_reg <= {1'b0, s_cmd_y};
                neg_reg <= s_cmd_x[31];
                state_reg <= ST_DOWN;
            end
        end
        ST_DOWN: begin
            if (big) begin
                mx_reg <= mx_reg >> 1;
                my_reg <= my_reg >> 1;
            end else begin
                ux_reg <= {3'd0, qx};
                iy_reg <= $signed({3'd0, qy});
                z_reg <= rot90 ? WM_HALF_PI_Q16 : 19'sd0;
                state_reg <= ST_UP;
            end
        end
        ST_UP: begin
            if (up) begin
                ux_reg <= ux_reg << up_sh;
                iy_reg <= iy_reg << up_sh;
            end
            i_reg <= 5'd0;
            state_reg <= ST_ROT;
        end
        ST_ROT: begin
            if (iy_reg != 0) begin
                ux_reg <= ux_reg + ys;
                if (iy_reg[31]) begin
                    iy_reg <= iy_reg + $signed(xs);
                    z_reg <= z_reg - wm_atan_q16(i_reg);
                end else begin
                    iy_reg <= iy_reg - $signed(xs);
                    z_reg <= z_reg + wm_atan_q16(i_reg);
                end
            end
            i_reg <= i_reg + 5'd1;
            if (iy_reg == 0 || i_reg == WM_ANGLE_LAST) state_reg <= ST_DONE;
        end
        ST_DONE: begin
            if (m_res_ready) state_reg <= ST_IDLE;
        end
        default: state_reg <= ST_IDLE;
    endcase

    if (rst) begin
        state_reg <= ST_IDLE;
    end
end


endmodule

`resetall
