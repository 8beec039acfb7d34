/*
 * wavemesh template stage: the dominant-coefficient labeller (docs/model.md "Labeller").
 *
 * One record per cycle in, its 3-bit block label three cycles later (magnitudes, comparisons,
 * decision; a pipeline with no stall: the caller guarantees room downstream).  Steps, as
 * wavemesh.model.label.label_blocks:
 *
 *   1. k* = the k with the largest |d_k|, the lowest k on ties (d1, then d2);
 *   2. |d_k*| > tau (strict): V for k* = 1, H for 2, D for 3; otherwise F;
 *   3. F, V, H become f, v, h when d1 * d2 < 0 (zero counts as basic); D is self-dual;
 *   4. demotion: s_narrow (block column narrower than 2 grid steps) turns V, v, D into F/f,
 *      s_low (block row lower than 2 steps) turns H, h, D into F/f, F/f by the sign rule of 3.
 *
 * Label code = kind << 1 | dual:
 *
 *   | code | 0 | 1 | 2 | 3 | 4 | 5 | 6 |
 *   |------|---|---|---|---|---|---|---|
 *   | label| F | f | V | v | H | h | D |
 *
 * Details are 18-bit two's complement (|d| <= 2 * 65535 from 16-bit samples; the full 18-bit
 * range -131072..131071 is handled too).  tau is an 18-bit unsigned count in detail units
 * (wavemesh.model.label.tau_counts); 2^18 - 1 makes every block flat.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module tlut_label #(
    // Width of the sideband s_user carried unchanged alongside each record (bits, >= 1)
    parameter USER_WIDTH = 1
) (
    input  wire                  clk,
    input  wire                  rst,

    /*
     * Record in: level M's details of one block
     */
    input  wire                  s_valid,
    input  wire [17:0]           s_d1,       // right minus left, two's complement
    input  wire [17:0]           s_d2,       // bottom minus top
    input  wire [17:0]           s_d3,       // diagonal minus anti-diagonal
    input  wire                  s_narrow,   // the block column is narrower than 2 grid steps
    input  wire                  s_low,      // the block row is lower than 2 grid steps
    input  wire [USER_WIDTH-1:0] s_user,

    /*
     * Label out, 3 cycles after the record
     */
    output wire                  m_valid,
    output wire [2:0]            m_label,
    output wire [USER_WIDTH-1:0] m_user,

    /*
     * Configuration
     */
    input  wire [17:0]           cfg_tau     // threshold in detail units: |d| > tau is significant
);

localparam [1:0] KIND_FLAT = 2'd0;
localparam [1:0] KIND_VERTICAL = 2'd1;
localparam [1:0] KIND_HORIZONTAL = 2'd2;
localparam [1:0] KIND_DIAGONAL = 2'd3;

// Stage 1: magnitudes and the sign rule
reg                  s1_valid_reg = 1'b0;
reg [17:0]           s1_a1_reg = 18'd0, s1_a2_reg = 18'd0, s1_a3_reg = 18'd0;
reg                  s1_dual_reg = 1'b0;
reg                  s1_narrow_reg = 1'b0, s1_low_reg = 1'b0;
reg [USER_WIDTH-1:0] s1_user_reg = {USER_WIDTH{1'b0}};

// Stage 2: the comparisons
reg                  s2_valid_reg = 1'b0;
reg                  s2_a1_ge_a2_reg = 1'b0, s2_a1_ge_a3_reg = 1'b0, s2_a2_ge_a3_reg = 1'b0;
reg                  s2_significant_reg = 1'b0;
reg                  s2_dual_reg = 1'b0;
reg                  s2_narrow_reg = 1'b0, s2_low_reg = 1'b0;
reg [USER_WIDTH-1:0] s2_user_reg = {USER_WIDTH{1'b0}};

// Stage 3: the label
reg                  s3_valid_reg = 1'b0;
reg [2:0]            s3_label_reg = 3'd0;
reg [USER_WIDTH-1:0] s3_user_reg = {USER_WIDTH{1'b0}};

assign m_valid = s3_valid_reg;
assign m_label = s3_label_reg;
assign m_user = s3_user_reg;

// |d| of an 18-bit two's complement value: -(-2^17) = 2^17 still fits 18 unsigned bits
function [17:0] magnitude;
    input [17:0] d;
    begin
        magnitude = d[17] ? (~d + 18'd1) : d;
    end
endfunction

// d1 * d2 < 0: both non-zero and of opposite signs
wire sign_dual = (s_d1 != 18'd0) && (s_d2 != 18'd0) && (s_d1[17] != s_d2[17]);


reg [1:0] kind;
reg       demote;
reg [2:0] label_next;

always @* begin
    // dominant coefficient, ties to the lowest k
    if (!s2_significant_reg) begin
        // nothing exceeds tau: flat
        kind = KIND_FLAT;
    end else if (s2_a1_ge_a2_reg && s2_a1_ge_a3_reg) begin
        // d1 dominates (wins ties against d2 and d3)
        kind = KIND_VERTICAL;
    end else if (s2_a2_ge_a3_reg) begin
        // d2 dominates (wins ties against d3)
        kind = KIND_HORIZONTAL;
    end else begin
        // d3 dominates
        kind = KIND_DIAGONAL;
    end

    // no room for a vertical edge / centre in a narrow column, for a horizontal one in a low row
    demote = (s2_narrow_reg && (kind == KIND_VERTICAL || kind == KIND_DIAGONAL))
          || (s2_low_reg && (kind == KIND_HORIZONTAL || kind == KIND_DIAGONAL));

    if (kind == KIND_FLAT || demote) begin
        // F or f by the sign rule
        label_next = {KIND_FLAT, s2_dual_reg};
    end else if (kind == KIND_DIAGONAL) begin
        // D is self-dual
        label_next = {KIND_DIAGONAL, 1'b0};
    end else begin
        // V/v or H/h by the sign rule
        label_next = {kind, s2_dual_reg};
    end
end

always @(posedge clk) begin
    s1_valid_reg <= s_valid;
    s1_a1_reg <= magnitude(s_d1);
    s1_a2_reg <= magnitude(s_d2);
    s1_a3_reg <= magnitude(s_d3);
    s1_dual_reg <= sign_dual;
    s1_narrow_reg <= s_narrow;
    s1_low_reg <= s_low;
    s1_user_reg <= s_user;

    // all comparisons in parallel; the largest magnitude exceeds tau exactly when any does
    s2_valid_reg <= s1_valid_reg;
    s2_a1_ge_a2_reg <= s1_a1_reg >= s1_a2_reg;
    s2_a1_ge_a3_reg <= s1_a1_reg >= s1_a3_reg;
    s2_a2_ge_a3_reg <= s1_a2_reg >= s1_a3_reg;
    s2_significant_reg <= (s1_a1_reg > cfg_tau) || (s1_a2_reg > cfg_tau) || (s1_a3_reg > cfg_tau);
    s2_dual_reg <= s1_dual_reg;
    s2_narrow_reg <= s1_narrow_reg;
    s2_low_reg <= s1_low_reg;
    s2_user_reg <= s1_user_reg;

    s3_valid_reg <= s2_valid_reg;
    s3_label_reg <= label_next;
    s3_user_reg <= s2_user_reg;

    if (rst) begin
        s1_valid_reg <= 1'b0;
        s2_valid_reg <= 1'b0;
        s3_valid_reg <= 1'b0;
    end
end

endmodule

`resetall
