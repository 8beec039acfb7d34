/*
 * wavemesh: single-port RAM of the SoC (firmware, heights, coefficients, template output)
 *
 * DEPTH entries of WIDTH bits behind a 32-bit CPU port.  Synchronous read: rdata holds the entry
 * addressed in the last cycle en was high (block RAM).  Writes:
 *
 *   WIDTH = 32  byte lanes: wstrb[k] writes bits 8k+7..8k (sb, sh, sw all work)
 *   WIDTH < 32  whole entries only: wdata[WIDTH-1:0] is written when wstrb is 4'b1111 (sw);
 *               narrower stores are ignored
 *
 * Reads of a narrow RAM are zero-extended, or sign-extended when SIGNED is 1.  INIT_FILE, when not
 * empty, names a $readmemh file of DEPTH (or fewer) entries, one hex word per line, loaded at
 * build time (firmware image).
 *
 * A second port reads only: b_rdata holds the entry b_addr addressed in the last cycle b_en was high
 * (the VexRiscv's instruction cache refills through it, soc_cpu_vexriscv.v).  Tied off
 * (b_en low) it is no hardware.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module soc_ram #
(
    // Bits per entry, 1..32
    parameter WIDTH = 32,
    // Entries, >= 2
    parameter DEPTH = 1024,
    // 1: reads sign-extend a narrow entry to 32 bits; 0: zero-extend
    parameter SIGNED = 0,
    // $readmemh file loaded at build time, "" for none
    parameter INIT_FILE = ""
)
(
    input  wire                      clk,

    input  wire                      en,      // access this cycle
    input  wire [3:0]                wstrb,   // 0: read
    input  wire [$clog2(DEPTH)-1:0]  addr,    // entry index
    input  wire [31:0]               wdata,
    output wire [31:0]               rdata,

    input  wire                      b_en,    // read port B this cycle
    input  wire [$clog2(DEPTH)-1:0]  b_addr,
    output wire [31:0]               b_rdata
);

// check configuration
initial begin
    if (WIDTH < 1 || WIDTH > 32 || DEPTH < 2) begin
        $error("Error: need 1 <= WIDTH <= 32 and DEPTH >= 2 (instance %m)");
        $finish;
    end
end

// no_rw_check: a read in the cycle of a write to the same entry may see either word (yosys then maps the
// two ports on one true dual-port block RAM, not a copy for each read port): port A's reads of a
// write cycle are not used, and nothing writes the code port B reads while it runs
(* no_rw_check *)
reg [WIDTH-1:0] mem[0:DEPTH-1];
reg [WIDTH-1:0] rdata_reg = {WIDTH{1'b0}};
reg [WIDTH-1:0] b_rdata_reg = {WIDTH{1'b0}};

always @(posedge clk) begin
    if (b_en) begin
        b_rdata_reg <= mem[b_addr];
    end
end

generate
    if (INIT_FILE != "") begin : g_init
        initial begin
            $readmemh(INIT_FILE, mem);
        end
    end

    if (WIDTH == 32) begin : g_word
        assign rdata = rdata_reg;
        assign b_rdata = b_rdata_reg;
    end else if (SIGNED) begin : g_signed
        assign rdata = {{(32 - WIDTH){rdata_reg[WIDTH-1]}}, rdata_reg};
        assign b_rdata = {{(32 - WIDTH){b_rdata_reg[WIDTH-1]}}, b_rdata_reg};
    end else begin : g_unsigned
        assign rdata = {{(32 - WIDTH){1'b0}}, rdata_reg};
        assign b_rdata = {{(32 - WIDTH){1'b0}}, b_rdata_reg};
    end
endgenerate

generate
    if (WIDTH == 32) begin : g_lanes
        integer k;

        always @(posedge clk) begin
            if (en) begin
                // byte lanes
                for (k = 0; k < 4; k = k + 1) begin
                    if (wstrb[k]) begin
                        mem[addr][8*k +: 8] <= wdata[8*k +: 8];
                    end
                end
                rdata_reg <= mem[addr];
            end
        end
    end else begin : g_entries
        // a narrow entry takes the low bits of the word
        wire [31-WIDTH:0] wdata_high_unused = wdata[31:WIDTH];

        always @(posedge clk) begin
            if (en) begin
                if (wstrb == 4'b1111) begin
                    // whole entry (sw)
                    mem[addr] <= wdata[WIDTH-1:0];
                end
                rdata_reg <= mem[addr];
            end
        end
    end
endgenerate

endmodule

`resetall
