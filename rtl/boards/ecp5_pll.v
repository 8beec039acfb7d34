/*
 * wavemesh: the ECP5's PLL (EHXPLLL) making the system clock from a board's oscillator
 *
 * CLKOP is always the output fed back to the phase detector (FEEDBK_PATH "CLKOP", as Project Trellis'
 * ecppll writes it).  With CLKOS_DIV 0 it is also the system clock: f_out = f_in CLKFB_DIV / CLKI_DIV,
 * the VCO at f_out CLKOP_DIV.  With CLKOS_DIV > 0 (ecppll's --highres) CLKOP only closes the loop and
 * CLKOS is the system clock: the VCO at f_in / CLKI_DIV x CLKFB_DIV x CLKOP_DIV, f_out = VCO / CLKOS_DIV.
 * The dividers come from the memory map (host/wavemesh/device/memmap.py, ecp5_pll: WM_PLL_* of
 * wm_memmap.vh), the one source of the clock that SYS.CLK_HZ, the UART divisor and HELLO state.  locked
 * is the PLL's LOCK: the board top holds the SoC in reset until it is high.
 *
 * Only synthesis (Yosys defines SYNTHESIS) has the primitive.  The simulated board (sim/board_sim.v)
 * and the lint run in system clock cycles: there the output is the input and locked is 1.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module ecp5_pll #
(
    parameter integer CLKI_DIV = 1,
    parameter integer CLKFB_DIV = 1,
    parameter integer CLKOP_DIV = 24,
    parameter integer CLKOP_CPHASE = 11,
    parameter integer CLKOS_DIV = 0,
    parameter integer CLKOS_CPHASE = 0
)
(
    input  wire  clk_in,
    output wire  clk_out,
    output wire  locked
);

`ifdef SYNTHESIS
wire clkop;
wire clkos;

(* ICP_CURRENT = "12" *) (* LPF_RESISTOR = "8" *) (* MFG_ENABLE_FILTEROPAMP = "1" *) (* MFG_GMCREF_SEL = "2" *)
EHXPLLL #(
    .PLLRST_ENA("DISABLED"),
    .INTFB_WAKE("DISABLED"),
    .STDBY_ENABLE("DISABLED"),
    .DPHASE_SOURCE("DISABLED"),
    .OUTDIVIDER_MUXA("DIVA"),
    .OUTDIVIDER_MUXB("DIVB"),
    .OUTDIVIDER_MUXC("DIVC"),
    .OUTDIVIDER_MUXD("DIVD"),
    .CLKI_DIV(CLKI_DIV),
    .CLKOP_ENABLE("ENABLED"),
    .CLKOP_DIV(CLKOP_DIV),
    .CLKOP_CPHASE(CLKOP_CPHASE),
    .CLKOP_FPHASE(0),
    .CLKOS_ENABLE(CLKOS_DIV > 0 ? "ENABLED" : "DISABLED"),
    .CLKOS_DIV(CLKOS_DIV > 0 ? CLKOS_DIV : 1),
    .CLKOS_CPHASE(CLKOS_CPHASE),
    .CLKOS_FPHASE(0),
    .FEEDBK_PATH("CLKOP"),
    .CLKFB_DIV(CLKFB_DIV)
) pll_inst (
    .RST(1'b0),
    .STDBY(1'b0),
    .CLKI(clk_in),
    .CLKOP(clkop),
    .CLKOS(clkos),
    .CLKFB(clkop),
    .CLKINTFB(),
    .PHASESEL0(1'b0),
    .PHASESEL1(1'b0),
    .PHASEDIR(1'b1),
    .PHASESTEP(1'b1),
    .PHASELOADREG(1'b1),
    .PLLWAKESYNC(1'b0),
    .ENCLKOP(1'b0),
    .LOCK(locked)
);

generate
    if (CLKOS_DIV > 0) begin : g_clkos
        assign clk_out = clkos;
    end else begin : g_clkop
        assign clk_out = clkop;
    end
endgenerate
`else
assign clk_out = clk_in;
assign locked = 1'b1;
`endif

endmodule

`resetall
