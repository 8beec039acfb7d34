/*
 * wavemesh: power-on reset and a reset button for the board tops
 *
 * rst is high from configuration until 2^POR_BITS clocks have passed (every flip-flop starts at 0
 * after configuration, so the counter needs no reset of its own), and again while the button is
 * pressed (synchronised by two flip-flops, then held for the same count after release, so a bouncing
 * button gives one clean reset).  The wait also covers the iCE40's block RAMs, which read as zero for
 * a few microseconds after configuration.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module wm_por #
(
    // reset lasts 2^POR_BITS clocks after configuration and after the button's release
    parameter POR_BITS = 16,
    // 1: the button pin is high when pressed; 0: low when pressed
    parameter BUTTON_ACTIVE_HIGH = 1
)
(
    input  wire  clk,
    input  wire  button,   // asynchronous pin
    output wire  rst
);

reg [1:0] button_sync_reg = 2'b00;
reg [POR_BITS:0] count_reg = {(POR_BITS + 1){1'b0}};

wire pressed = BUTTON_ACTIVE_HIGH ? button_sync_reg[1] : !button_sync_reg[1];

always @(posedge clk) begin
    button_sync_reg <= {button_sync_reg[0], button};
    if (pressed) begin
        count_reg <= {(POR_BITS + 1){1'b0}};
    end else if (!count_reg[POR_BITS]) begin
        count_reg <= count_reg + 1'b1;
    end
end

assign rst = !count_reg[POR_BITS];

endmodule

`resetall
