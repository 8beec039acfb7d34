/*
 * wavemesh: raster position counter of the filter bank
 *
 * Counts (x, y) over a cfg_wm1 + 1 by cfg_hm1 + 1 grid in raster order, one step per cycle with step
 * high, and keeps "last column" and "last row" as registered flags so that users compare nothing.
 * After the last position it wraps to (0, 0).  start (re)loads the first position for new sizes; it
 * wins over step.  haar_level counts its input samples with it, haar_bank the records it hands out.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module haar_raster #
(
    // Width of x in bits (the grid is at most 2^X_WIDTH columns)
    parameter X_WIDTH = 9,
    // Width of y in bits (the grid is at most 2^Y_WIDTH rows)
    parameter Y_WIDTH = 9
)
(
    input  wire                clk,
    input  wire                rst,

    input  wire                start,     // go to (0, 0) of a grid of the cfg_* size
    input  wire [X_WIDTH-1:0]  cfg_wm1,   // columns - 1 (held while counting)
    input  wire [Y_WIDTH-1:0]  cfg_hm1,   // rows - 1 (held while counting)
    input  wire                step,      // advance to the next position

    output wire [X_WIDTH-1:0]  x,
    output wire [Y_WIDTH-1:0]  y,
    output wire                x_last,    // x == cfg_wm1
    output wire                y_last     // y == cfg_hm1
);

reg [X_WIDTH-1:0] x_reg = {X_WIDTH{1'b0}}, x_next;
reg [Y_WIDTH-1:0] y_reg = {Y_WIDTH{1'b0}}, y_next;
reg x_last_reg = 1'b0, x_last_next;
reg y_last_reg = 1'b0, y_last_next;

wire [X_WIDTH-1:0] x_inc = x_reg + 1'b1;
wire [Y_WIDTH-1:0] y_inc = y_reg + 1'b1;

assign x = x_reg;
assign y = y_reg;
assign x_last = x_last_reg;
assign y_last = y_last_reg;

always @* begin
    x_next = x_reg;
    y_next = y_reg;
    x_last_next = x_last_reg;
    y_last_next = y_last_reg;

    if (start) begin
        // first position of a new grid
        x_next = {X_WIDTH{1'b0}};
        y_next = {Y_WIDTH{1'b0}};
        x_last_next = cfg_wm1 == {X_WIDTH{1'b0}};
        y_last_next = cfg_hm1 == {Y_WIDTH{1'b0}};
    end else if (step) begin
        if (x_last_reg) begin
            // end of a row: next row, or wrap after the last one
            x_next = {X_WIDTH{1'b0}};
            x_last_next = cfg_wm1 == {X_WIDTH{1'b0}};
            if (y_last_reg) begin
                y_next = {Y_WIDTH{1'b0}};
                y_last_next = cfg_hm1 == {Y_WIDTH{1'b0}};
            end else begin
                y_next = y_inc;
                y_last_next = y_inc == cfg_hm1;
            end
        end else begin
            // inside a row
            x_next = x_inc;
            x_last_next = x_inc == cfg_wm1;
        end
    end
end

always @(posedge clk) begin
    x_reg <= x_next;
    y_reg <= y_next;
    x_last_reg <= x_last_next;
    y_last_reg <= y_last_next;

    if (rst) begin
        x_reg <= {X_WIDTH{1'b0}};
        y_reg <= {Y_WIDTH{1'b0}};
        x_last_reg <= 1'b0;
        y_last_reg <= 1'b0;
    end
end

endmodule

`resetall
