/*
 * wavemesh: STEPS steps of a restoring division, the one clock's arithmetic of every divider in rtl/
 * (udiv64's, tri_slope's two)
 *
 * Combinational.  A divider keeps the numerator bits still to take at the top of n, the quotient so
 * far and the partial remainder (below d); each step shifts n's top bit into the remainder, takes d
 * off it when it fits and shifts the quotient's new bit in at the bottom:
 *
 *     t = 2 r + top bit of n;   n <<= 1;   t >= d ? (r = t - d, q = 2 q + 1) : (r = t, q = 2 q)
 *
 * With r < d on the way in, r < d on the way out, so RW bits hold it (t takes RW + 1).  d = 0 gives
 * quotient bits of one and the remainder the numerator's bits taken.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module udiv_step #
(
    // numerator bits (the ones still to take at the top)
    parameter NW = 64,
    // divisor and remainder bits
    parameter RW = 64,
    // quotient bits (the oldest shift out at the top)
    parameter QW = 64,
    // restoring steps: quotient bits a clock, >= 1
    parameter STEPS = 2
)
(
    input  wire [NW-1:0]  n,
    input  wire [QW-1:0]  q,
    input  wire [RW-1:0]  r,
    input  wire [RW-1:0]  d,

    output reg  [NW-1:0]  n_next,
    output reg  [QW-1:0]  q_next,
    output reg  [RW-1:0]  r_next
);

// check configuration
initial begin
    if (STEPS < 1 || NW < 1 || RW < 1 || QW < 2) begin
        $error("Error: STEPS, NW, RW must be >= 1 and QW >= 2 (instance %m)");
        $finish;
    end
end

reg [RW:0] t;
integer i;

always @* begin
    n_next = n;
    q_next = q;
    r_next = r;
    for (i = 0; i < STEPS; i = i + 1) begin
        t = {r_next, n_next[NW-1]};
        n_next = n_next << 1;
        if (t >= {1'b0, d}) begin
            r_next = t[RW-1:0] - d;
            q_next = {q_next[QW-2:0], 1'b1};
        end else begin
            r_next = t[RW-1:0];
            q_next = {q_next[QW-2:0], 1'b0};
        end
    end
end

endmodule

`resetall
