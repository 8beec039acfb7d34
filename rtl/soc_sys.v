/*
 * wavemesh: the SoC's system register block
 *
 * Registers (offsets in the block; docs/soc.md has the tables, generated from
 * host/wavemesh/device/memmap.py):
 *
 *   0x00 CYCLE_LO        cycles since reset [31:0]; reading it latches [63:32] for CYCLE_HI
 *   0x04 CYCLE_HI        cycles since reset [63:32] as latched by the last CYCLE_LO read
 *   0x08 TIMER           down-counter: write loads, -1 per cycle, stops at 0
 *   0x0C LEDS            LED outputs [LED_COUNT-1:0]
 *   0x10 STAGE           stage marker: a write pulses stage_valid with the value (the simulator logs it)
 *   0x14 HALT            a write pulses halt_valid with the exit code (the simulator exits)
 *   0x20 CLK_HZ, 0x24 FW_RAM_BYTES, 0x28 HEIGHT_SAMPLES, 0x2C COEF_ENTRIES, 0x30 TOUT_ENTRIES
 *                        read-only configuration
 *
 * Bus: bus_valid is a one-cycle request (bus_wstrb = 0 for a read); bus_rdata is valid in the next
 * cycle.  Any non-zero bus_wstrb writes the whole register.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_sys #
(
    // LED outputs, 1..32
    parameter LED_COUNT = 8,
    // configuration the block reports (read-only registers)
    parameter CLK_HZ = 25000000,
    parameter FW_RAM_BYTES = 98304,
    parameter HEIGHT_SAMPLES = 65536,
    parameter COEF_ENTRIES = 65536,
    parameter TOUT_ENTRIES = 4096
)
(
    input  wire                  clk,
    input  wire                  rst,

    /*
     * Register bus
     */
    input  wire                  bus_valid,
    input  wire [7:0]            bus_addr,
    input  wire [31:0]           bus_wdata,
    input  wire [3:0]            bus_wstrb,
    output wire [31:0]           bus_rdata,

    /*
     * Outputs
     */
    output wire [LED_COUNT-1:0]  led,
    output wire                  stage_valid,   // one-cycle strobe per STAGE write
    output wire [31:0]           stage,
    output wire                  halt_valid,    // one-cycle strobe per HALT write
    output wire [31:0]           halt_code
);


// check configuration
initial begin
    if (LED_COUNT < 1 || LED_COUNT > 32) begin
        $error("Error: LED_COUNT must be 1..32 (instance %m)");
        $finish;
    end
end

reg [63:0] cycle_reg = 64'd0;
reg [31:0] cycle_hi_latch_reg = 32'd0, cycle_hi_latch_next;
reg [31:0] timer_reg = 32'd0, timer_next;
reg [LED_COUNT-1:0] led_reg = {LED_COUNT{1'b0}}, led_next;
reg [31:0] stage_reg = 32'd0, stage_next;
reg stage_valid_reg = 1'b0, stage_valid_next;
reg [31:0] halt_code_reg = 32'd0, halt_code_next;
reg halt_valid_reg = 1'b0, halt_valid_next;
reg [31:0] rdata_reg = 32'd0, rdata_next;

// LEDs zero-extended to a word (LED_COUNT may be 32)
reg [31:0] led_word;
always @* begin
    led_word = 32'd0;
    led_word[LED_COUNT-1:0] = led_reg;
end

wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire reg_write = bus_valid && bus_wstrb != 4'd0;

assign bus_rdata = rdata_reg;
assign led = led_reg;
assign stage_valid = stage_valid_reg;
assign stage = stage_reg;
assign halt_valid = halt_valid_reg;
assign halt_code = halt_code_reg;

always @* begin
    cycle_hi_latch_next = cycle_hi_latch_reg;
    timer_next = timer_reg;
    led_next = led_reg;
    stage_next = stage_reg;
    stage_valid_next = 1'b0;
    halt_code_next = halt_code_reg;
    halt_valid_next = 1'b0;
    rdata_next = 32'd0;

    if (timer_reg != 32'd0) begin
        // the timer runs down to 0 and stops
        timer_next = timer_reg - 32'd1;
    end

    if (reg_read) begin
        // read: registered data for the next cycle
        case (bus_addr)
            `WM_SYS_CYCLE_LO: begin
                rdata_next = cycle_reg[31:0];
                cycle_hi_latch_next = cycle_reg[63:32];
            end
            `WM_SYS_CYCLE_HI: rdata_next = cycle_hi_latch_reg;
            `WM_SYS_TIMER: rdata_next = timer_reg;
            `WM_SYS_LEDS: rdata_next = led_word;
            `WM_SYS_STAGE: rdata_next = stage_reg;
            `WM_SYS_HALT: rdata_next = halt_code_reg;
            `WM_SYS_CLK_HZ: rdata_next = CLK_HZ;
            `WM_SYS_FW_RAM_BYTES: rdata_next = FW_RAM_BYTES;
            `WM_SYS_HEIGHT_SAMPLES: rdata_next = HEIGHT_SAMPLES;
            `WM_SYS_COEF_ENTRIES: rdata_next = COEF_ENTRIES;
            `WM_SYS_TOUT_ENTRIES: rdata_next = TOUT_ENTRIES;
            default: rdata_next = 32'd0;
        endcase
    end

    if (reg_write) begin
        case (bus_addr)
            `WM_SYS_TIMER: timer_next = bus_wdata;
            `WM_SYS_LEDS: led_next = bus_wdata[LED_COUNT-1:0];
            `WM_SYS_STAGE: begin
                // stage marker
                stage_next = bus_wdata;
                stage_valid_next = 1'b1;
            end
            `WM_SYS_HALT: begin
                // halt request
                halt_code_next = bus_wdata;
                halt_valid_next = 1'b1;
            end
            default: begin
                // read-only or unmapped: ignored
            end
        endcase
    end
end

always @(posedge clk) begin
    cycle_reg <= cycle_reg + 64'd1;
    cycle_hi_latch_reg <= cycle_hi_latch_next;
    timer_reg <= timer_next;
    led_reg <= led_next;
    stage_reg <= stage_next;
    stage_valid_reg <= stage_valid_next;
    halt_code_reg <= halt_code_next;
    halt_valid_reg <= halt_valid_next;
    rdata_reg <= rdata_next;

    if (rst) begin
        cycle_reg <= 64'd0;
        cycle_hi_latch_reg <= 32'd0;
        timer_reg <= 32'd0;
        led_reg <= {LED_COUNT{1'b0}};
        stage_reg <= 32'd0;
        stage_valid_reg <= 1'b0;
        halt_code_reg <= 32'd0;
        halt_valid_reg <= 1'b0;
    end
end

endmodule

`resetall
