/*
 * wavemesh: the 64-bit divider, n / d and n mod d of unsigned 64-bit integers in hardware
 *
 * The board's firmware divides 64-bit integers in the refiner (E(T)'s rounding, the unit normals, the
 * Jacobi rotations, R_A: firmware/board/src/div64.c's __udivdi3 and __divdi3), where the soft CPU has a
 * 32-bit divider only.  This is a restoring division (udiv_step.v), STEPS quotient bits a clock, from
 * the top of n's highest non-zero 16-bit digit (the quotient's bits above it are zeros): 64, 48, 32
 * or 16 steps.  The result is the C operators' n / d and n % d; d = 0 gives the quotient all ones in
 * the bits taken and the remainder n (the firmware never divides by 0: the C leaves it undefined).
 *
 * Timing: 1 clock to take the command, 64 / STEPS of division (48, 32, 16 / STEPS when n < 2^48, 2^32,
 * 2^16), 1 to hand out the result: 34 clocks at STEPS = 2 for a 64-bit n, 26 for a 48-bit one.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module udiv64 #
(
    // quotient bits per clock: 1 or 2
    parameter STEPS = 2
)
(
    input  wire         clk,
    input  wire         rst,

    input  wire [63:0]  s_n,
    input  wire [63:0]  s_d,
    input  wire         s_valid,
    output wire         s_ready,

    output wire [63:0]  m_q,
    output wire [63:0]  m_r,
    output wire         m_valid,
    input  wire         m_ready,

    output wire         busy
);

// check configuration
initial begin
    if (STEPS < 1 || STEPS > 2) begin
        $error("Error: STEPS must be 1 or 2 (instance %m)");
        $finish;
    end
end

localparam [6:0] STEP7 = STEPS[6:0];

localparam [1:0]
    ST_IDLE = 2'd0,
    ST_RUN = 2'd1,
    ST_DONE = 2'd2;

reg [1:0] state_reg = ST_IDLE;
reg [63:0] num_reg = 64'd0, quo_reg = 64'd0, rem_reg = 64'd0, d_reg = 64'd0;
reg [6:0] left_reg = 7'd0;

assign s_ready = state_reg == ST_IDLE;
assign m_q = quo_reg;
assign m_r = rem_reg;
assign m_valid = state_reg == ST_DONE;
assign busy = state_reg != ST_IDLE;

// one clock: STEPS restoring steps
wire [63:0] dn, dq, dr;

udiv_step #(
    .NW(64),
    .RW(64),
    .QW(64),
    .STEPS(STEPS)
)
step_inst (
    .n(num_reg),
    .q(quo_reg),
    .r(rem_reg),
    .d(d_reg),
    .n_next(dn),
    .q_next(dq),
    .r_next(dr)
);

always @(posedge clk) begin
    case (state_reg)
        ST_IDLE: begin
            if (s_valid) begin
                // n's digits from its highest non-zero one at the top
                if (s_n[63:48] != 16'd0) begin
                    num_reg <= s_n;
                    left_reg <= 7'd64;
                end else if (s_n[47:32] != 16'd0) begin
                    num_reg <= {s_n[47:0], 16'd0};
                    left_reg <= 7'd48;
                end else if (s_n[31:16] != 16'd0) begin
                    num_reg <= {s_n[31:0], 32'd0};
                    left_reg <= 7'd32;
                end else begin
                    num_reg <= {s_n[15:0], 48'd0};
                    left_reg <= 7'd16;
                end
                d_reg <= s_d;
                quo_reg <= 64'd0;
                rem_reg <= 64'd0;
                state_reg <= ST_RUN;
            end
        end
        ST_RUN: begin
            num_reg <= dn;
            quo_reg <= dq;
            rem_reg <= dr;
            left_reg <= left_reg - STEP7;
            if (left_reg == STEP7) state_reg <= ST_DONE;
        end
        ST_DONE: begin
            if (m_ready) state_reg <= ST_IDLE;
        end
        default: state_reg <= ST_IDLE;
    endcase

    if (rst) begin
        state_reg <= ST_IDLE;
    end
end

endmodule

`resetall
