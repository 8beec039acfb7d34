/*
 * wavemesh: the slope unit, the normal metric's slope factor of a triangle in hardware
 *
 * For one triangle (three grid vertices p_k, the corner heights z_k) and the slope scales s_x = m_x /
 * 2^e_x, s_y = m_y / 2^e_y (height units per ground unit along x and y) it computes, exactly as
 * firmware/src/tri_error.c's slope_square and wm_isqrt64 (wavemesh.model.tri_slope the Python model):
 *
 *     D  = (x1 - x0)(y2 - y0) - (x2 - x0)(y1 - y0)            twice the area (> 0: counter-clockwise)
 *     Na = (z1 - z0)(y2 - y0) - (z2 - z0)(y1 - y0)           the plane's gradient numerators
 *     Nb = (x1 - x0)(z2 - z0) - (x2 - x0)(z1 - z0)
 *     ga = min(floor(2^16 |Na| m_x / 2^e_x / D), 2^62)       Q16.16 slope along x, rounded down; gb alike
 *     k  = the smallest shift with ga >> k and gb >> k below 2^31
 *     X  = floor(2^32 / 4^k) + (ga >> k)^2 + (gb >> k)^2      (the first term 0 when 2 k >= 33)
 *     root = floor(sqrt(X))
 *
 * and returns root and k: the slope factor r = sqrt(1 + g^2) in Q16.16 is root << k.  For D <= 0
 * (not a counter-clockwise triangle; the firmware never asks) it returns root 0, k 0.  A root command
 * takes floor(sqrt(x)) of a 64-bit x alone (fixed.c's wm_isqrt64), k 0.
 *
 *   command -> differences -> products (D, Na, Nb) -> two dividers (ga, gb) -> k -> squares -> root
 *
 * The divisions: floor(2^16 |Na| m / 2^e / D) = floor((N >> e) / D) with N = 2^16 |Na| m, so each
 * divider is a restoring division (udiv_step.v) that takes N's bits from the top and stops e bits
 * early (no shifter for e: a larger e is a shorter division), DIV_STEPS quotient bits a clock.  The
 * root: the bit-by-bit restoring square root, two bits of X (one root bit) a step, SQRT_STEPS steps a
 * clock.
 *
 * Timing: 1 clock to take the command, 2 of products, ceil((NW - e) / DIV_STEPS) of division (the
 * longer of the two axes; NW = COORD_BITS + 49 rounded up to DIV_STEPS), 2 of k, 3 of squares, 32 /
 * SQRT_STEPS of root, 1 to hand out the result: 48 clocks for the SoC's 11-bit coordinates and a
 * scale of e = 15.  No path holds more than one multiplier (the SoC's clock with room).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tri_slope #
(
    // grid coordinate bits (the corners, unsigned): 2..15
    parameter COORD_BITS = 11,
    // quotient bits per clock of each divider: 1 or 2
    parameter DIV_STEPS = 2,
    // root bits per clock: 1 or 2
    parameter SQRT_STEPS = 2
)
(
    input  wire                       clk,
    input  wire                       rst,

    /*
     * Command: the corners (x0 in bits CB-1..0, ...), the corner heights (z0 in 15..0, ...), the
     * scales (m in 15..0, e in 22..16 of each)
     */
    input  wire [3*COORD_BITS-1:0]    s_cmd_x,
    input  wire [3*COORD_BITS-1:0]    s_cmd_y,
    input  wire [47:0]                s_cmd_z,
    input  wire [22:0]                s_cmd_sx,
    input  wire [22:0]                s_cmd_sy,
    input  wire                       s_cmd_valid,
    output wire                       s_cmd_ready,

    /*
     * Root command: floor(sqrt(x)) of any 64-bit x alone (the result's k 0); taken when no triangle
     * command is offered in the same clock, with the same ready
     */
    input  wire [63:0]                s_root_x,
    input  wire                       s_root_valid,

    /*
     * Result: floor(sqrt(X)) and the shift k
     */
    output wire [31:0]                m_res_root,
    output wire [5:0]                 m_res_k,
    output wire                       m_res_valid,
    input  wire                       m_res_ready,

    output wire                       busy
);

localparam CB = COORD_BITS;
// |Na|, |Nb| < 2^(CB+17); N = 2^16 |Na| m < 2^(CB+49), padded to a multiple of DIV_STEPS
localparam NAW = CB + 17;
localparam NW0 = CB + 49;
localparam NW = ((NW0 + DIV_STEPS - 1) / DIV_STEPS) * DIV_STEPS;
// D < 2^(2 CB + 1)
localparam DW = 2 * CB + 1;
// the root's step count at its last clock
localparam integer RLAST_I = 32 - SQRT_STEPS;
localparam [4:0] RLAST = RLAST_I[4:0];
localparam [4:0] RSTEP = SQRT_STEPS[4:0];
localparam [7:0] DSTEP = DIV_STEPS[7:0];
localparam [7:0] NW8 = NW[7:0];

// check configuration
initial begin
    if (COORD_BITS < 2 || COORD_BITS > 15) begin
        $error("Error: COORD_BITS must be 2..15 (instance %m)");
        $finish;
    end
    if (DIV_STEPS < 1 || DIV_STEPS > 2 || SQRT_STEPS < 1 || SQRT_STEPS > 2) begin
        $error("Error: DIV_STEPS and SQRT_STEPS must be 1 or 2 (instance %m)");
        $finish;
    end
end

localparam [3:0]
    ST_IDLE = 4'd0,
    ST_PRODA = 4'd1,
    ST_PRODB = 4'd2,
    ST_DIV = 4'd3,
    ST_NORMA = 4'd4,
    ST_NORMB = 4'd5,
    ST_SQA = 4'd6,
    ST_SQB = 4'd7,
    ST_SQC = 4'd8,
    ST_ROOT = 4'd9,
    ST_DONE = 4'd10;

reg [3:0] state_reg = ST_IDLE;

// the command's differences (signed)
reg signed [CB:0] dx1_reg = 0, dy1_reg = 0, dx2_reg = 0, dy2_reg = 0;
reg signed [16:0] dz1_reg = 0, dz2_reg = 0;
reg [15:0] mx_reg = 16'd0, my_reg = 16'd0;
reg [6:0] ex_reg = 7'd0, ey_reg = 7'd0;

// D and the dividers: numerator bits still to take in the top of num_*, the quotient, the remainder
reg [DW-1:0] d_reg = {DW{1'b0}};
reg bad_reg = 1'b0;
reg [NW-1:0] num_a_reg = {NW{1'b0}}, num_b_reg = {NW{1'b0}};
reg [63:0] quo_a_reg = 64'd0, quo_b_reg = 64'd0;
reg [DW-1:0] rem_a_reg = {DW{1'b0}}, rem_b_reg = {DW{1'b0}};
reg [7:0] left_a_reg = 8'd0, left_b_reg = 8'd0;

// k, the shifted slopes, X, the root
reg [5:0] k_reg = 6'd0;
reg [30:0] a_reg = 31'd0, b_reg = 31'd0;
reg [63:0] x_reg = 64'd0;
reg [33:0] rrem_reg = 34'd0;
reg [31:0] root_reg = 32'd0;
reg [4:0] rcount_reg = 5'd0;

assign s_cmd_ready = state_reg == ST_IDLE;
assign m_res_root = root_reg;
assign m_res_k = k_reg;
assign m_res_valid = state_reg == ST_DONE;
assign busy = state_reg != ST_IDLE;

/*
 * The products: D, Na, Nb from the differences' registers (ST_PRODA), then |Na| m, |Nb| m from theirs
 * (ST_PRODB): two clocks, so that no path holds two multipliers
 */
wire signed [2*CB+2:0] d_full = dx1_reg * dy2_reg - dx2_reg * dy1_reg;
wire signed [CB+18:0] na_full = dz1_reg * dy2_reg - dz2_reg * dy1_reg;
wire signed [CB+18:0] nb_full = dx1_reg * dz2_reg - dx2_reg * dz1_reg;
reg signed [CB+18:0] na_reg = 0, nb_reg = 0;
wire [CB+18:0] na_mag = na_reg[CB+18] ? -na_reg : na_reg;
wire [CB+18:0] nb_mag = nb_reg[CB+18] ? -nb_reg : nb_reg;
wire [NW-17:0] p_a = na_mag[NAW-1:0] * mx_reg;
wire [NW-17:0] p_b = nb_mag[NAW-1:0] * my_reg;
wire [NW-1:0] n_a = {p_a, 16'd0};
wire [NW-1:0] n_b = {p_b, 16'd0};

// the steps of a division: NW - e (none when e >= NW), rounded up to DIV_STEPS with a leading zero
function [7:0] div_steps;
    input [6:0] e;
    begin
        if ({1'b0, e} >= NW8) begin
            div_steps = 8'd0;
        end else begin
            div_steps = NW8 - {1'b0, e};
            if (DIV_STEPS == 2 && div_steps[0]) div_steps = div_steps + 8'd1;
        end
    end
endfunction

function [NW-1:0] div_load;
    input [NW-1:0] n;
    input e0;
    begin
        // an odd count of steps takes one leading zero more: N >> 1 in the same bits
        div_load = (DIV_STEPS == 2 && NW8[0] != e0) ? n >> 1 : n;
    end
endfunction

/*
 * One clock of each divider: DIV_STEPS restoring steps
 */
wire [NW-1:0] dn_a, dn_b;
wire [63:0] dq_a, dq_b;
wire [DW-1:0] dr_a, dr_b;

udiv_step #(
    .NW(NW),
    .RW(DW),
    .QW(64),
    .STEPS(DIV_STEPS)
)
step_a_inst (
    .n(num_a_reg),
    .q(quo_a_reg),
    .r(rem_a_reg),
    .d(d_reg),
    .n_next(dn_a),
    .q_next(dq_a),
    .r_next(dr_a)
);

udiv_step #(
    .NW(NW),
    .RW(DW),
    .QW(64),
    .STEPS(DIV_STEPS)
)
step_b_inst (
    .n(num_b_reg),
    .q(quo_b_reg),
    .r(rem_b_reg),
    .d(d_reg),
    .n_next(dn_b),
    .q_next(dq_b),
    .r_next(dr_b)
);

/*
 * k (ST_NORMA) and the shifted slopes (ST_NORMB): ga, gb capped at 2^62, k = max(0, bit length of
 * ga | gb - 31)
 */
wire [63:0] qa64 = quo_a_reg;
wire [63:0] qb64 = quo_b_reg;
wire [62:0] ga = qa64[63:62] != 2'd0 ? 63'h4000_0000_0000_0000 : qa64[62:0];
wire [62:0] gb = qb64[63:62] != 2'd0 ? 63'h4000_0000_0000_0000 : qb64[62:0];
wire [62:0] gab = ga | gb;
reg [5:0] glen;
integer j;

always @* begin
    glen = 6'd0;
    for (j = 0; j < 63; j = j + 1) begin
        if (gab[j]) glen = j[5:0] + 6'd1;
    end
end

wire [5:0] k_new = glen > 6'd31 ? glen - 6'd31 : 6'd0;
wire [62:0] ga_sh = ga >> k_reg;
wire [62:0] gb_sh = gb >> k_reg;

/*
 * The squares (ST_SQA, ST_SQB into sq_reg: one multiplier; summed in ST_SQB, ST_SQC) and the root's
 * steps (ST_ROOT)
 */
wire [30:0] sq_in = state_reg == ST_SQA ? a_reg : b_reg;
wire [61:0] sq = sq_in * sq_in;
reg [61:0] sq_reg = 62'd0;
wire [32:0] one = k_reg > 6'd16 ? 33'd0 : 33'h1_0000_0000 >> {k_reg, 1'b0};

reg [63:0] rx;
reg [33:0] rr, rt;
reg [31:0] rq;
integer s;

always @* begin
    rx = x_reg;
    rr = rrem_reg;
    rq = root_reg;
    for (s = 0; s < SQRT_STEPS; s = s + 1) begin
        rt = {rr[31:0], rx[63:62]};
        rx = rx << 2;
        if (rt >= {rq, 2'b01}) begin
            rr = rt - {rq, 2'b01};
            rq = {rq[30:0], 1'b1};
        end else begin
            rr = rt;
            rq = {rq[30:0], 1'b0};
        end
    end
end

always @(posedge clk) begin
    case (state_reg)
        ST_IDLE: begin
            if (s_cmd_valid) begin
                dx1_reg <= $signed({1'b0, s_cmd_x[CB +: CB]}) - $signed({1'b0, s_cmd_x[0 +: CB]});
                dy1_reg <= $signed({1'b0, s_cmd_y[CB +: CB]}) - $signed({1'b0, s_cmd_y[0 +: CB]});
                dx2_reg <= $signed({1'b0, s_cmd_x[2*CB +: CB]}) - $signed({1'b0, s_cmd_x[0 +: CB]});
                dy2_reg <= $signed({1'b0, s_cmd_y[2*CB +: CB]}) - $signed({1'b0, s_cmd_y[0 +: CB]});
                dz1_reg <= $signed({1'b0, s_cmd_z[16 +: 16]}) - $signed({1'b0, s_cmd_z[0 +: 16]});
                dz2_reg <= $signed({1'b0, s_cmd_z[32 +: 16]}) - $signed({1'b0, s_cmd_z[0 +: 16]});
                mx_reg <= s_cmd_sx[15:0];
                ex_reg <= s_cmd_sx[22:16];
                my_reg <= s_cmd_sy[15:0];
                ey_reg <= s_cmd_sy[22:16];
                state_reg <= ST_PRODA;
            end else if (s_root_valid) begin
                x_reg <= s_root_x;
                k_reg <= 6'd0;
                bad_reg <= 1'b0;
                rrem_reg <= 34'd0;
                root_reg <= 32'd0;
                rcount_reg <= 5'd0;
                state_reg <= ST_ROOT;
            end
        end
        ST_PRODA: begin
            bad_reg <= d_full[2*CB+2] || d_full == 0;
            d_reg <= d_full[DW-1:0];
            na_reg <= na_full;
            nb_reg <= nb_full;
            state_reg <= ST_PRODB;
        end
        ST_PRODB: begin
            num_a_reg <= div_load(n_a, ex_reg[0]);
            num_b_reg <= div_load(n_b, ey_reg[0]);
            quo_a_reg <= 64'd0;
            quo_b_reg <= 64'd0;
            rem_a_reg <= {DW{1'b0}};
            rem_b_reg <= {DW{1'b0}};
            left_a_reg <= div_steps(ex_reg);
            left_b_reg <= div_steps(ey_reg);
            state_reg <= ST_DIV;
        end
        ST_DIV: begin
            if (left_a_reg != 8'd0) begin
                num_a_reg <= dn_a;
                quo_a_reg <= dq_a;
                rem_a_reg <= dr_a;
                left_a_reg <= left_a_reg - DSTEP;
            end
            if (left_b_reg != 8'd0) begin
                num_b_reg <= dn_b;
                quo_b_reg <= dq_b;
                rem_b_reg <= dr_b;
                left_b_reg <= left_b_reg - DSTEP;
            end
            if (left_a_reg <= DSTEP && left_b_reg <= DSTEP) state_reg <= ST_NORMA;
        end
        ST_NORMA: begin
            k_reg <= k_new;
            state_reg <= ST_NORMB;
        end
        ST_NORMB: begin
            a_reg <= ga_sh[30:0];
            b_reg <= gb_sh[30:0];
            state_reg <= ST_SQA;
        end
        ST_SQA: begin
            sq_reg <= sq;
            state_reg <= ST_SQB;
        end
        ST_SQB: begin
            sq_reg <= sq;
            x_reg <= {31'd0, one} + {2'd0, sq_reg};
            state_reg <= ST_SQC;
        end
        ST_SQC: begin
            x_reg <= x_reg + {2'd0, sq_reg};
            rrem_reg <= 34'd0;
            root_reg <= 32'd0;
            rcount_reg <= 5'd0;
            state_reg <= ST_ROOT;
        end
        ST_ROOT: begin
            x_reg <= rx;
            rrem_reg <= rr;
            root_reg <= rq;
            rcount_reg <= rcount_reg + RSTEP;
            if (rcount_reg == RLAST) begin
                state_reg <= ST_DONE;
                if (bad_reg) begin
                    root_reg <= 32'd0;
                    k_reg <= 6'd0;
                end
            end
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

// bits never used: the products' tops (below their bounds), the shifted slopes' tops (below 2^31)
wire unused = ^{d_full[2*CB+2:DW], ga_sh[62:31], gb_sh[62:31],
                na_mag[CB+18:NAW], nb_mag[CB+18:NAW]};

endmodule

`resetall
