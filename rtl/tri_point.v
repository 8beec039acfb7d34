/*
 * wavemesh: the point-error unit, one sample's distance to a triangle's plane in hardware
 *
 * The refiner's point error (firmware/src/tri_error.c's wm_point_error: the regularisation's lower
 * bounds, the decimation's and the reduction's point tests) of the sample p = (px, py), height h,
 * against the counter-clockwise triangle (x_k, y_k) with corner heights z_k, exactly as the C and
 * wavemesh.model.tri_point compute it:
 *
 *     D   = orient(p0, p1, p2),   E_k = orient(p_k+1, p_k+2, p)         (k + 1, k + 2 modulo 3)
 *     V   = |E_0 z_0 + E_1 z_1 + E_2 z_2 - D h|
 *     ev  = min(ceil(2^16 V / D), 2^32 - 1)                              the vertical error, Q16.16
 *     e   = ev when the mode is 0 or ev = 0, else ceil(2^16 ev / r)       the normal one (r >= 2^16)
 *
 * (all ones when D <= 0).  The slope factor r comes with the command (mode 1) or, mode 2, from the
 * slope unit that the same command starts (soc_engine: s_r and s_r_valid, its result register): the
 * unit waits for it, also when ev = 0, so that the slope unit is idle when the result is out.
 *
 *   command -> edge functions -> products -> V -> ev's division -> [r] -> e's division -> result
 *
 * Both divisions are restoring (udiv_step.v, DIV_STEPS quotient bits a clock) with 32 quotient bits:
 * ev's numerator 2^16 V + D - 1 is below 2^64 (V < 2^(2 COORD_BITS + 19)); its bits above 32 start the
 * remainder, and when they reach D the quotient is 2^32 or more (saturated, no division); e's is
 * 2^16 ev + r - 1 whose quotient is at most ev (r >= 2^16).
 *
 * Timing: 1 clock to take the command, 4 to V and the first division's set-up, 32 / DIV_STEPS of
 * division, then for e 1 to take r, 1 of set-up and 32 / DIV_STEPS more, 1 to hand out the result: 22
 * clocks for ev at DIV_STEPS = 2, 40 for e (in mode 2 at least until r is there); when ev saturates 6
 * for ev, 24 for e (its division alone).
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tri_point #
(
    // grid coordinate bits: x, y < 2^COORD_BITS; 2..14 (2^16 V + D - 1 < 2^64, as the C's arithmetic)
    parameter COORD_BITS = 11,
    // quotient bits a clock: 1 or 2
    parameter DIV_STEPS = 2
)
(
    input  wire                      clk,
    input  wire                      rst,

    /*
     * Command: the corners (corner k in bits k CB ..), their heights, the sample, its height, r, the mode
     */
    input  wire [3*COORD_BITS-1:0]   s_cmd_x,
    input  wire [3*COORD_BITS-1:0]   s_cmd_y,
    input  wire [47:0]               s_cmd_z,
    input  wire [COORD_BITS-1:0]     s_cmd_px,
    input  wire [COORD_BITS-1:0]     s_cmd_py,
    input  wire [15:0]               s_cmd_h,
    input  wire [63:0]               s_cmd_r,
    input  wire [1:0]                s_cmd_mode,    // 0 ev, 1 e with s_cmd_r, 2 e with s_r (3: as 0)
    input  wire                      s_cmd_valid,
    output wire                      s_cmd_ready,

    /*
     * Mode 2's slope factor: taken once s_r_valid is high (held until the result is out)
     */
    input  wire [63:0]               s_r,
    input  wire                      s_r_valid,

    /*
     * Result: e
     */
    output wire [31:0]               m_res_e,
    output wire                      m_res_valid,
    input  wire                      m_res_ready,

    output wire                      busy
);

localparam CB = COORD_BITS;
localparam EW = 2 * CB + 2;    // E_k, D: signed, |.| < 2^(2 CB + 1)
localparam PW = EW + 17;       // E_k z_k, D h: signed
localparam VW = PW + 1;        // the sum: signed, |V| < 2^(2 CB + 19)
localparam [7:0] DIV_CLOCKS = 8'd32 / DIV_STEPS[7:0];

// check configuration
initial begin
    if (COORD_BITS < 2 || COORD_BITS > 14) begin
        $error("Error: COORD_BITS must be 2..14 (instance %m)");
        $finish;
    end
    if (DIV_STEPS < 1 || DIV_STEPS > 2) begin
        $error("Error: DIV_STEPS must be 1 or 2 (instance %m)");
        $finish;
    end
end

localparam [2:0]
    ST_IDLE = 3'd0,
    ST_EDGE = 3'd1,
    ST_PROD = 3'd2,
    ST_SUM = 3'd3,
    ST_SET = 3'd4,
    ST_DIV = 3'd5,
    ST_WAIT = 3'd6,
    ST_DONE = 3'd7;

reg [2:0] state_reg = ST_IDLE;

// the command
reg signed [CB+1:0] x0_reg = 0, x1_reg = 0, x2_reg = 0, y0_reg = 0, y1_reg = 0, y2_reg = 0;
reg signed [CB+1:0] px_reg = 0, py_reg = 0;
reg [15:0] z0_reg = 16'd0, z1_reg = 16'd0, z2_reg = 16'd0, h_reg = 16'd0;
reg [63:0] r_reg = 64'd0;
reg [1:0] mode_reg = 2'd0;
// the edge functions, the products, V
reg signed [EW-1:0] e0_reg = 0, e1_reg = 0, e2_reg = 0, d_reg = 0;
reg signed [PW-1:0] p0_reg = 0, p1_reg = 0, p2_reg = 0, pd_reg = 0;
reg signed [VW-1:0] v_reg = 0;
// the divider: the numerator's bits still to take, the quotient, the remainder, the divisor
reg [31:0] num_reg = 32'd0, quo_reg = 32'd0;
reg [63:0] rem_reg = 64'd0, div_reg = 64'd0;
reg [7:0] count_reg = 8'd0;
reg second_reg = 1'b0;          // the division in work is e's
reg [31:0] ev_reg = 32'd0, e_reg = 32'd0;

assign s_cmd_ready = state_reg == ST_IDLE;
assign m_res_e = e_reg;
assign m_res_valid = state_reg == ST_DONE;
assign busy = state_reg != ST_IDLE;

// orient(a, b, c) = (b - a) x (c - a)
function signed [EW-1:0] orient;
    input signed [CB+1:0] ax, ay, bx, by, cx, cy;
    reg signed [CB+1:0] ux, uy, wx, wy;
    begin
        // each difference below 2^CB in magnitude: CB + 2 signed bits
        ux = bx - ax;
        uy = by - ay;
        wx = cx - ax;
        wy = cy - ay;
        orient = {{(EW-CB-2){ux[CB+1]}}, ux} * {{(EW-CB-2){wy[CB+1]}}, wy}
                 - {{(EW-CB-2){uy[CB+1]}}, uy} * {{(EW-CB-2){wx[CB+1]}}, wx};
    end
endfunction

/*
 * ST_SET: |V| and ev's numerator, or e's; its bits above 32 start the remainder
 */
wire [VW-1:0] av = v_reg[VW-1] ? -v_reg : v_reg;
wire [64:0] n_ev = {{(65-VW){1'b0}}, av} << 16;
wire [64:0] n_e = {17'd0, ev_reg, 16'd0};
wire [64:0] n_add = second_reg ? n_e + {1'b0, r_reg} - 65'd1
                               : n_ev + {{(65-EW){1'b0}}, d_reg} - 65'd1;
wire [63:0] d_set = second_reg ? r_reg : {{(64-EW){1'b0}}, d_reg};
// the quotient needs more than 32 bits (only ev's can)
wire sat = {32'd0, n_add[64:32]} >= {1'b0, d_set};

wire [31:0] dn, dq;
wire [63:0] dr;

udiv_step #(
    .NW(32),
    .RW(64),
    .QW(32),
    .STEPS(DIV_STEPS)
)
step_inst (
    .n(num_reg),
    .q(quo_reg),
    .r(rem_reg),
    .d(div_reg),
    .n_next(dn),
    .q_next(dq),
    .r_next(dr)
);

// after ev: e's division, or the result (in mode 2 once r is there)
wire need_e = mode_reg == 2'd1 || mode_reg == 2'd2;

always @(posedge clk) begin
    case (state_reg)
        ST_IDLE: begin
            if (s_cmd_valid) begin
                x0_reg <= $signed({2'b00, s_cmd_x[0 +: CB]});
                x1_reg <= $signed({2'b00, s_cmd_x[CB +: CB]});
                x2_reg <= $signed({2'b00, s_cmd_x[2*CB +: CB]});
                y0_reg <= $signed({2'b00, s_cmd_y[0 +: CB]});
                y1_reg <= $signed({2'b00, s_cmd_y[CB +: CB]});
                y2_reg <= $signed({2'b00, s_cmd_y[2*CB +: CB]});
                px_reg <= $signed({2'b00, s_cmd_px});
                py_reg <= $signed({2'b00, s_cmd_py});
                z0_reg <= s_cmd_z[15:0];
                z1_reg <= s_cmd_z[31:16];
                z2_reg <= s_cmd_z[47:32];
                h_reg <= s_cmd_h;
                r_reg <= s_cmd_r;
                mode_reg <= s_cmd_mode;
                second_reg <= 1'b0;
                state_reg <= ST_EDGE;
            end
        end
        ST_EDGE: begin
            e0_reg <= orient(x1_reg, y1_reg, x2_reg, y2_reg, px_reg, py_reg);
            e1_reg <= orient(x2_reg, y2_reg, x0_reg, y0_reg, px_reg, py_reg);
            e2_reg <= orient(x0_reg, y0_reg, x1_reg, y1_reg, px_reg, py_reg);
            d_reg <= orient(x0_reg, y0_reg, x1_reg, y1_reg, x2_reg, y2_reg);
            state_reg <= ST_PROD;
        end
        ST_PROD: begin
            p0_reg <= e0_reg * $signed({1'b0, z0_reg});
            p1_reg <= e1_reg * $signed({1'b0, z1_reg});
            p2_reg <= e2_reg * $signed({1'b0, z2_reg});
            pd_reg <= d_reg * $signed({1'b0, h_reg});
            if (d_reg <= 0) begin
                // no triangle: all ones, as the C
                ev_reg <= 32'hFFFF_FFFF;
                e_reg <= 32'hFFFF_FFFF;
                state_reg <= mode_reg == 2'd2 ? ST_WAIT : ST_DONE;
                mode_reg <= mode_reg == 2'd2 ? 2'd3 : mode_reg;
            end else begin
                state_reg <= ST_SUM;
            end
        end
        ST_SUM: begin
            v_reg <= {p0_reg[PW-1], p0_reg} + {p1_reg[PW-1], p1_reg} + {p2_reg[PW-1], p2_reg}
                     - {pd_reg[PW-1], pd_reg};
            state_reg <= ST_SET;
        end
        ST_SET: begin
            if (sat) begin
                // ev saturated (e's division never is)
                ev_reg <= 32'hFFFF_FFFF;
                state_reg <= need_e ? ST_WAIT : ST_DONE;
                e_reg <= 32'hFFFF_FFFF;
            end else begin
                num_reg <= n_add[31:0];
                rem_reg <= {31'd0, n_add[64:32]};
                div_reg <= d_set;
                quo_reg <= 32'd0;
                count_reg <= DIV_CLOCKS;
                state_reg <= ST_DIV;
            end
        end
        ST_DIV: begin
            num_reg <= dn;
            quo_reg <= dq;
            rem_reg <= dr;
            count_reg <= count_reg - 8'd1;
            if (count_reg == 8'd1) begin
                if (second_reg) begin
                    e_reg <= dq;
                    state_reg <= ST_DONE;
                end else begin
                    ev_reg <= dq;
                    e_reg <= dq;
                    state_reg <= need_e ? ST_WAIT : ST_DONE;
                end
            end
        end
        ST_WAIT: begin
            // e = ev when ev = 0; mode 2 (and 3 after D <= 0) first waits for the slope unit's r
            if (mode_reg == 2'd1 || s_r_valid) begin
                if (mode_reg == 2'd2) r_reg <= s_r;
                if (mode_reg != 2'd3 && ev_reg != 32'd0) begin
                    second_reg <= 1'b1;
                    state_reg <= ST_SET;
                end else begin
                    state_reg <= ST_DONE;
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

endmodule

`resetall
