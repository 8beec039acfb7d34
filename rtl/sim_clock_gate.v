/*
 * wavemesh: the simulator's clock gate (sim/build.py's default build alone; the bitstream has none)
 *
 * gclk is clk while en is high: en is latched while clk is low, as a clock-gating cell does, so that
 * the gated edge comes in the same evaluation as clk's and sees the values from before it, as every
 * other register does.  soc_accel gates its FPGA stage with it (WM_SIM_STAGE_GATE) and soc_engine the
 * error engine's units (WM_SIM_ENGINE_GATE); why each is exact is docs/soc.md's ("The simulated
 * board", "Speed").  A Verilator model evaluates a unit's logic at its clock's edges only, so an idle
 * unit costs the simulation nothing.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module sim_clock_gate
(
    input  wire clk,
    input  wire en,
    output wire gclk
);

reg en_latch;
always @* begin
    if (!clk) begin
        en_latch = en;
    end
end
assign gclk = clk && en_latch;

endmodule

`resetall
