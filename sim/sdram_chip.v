/*
 * wavemesh: cycle model of the ULX3S's SDR SDRAM for the simulated board, with its timing checks
 *
 * The chip of tests/rtl/sdram_tb.py (`Chip`), in Verilog so the Verilator board runs it at full
 * speed: 4 banks of 2^ROW_BITS rows of 2^COL_BITS halfwords, burst length 1.  Its clock is the
 * inverted system clock (as on the board, an output DDR register drives ~clk): it samples the pins
 * at clk's falling edge.  A READ seen at falling edge n drives its datum from falling edge
 * n + CL - 1 to falling edge n + CL (the controller captures it at the rising edge between);
 * outside that window the DQ it returns is junk, never the last datum.
 *
 * Every datasheet timing is checked in ps against `WM_SDRAM_*` (host/wavemesh/device/memmap.py, the table
 * the controller is built with): the power-up wait and the initialisation (PRECHARGE ALL, >= 2
 * REFRESH, LOAD MODE with CL and burst length 1), tRCD, tRP, tRAS, tRC, tRRD, tRFC, tWR, tMRD,
 * every gap between two REFRESH commands <= tREFI, each command legal in its bank's state, no
 * auto precharge, no read or write outside a row, and the data bus driven by one side at a time.
 * A violation prints "wmsim: sdram: ..." with the cycle and stops the simulation ($fatal); with
 * FATAL = 0 (the model's own test, tests/rtl/test_sdram_chip.py) it counts instead (violations_reg,
 * last_what_reg) and the simulation goes on.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module sdram_chip #
(
    // the system clock in Hz (the checks' time base)
    parameter CLK_HZ = `WM_CLK_HZ,
    parameter ROW_BITS = `WM_SDRAM_ROW_BITS,
    parameter COL_BITS = `WM_SDRAM_COL_BITS,
    parameter CAS_LATENCY = `WM_SDRAM_CAS_LATENCY,
    // 1: stop the simulation at the first violation; 0: count them
    parameter FATAL = 1
)
(
    input  wire                 clk,          // the system clock; the chip runs on its falling edge
    input  wire                 cke,
    input  wire                 cs_n,
    input  wire                 ras_n,
    input  wire                 cas_n,
    input  wire                 we_n,
    input  wire [1:0]           ba,
    input  wire [ROW_BITS-1:0]  a,
    input  wire [1:0]           dqm,
    input  wire [15:0]          dq_o,         // the controller's side of DQ
    input  wire                 dq_oe,
    output wire [15:0]          dq_i          // what the controller sees on DQ
);

localparam [63:0] HZ = CLK_HZ;
localparam [63:0] T_PS = 64'd1000000000000 / HZ;
localparam ADDR_BITS = ROW_BITS + 2 + COL_BITS;

// datasheet timings in ps
localparam [63:0] P_INIT = 64'd1000 * `WM_SDRAM_T_INIT_NS;
localparam [63:0] P_RCD = 64'd1000 * `WM_SDRAM_T_RCD_NS;
localparam [63:0] P_RP = 64'd1000 * `WM_SDRAM_T_RP_NS;
localparam [63:0] P_RAS = 64'd1000 * `WM_SDRAM_T_RAS_NS;
localparam [63:0] P_RC = 64'd1000 * `WM_SDRAM_T_RC_NS;
localparam [63:0] P_RFC = 64'd1000 * `WM_SDRAM_T_RFC_NS;
localparam [63:0] P_RRD = 64'd1000 * `WM_SDRAM_T_RRD_NS;
localparam [63:0] P_WR = 64'd1000 * `WM_SDRAM_T_WR_NS;
localparam [63:0] C_WR_MIN = `WM_SDRAM_T_WR_MIN_CK;
localparam [63:0] C_MRD = `WM_SDRAM_T_MRD_CK;
localparam [63:0] P_REFI = 64'd1000 * `WM_SDRAM_T_REFI_NS + 64'd500;  // tREFI is 7812.5 ns
localparam [63:0] P_HZ = 64'd1000 * `WM_SDRAM_T_HZ_NS;

localparam [63:0] NEVER = 64'h0000_0100_0000_0000;  // "long ago" (2^40 edges) for a first command

reg [15:0] mem [0:(1 << ADDR_BITS) - 1];

// falling edges since time 0
reg [63:0] n_reg = 64'd0;
// violations so far and the name of the last (FATAL = 0)
reg [31:0] violations_reg = 32'd0;
reg [8*80-1:0] last_what_reg = {80{8'h20}};

// per bank: open row, last ACTIVATE, PRECHARGE and WRITE
reg        open_reg [0:3];
reg [ROW_BITS-1:0] row_reg [0:3];
reg [63:0] act_reg [0:3];
reg [63:0] pre_reg [0:3];
reg [63:0] wr_reg [0:3];
// global: last ACTIVATE of any bank, REFRESH, LOAD MODE; initialisation progress
reg [63:0] act_any_reg = 64'd0;
reg [63:0] ref_reg = 64'd0;
reg [63:0] mrd_reg = 64'd0;
reg        pre_all_done_reg = 1'b0;  // the initialisation's PRECHARGE ALL
reg [3:0]  init_refs_reg = 4'd0;     // its REFRESH commands
reg        mode_done_reg = 1'b0;     // LOAD MODE: the chip is ready
reg        first_cmd_reg = 1'b1;
reg        refi_late_reg = 1'b0;     // this refresh gap has been reported

// read pipeline: the datum of a READ seen at edge n is driven from edge n + CL - 1
reg [CAS_LATENCY-1:0] rd_pipe_reg = {CAS_LATENCY{1'b0}};
reg [15:0] rd_data_pipe_reg [0:CAS_LATENCY-1];
reg        drive_reg = 1'b0;         // the chip drives DQ from this falling edge to the next
reg        drive_prev_reg = 1'b0;
reg [15:0] drive_data_reg = 16'd0;
reg [15:0] junk_reg = 16'hA5C3;

integer i;
initial begin
    for (i = 0; i < 4; i = i + 1) begin
        open_reg[i] = 1'b0;
        row_reg[i] = {ROW_BITS{1'b0}};
        act_reg[i] = 64'd0;
        pre_reg[i] = 64'd0;
        wr_reg[i] = 64'd0;
    end
    for (i = 0; i < CAS_LATENCY; i = i + 1) begin
        rd_data_pipe_reg[i] = 16'd0;
    end
    if (ROW_BITS < 11 || ROW_BITS > 13 || COL_BITS < 8 || COL_BITS > 10 || CAS_LATENCY < 2
            || CAS_LATENCY > 3) begin
        $error("Error: unsupported SDRAM geometry (instance %m)");
        $finish;
    end
end

assign dq_i = drive_reg ? drive_data_reg : junk_reg;

wire [2:0] cmd = {ras_n, cas_n, we_n};
localparam [2:0]
    CMD_LOAD_MODE = 3'b000,
    CMD_REFRESH = 3'b001,
    CMD_PRECHARGE = 3'b010,
    CMD_ACTIVATE = 3'b011,
    CMD_WRITE = 3'b100,
    CMD_READ = 3'b101,
    CMD_BURST_TERM = 3'b110,
    CMD_NOP = 3'b111;

wire [63:0] now = n_reg;

// ps since edge `then`
function [63:0] since;
    input [63:0] then;
    begin
        since = (now - then) * T_PS;
    end
endfunction

task fail;
    input [8*80-1:0] what;
    begin
        $display("wmsim: sdram: %0s violated at cycle %0d (%0t)", what, now, $time);
        if (FATAL != 0) begin
            $fatal(1, "sdram_chip: timing or protocol violation");
        end
        violations_reg = violations_reg + 32'd1;
        last_what_reg = what;
    end
endtask

wire [COL_BITS-1:0] col = a[COL_BITS-1:0];
wire [ADDR_BITS-1:0] hw_addr = {row_reg[ba], ba, col};
wire active = !cs_n && cmd != CMD_NOP;
wire all_idle = !open_reg[0] && !open_reg[1] && !open_reg[2] && !open_reg[3];

always @(negedge clk) begin
    n_reg <= n_reg + 64'd1;
    junk_reg <= {junk_reg[14:0], junk_reg[15] ^ junk_reg[13] ^ junk_reg[12] ^ junk_reg[10]};

    // the read pipeline moves on one chip clock
    rd_pipe_reg <= {rd_pipe_reg[CAS_LATENCY-2:0], 1'b0};
    for (i = CAS_LATENCY - 1; i > 0; i = i - 1) begin
        rd_data_pipe_reg[i] <= rd_data_pipe_reg[i-1];
    end
    drive_prev_reg <= drive_reg;
    drive_reg <= rd_pipe_reg[CAS_LATENCY-2];
    drive_data_reg <= rd_data_pipe_reg[CAS_LATENCY-2];

    // one side on the bus: the controller must not drive while the chip does or has just stopped
    // (the chip releases DQ tHZ after its last edge; the controller turns on at a rising edge)
    if (dq_oe && (drive_reg || rd_pipe_reg[CAS_LATENCY-2] || (drive_prev_reg && P_HZ > T_PS / 2))) begin
        fail("DQ contention");
    end

    if (!cke) begin
        fail("CKE low (no power-down in this design)");
    end

    // refresh interval, once the chip is running
    if (mode_done_reg && since(ref_reg) > P_REFI && !refi_late_reg) begin
        fail("tREFI");
        refi_late_reg <= 1'b1;
    end

    if (active) begin
        // the power-up wait precedes every command
        if (first_cmd_reg) begin
            if (since(64'd0) < P_INIT) fail("power-up wait");
            first_cmd_reg <= 1'b0;
        end
        // every command waits for tRFC after a REFRESH and tMRD after a LOAD MODE
        if (since(ref_reg) < P_RFC && init_refs_reg != 4'd0) fail("tRFC");
        if (now - mrd_reg < C_MRD && mode_done_reg) fail("tMRD");
    end

    if (!cs_n) begin
        case (cmd)
            CMD_ACTIVATE: begin
                if (!mode_done_reg) fail("ACTIVATE before the initialisation");
                if (open_reg[ba]) fail("ACTIVATE of an open bank");
                if (since(pre_reg[ba]) < P_RP) fail("tRP");
                if (since(act_reg[ba]) < P_RC) fail("tRC");
                if (since(act_any_reg) < P_RRD) fail("tRRD");
                open_reg[ba] <= 1'b1;
                row_reg[ba] <= a;
                act_reg[ba] <= now;
                act_any_reg <= now;
            end
            CMD_READ, CMD_WRITE: begin
                if (!open_reg[ba]) fail("READ/WRITE of a closed bank");
                if (since(act_reg[ba]) < P_RCD) fail("tRCD");
                if (a[10]) fail("auto precharge (not used by this design)");
                if (cmd == CMD_WRITE) begin
                    if (!dq_oe) fail("WRITE without its datum on DQ");
                    if (!dqm[0]) mem[hw_addr][7:0] <= dq_o[7:0];
                    if (!dqm[1]) mem[hw_addr][15:8] <= dq_o[15:8];
                    wr_reg[ba] <= now;
                end else begin
                    if (dqm != 2'b00) fail("DQM on a READ (the reads are whole halfwords)");
                    rd_pipe_reg[0] <= 1'b1;
                    rd_data_pipe_reg[0] <= mem[hw_addr];
                end
            end
            CMD_PRECHARGE: begin
                for (i = 0; i < 4; i = i + 1) begin
                    if (a[10] || ba == i[1:0]) begin
                        if (open_reg[i]) begin
                            if (since(act_reg[i]) < P_RAS) fail("tRAS");
                            if (since(wr_reg[i]) < P_WR || now - wr_reg[i] < C_WR_MIN) fail("tWR");
                        end
                        open_reg[i] <= 1'b0;
                        pre_reg[i] <= now;
                    end
                end
                if (a[10] && !pre_all_done_reg) pre_all_done_reg <= 1'b1;
            end
            CMD_REFRESH: begin
                if (!all_idle) fail("REFRESH with a bank open");
                if (!pre_all_done_reg) fail("REFRESH before the initialisation's PRECHARGE ALL");
                for (i = 0; i < 4; i = i + 1) begin
                    if (since(pre_reg[i]) < P_RP) fail("tRP before REFRESH");
                end
                ref_reg <= now;
                refi_late_reg <= 1'b0;
                if (init_refs_reg != 4'd15) init_refs_reg <= init_refs_reg + 4'd1;
            end
            CMD_LOAD_MODE: begin
                if (!all_idle) fail("LOAD MODE with a bank open");
                if (init_refs_reg < 4'd2) fail("LOAD MODE before two REFRESH commands");
                if (ba != 2'b00 || a[2:0] != 3'b000 || a[3] || a[6:4] != CAS_LATENCY[2:0] || a[8:7] != 2'b00)
                    fail("mode register (burst length 1, sequential, CL, standard operation)");
                for (i = 0; i < 4; i = i + 1) begin
                    if (since(pre_reg[i]) < P_RP) fail("tRP before LOAD MODE");
                end
                mrd_reg <= now;
                mode_done_reg <= 1'b1;
            end
            CMD_BURST_TERM: begin
                fail("BURST TERMINATE (not used by this design)");
            end
            default: begin
                // NOP
            end
        endcase
    end
end

// the initial state: every falling edge "long ago" for the first ACTIVATE, PRECHARGE, REFRESH
initial begin
    act_any_reg = 64'd0 - NEVER;
    for (i = 0; i < 4; i = i + 1) begin
        act_reg[i] = 64'd0 - NEVER;
        pre_reg[i] = 64'd0 - NEVER;
        wr_reg[i] = 64'd0 - NEVER;
    end
    ref_reg = 64'd0 - NEVER;
    mrd_reg = 64'd0 - NEVER;
end

endmodule

`resetall
