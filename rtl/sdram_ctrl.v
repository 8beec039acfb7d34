/*
 * wavemesh: SDRAM controller for the ULX3S's 16-bit SDR SDRAM (32 MB: 4 banks x 8192 rows x 512
 * columns), a CPU port with a small cache and a streaming port for the FPGA stage
 *
 * One clock.  The chip's clock is the inverted system clock (sdram_clk = ~clk, an output DDR
 * register at the board's top): the chip samples every command and write datum in the middle of
 * the cycle that drives it, and the read datum of a READ put on the pins at edge E is captured
 * into dq_in_reg at edge E + CAS_LATENCY (valid from the chip's edge before it plus tAC to its
 * edge after it plus tOH).  rtl/README.md, "SDRAM controller", has the timing table.
 *
 * Engine.  Burst length 1 (mode register): every READ or WRITE moves one halfword and a column
 * command can go out every cycle, so a stream runs at one halfword per clock inside a row, any
 * length, and stalls between beats cost nothing.  Each bank keeps its row open until another row
 * of it is needed or a refresh closes them all.  Per bank, down-counters keep ACTIVATE ->
 * READ/WRITE >= tRCD, ACTIVATE -> PRECHARGE >= tRAS, ACTIVATE -> ACTIVATE >= tRC, PRECHARGE ->
 * ACTIVATE/REFRESH >= tRP and WRITE -> PRECHARGE >= tWR; globally ACTIVATE -> ACTIVATE >= tRRD,
 * REFRESH -> anything >= tRFC, LOAD MODE -> anything >= tMRD, and READ -> WRITE leaves the data
 * bus idle until the chip has released it (CAS latency, then tHZ).  A refresh is due a fixed
 * number of cycles after the last one, chosen so that the longest possible wait for the banks
 * still keeps every gap between two REFRESH commands within tREFI.
 *
 * Clients: 0 the CPU port (sdram_cache), 1 the stream reader, 2 the stream writer, 3 the addressed
 * writer.  A client raises req when it can issue a beat; the engine serves the granted client beat
 * by beat (ACTIVATE and PRECHARGE as its addresses need them) until its req drops or, when another
 * client waits, it has issued MAX_RUN beats.  The CPU port wins every arbitration it takes part in
 * (its accesses are short and the CPU waits for them); the streams take turns.
 *
 * Stream reader: a command (halfword address, length) starts it; it issues reads while its FIFO
 * has room for every read in flight (credits: the SDRAM cannot be stalled once a READ is out) and
 * hands the halfwords out in order, tlast on each command's last one.  It holds two commands: the
 * one whose halfwords go out and the next, taken as soon as no second one is held (s_rd_cmd_ready),
 * whose reads follow the first's last READ in the next cycle, so back-to-back commands stream
 * without a gap while the first's data are still on their way; a command of length 0 is taken and
 * dropped; rd_busy while any halfword of a taken command is still to go out.  Stream writer: a
 * command (address, length) takes the next `length` halfwords of the write stream, which may arrive
 * before or after it (they wait in a FIFO); each is written as it is issued, and every written
 * halfword clears its line in the CPU port's cache; it takes a new command once the last one is
 * written (s_wr_cmd_ready, wr_busy).  Addressed writer: every beat carries its own halfword address (tuser),
 * for writers with several interleaved sequences (the filter bank's levels); the beats wait in a
 * FIFO and are written in order, each clearing its cache line too; wa_busy while any waits.
 *
 * Stage sync: a `sync` pulse (the SoC's SYS.STAGE write, with the CPU held) brings the controller to
 * one fixed state in a fixed time, so that what the CPU and the streams do next takes the same
 * cycles whatever ran before.  The engine lets the CPU port finish its fill or posted write, grants
 * no stream, precharges all banks and refreshes, and empties the CPU port's cache at the pulse (a
 * new epoch, and its sweep of C_SWEEP entries meanwhile); `sync_busy` stays high for exactly
 * C_SYNC + 1 cycles (the longest that can take), and at its end every timing counter is zero, every
 * bank idle, the arbitration as after reset, the CPU port's cache empty, and the refresh counter set as
 * if that REFRESH had been at the pulse (it came later, so every gap stays within tREFI and the
 * next refresh comes a fixed number of cycles after the sync).  A sync before the initialisation
 * is done lasts until the chip is ready (in the same state).
 *
 * Reset (synchronous, active high) restarts the chip's initialisation without the power-up wait
 * once it has been done (powered_reg is never reset) and drops every stream command and read in
 * flight; the timing counters keep counting through it, so a reset never shortens a timing.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module sdram_ctrl #
(
    // system clock in Hz (the chip's clock is its inverse)
    parameter CLK_HZ = 25000000,
    // CAS latency, 2 or 3 (2 is allowed up to 100 MHz on the ULX3S's parts)
    parameter CAS_LATENCY = 2,
    // row and column address bits (13 and 9: 16 M x 16; 10 columns for the 64 MB AS4C32M16SB)
    parameter ROW_BITS = 13,
    parameter COL_BITS = 9,
    // timings in ns (the worst of MT48LC16M16A2-75, IS42S16160G-7, AS4C32M16SB-7) or clocks (_CK)
    parameter T_INIT_NS = 200000,   // power-up: NOP for at least this long
    parameter INIT_REFRESHES = 8,   // AUTO REFRESH commands in the initialisation, >= 2
    parameter T_RCD_NS = 21,
    parameter T_RP_NS = 21,
    parameter T_RAS_NS = 44,
    parameter T_RC_NS = 66,
    parameter T_RFC_NS = 70,
    parameter T_RRD_NS = 15,
    parameter T_WR_NS = 15,
    parameter T_WR_MIN_CK = 2,
    parameter T_MRD_CK = 2,
    parameter T_HZ_NS = 6,          // data-out high-impedance time after the last read datum
    parameter T_REFI_NS = 7812,     // 8192 refreshes per 64 ms
    // stream FIFOs in halfwords, >= 2
    parameter RD_FIFO_DEPTH = 16,
    parameter WR_FIFO_DEPTH = 16,
    parameter WA_FIFO_DEPTH = 16,
    // beats a client may issue while another waits, 1..256
    parameter MAX_RUN = 16,
    // CPU cache: lines (power of two >= 2) of LINE_WORDS 32-bit words (power of two)
    parameter CACHE_LINES = 16,
    parameter LINE_WORDS = 4
)
(
    input  wire                            clk,
    input  wire                            rst,

    /*
     * CPU port (PicoRV32 native memory interface; byte address)
     */
    input  wire                            cpu_valid,
    input  wire [ROW_BITS+COL_BITS+2:0]    cpu_addr,
    input  wire [31:0]                     cpu_wdata,
    input  wire [3:0]                      cpu_wstrb,
    output wire                            cpu_ready,
    output wire [31:0]                     cpu_rdata,

    /*
     * Stream reader: command (halfword address, length in halfwords), data out
     */
    input  wire [ROW_BITS+COL_BITS+1:0]    s_rd_cmd_addr,
    input  wire [ROW_BITS+COL_BITS+2:0]    s_rd_cmd_len,
    input  wire                            s_rd_cmd_valid,
    output wire                            s_rd_cmd_ready,
    output wire [15:0]                     m_axis_rd_tdata,
    output wire                            m_axis_rd_tvalid,
    input  wire                            m_axis_rd_tready,
    output wire                            m_axis_rd_tlast,

    /*
     * Stream writer: command (halfword address, length in halfwords), data in
     */
    input  wire [ROW_BITS+COL_BITS+1:0]    s_wr_cmd_addr,
    input  wire [ROW_BITS+COL_BITS+2:0]    s_wr_cmd_len,
    input  wire                            s_wr_cmd_valid,
    output wire                            s_wr_cmd_ready,
    input  wire [15:0]                     s_axis_wr_tdata,
    input  wire                            s_axis_wr_tvalid,
    output wire                            s_axis_wr_tready,

    /*
     * Addressed writer: halfword and its address per beat
     */
    input  wire [15:0]                     s_axis_wa_tdata,
    input  wire [ROW_BITS+COL_BITS+1:0]    s_axis_wa_tuser,
    input  wire                            s_axis_wa_tvalid,
    output wire                            s_axis_wa_tready,

    /*
     * Status
     */
    output wire                            init_done,
    output wire                            rd_busy,
    output wire                            wr_busy,
    output wire                            wa_busy,

    /*
     * Stage sync: a pulse starts it; the CPU port must stay idle until sync_busy falls
     */
    input  wire                            sync,
    output wire                            sync_busy,

    /*
     * SDRAM pins (the tristate DQ buffer is at the board's top)
     */
    output wire                            sdram_cke,
    output wire                            sdram_cs_n,
    output wire                            sdram_ras_n,
    output wire                            sdram_cas_n,
    output wire                            sdram_we_n,
    output wire [1:0]                      sdram_ba,
    output wire [ROW_BITS-1:0]             sdram_a,
    output wire [1:0]                      sdram_dqm,
    output wire [15:0]                     sdram_dq_o,
    output wire                            sdram_dq_oe,
    input  wire [15:0]                     sdram_dq_i
);

localparam ADDR_BITS = ROW_BITS + 2 + COL_BITS;   // halfword address: {row, bank, column}
localparam LEN_BITS = ADDR_BITS + 1;

// clock cycles of the timings: ceil(ns * CLK_HZ / 1e9), at least min_ck
localparam [63:0] HZ = {32'd0, CLK_HZ[31:0]};
function integer cycles;
    input integer ns;
    input integer min_ck;
    reg [63:0] c;
    begin
        c = ({32'd0, ns} * HZ + 64'd999999999) / 64'd1000000000;
        cycles = c < {32'd0, min_ck} ? min_ck : c[31:0];
    end
endfunction

localparam C_INIT = cycles(T_INIT_NS, 1);
localparam C_RCD = cycles(T_RCD_NS, 1);
localparam C_RP = cycles(T_RP_NS, 1);
localparam C_RAS = cycles(T_RAS_NS, 1);
localparam C_RC = cycles(T_RC_NS, 1);
localparam C_RFC = cycles(T_RFC_NS, 1);
localparam C_RRD = cycles(T_RRD_NS, 1);
localparam C_WR = cycles(T_WR_NS, T_WR_MIN_CK);
localparam C_MRD = T_MRD_CK < 1 ? 1 : T_MRD_CK;
// READ at edge E: the chip drives DQ until its edge E + CL + 1/2 plus tHZ; a WRITE drives from its
// own edge on: ceil(1/2 + tHZ / T) cycles after the datum's capture edge
localparam [63:0] HZ_SPILL = (2 * T_HZ_NS * HZ + 64'd1000000000 + 64'd1999999999) / 64'd2000000000;
localparam C_RD_TO_WR = CAS_LATENCY + HZ_SPILL[31:0];
// the longest wait from "refresh due" to the REFRESH command: the open banks' tRAS or tWR, then
// tRP and tRC, one cycle to leave the run state, one of margin
localparam C_REF_SLACK = (C_RAS > C_WR ? C_RAS : C_WR) + C_RP + C_RC + 2;
localparam [63:0] REFI = T_REFI_NS * HZ / 64'd1000000000;     // whole cycles within tREFI
localparam C_REFI = REFI[31:0];
localparam C_REF_DUE = C_REFI - 1 - C_REF_SLACK;
// the stage sync's window: the longest time from `sync` to the quiet state: a refresh already due
// (C_REF_SLACK to its REFRESH, then tRFC), the CPU port's last work (its row closed and opened
// again, a line's beats, the last datum back), the sync's own PRECHARGE ALL and REFRESH, the READ ->
// WRITE turnaround, and a cycle of arbitration or state change between each (checked in simulation
// and by tests/rtl/sdram_tb.py, test_stage_sync)
localparam C_ROW = (C_RAS > C_WR ? C_RAS : C_WR) + C_RP + C_RC + C_RCD;
// The CPU port's cache is emptied at the pulse (a new epoch) and clears C_SWEEP of its entries
// meanwhile, a cycle each (sdram_cache, "Flush"), well within the window
localparam CACHE_EPOCH_BITS = 7;
localparam C_SWEEP = (CACHE_LINES + (1 << CACHE_EPOCH_BITS) - 2) / ((1 << CACHE_EPOCH_BITS) - 1);
localparam C_SYNC_WORK = 2 * (C_REF_SLACK + C_RFC) + C_ROW + 2 * LINE_WORDS + CAS_LATENCY + C_RD_TO_WR + 8;
localparam C_SYNC = C_SYNC_WORK > C_SWEEP + 2 ? C_SYNC_WORK : C_SWEEP + 2;

localparam CNT_BITS = 6;                                      // per-bank and tRRD/turnaround counters
localparam WAIT_BITS = $clog2(C_INIT + C_RFC + C_MRD + 1);
localparam REF_BITS = $clog2(C_REFI + 1);
localparam SYNC_BITS = $clog2(C_SYNC + 1);
localparam INIT_REF_BITS = $clog2(INIT_REFRESHES + 1);
localparam RL = CAS_LATENCY;                                  // READ to the datum in dq_in_reg

// check configuration
initial begin
    if (CAS_LATENCY < 2 || CAS_LATENCY > 3 || ROW_BITS < 11 || ROW_BITS > 13 || COL_BITS < 8
            || COL_BITS > 10 || INIT_REFRESHES < 2 || RD_FIFO_DEPTH < 2 || WR_FIFO_DEPTH < 2
            || WA_FIFO_DEPTH < 2
            || MAX_RUN < 1 || MAX_RUN > 256) begin
        $error("Error: unsupported SDRAM geometry or controller parameters (instance %m)");
        $finish;
    end
    if (C_RCD > 63 || C_RP > 63 || C_RAS > 63 || C_RC > 63 || C_RRD > 63 || C_WR > 63
            || C_RD_TO_WR > 63 || C_REF_DUE < 16 || C_REF_DUE < 2 * C_SYNC) begin
        $error("Error: CLK_HZ out of range for these timings (instance %m)");
        $finish;
    end
end

// commands {cs_n, ras_n, cas_n, we_n}
localparam [3:0] CMD_INHIBIT = 4'b1111, CMD_NOP = 4'b0111, CMD_ACT = 4'b0011, CMD_READ = 4'b0101,
                 CMD_WRITE = 4'b0100, CMD_PRE = 4'b0010, CMD_REF = 4'b0001, CMD_MRS = 4'b0000;
// mode register: write bursts as programmed, CAS latency, sequential, burst length 1
localparam [2:0] MODE_CL = CAS_LATENCY[2:0];
localparam [12:0] MODE = {3'b000, 1'b0, 2'b00, MODE_CL, 1'b0, 3'b000};

localparam [2:0] S_POWERUP = 3'd0, S_INIT_PRE = 3'd1, S_INIT_REF = 3'd2, S_INIT_MRS = 3'd3,
                 S_RUN = 3'd4, S_REF = 3'd5;

// counter loads: a command at cycle c allows the next one at c + C_x, so the counter starts at C_x - 1
localparam [CNT_BITS-1:0] N_RCD = C_RCD[CNT_BITS-1:0] - 1'b1, N_RP = C_RP[CNT_BITS-1:0] - 1'b1,
                          N_RAS = C_RAS[CNT_BITS-1:0] - 1'b1, N_RC = C_RC[CNT_BITS-1:0] - 1'b1,
                          N_RRD = C_RRD[CNT_BITS-1:0] - 1'b1, N_WR = C_WR[CNT_BITS-1:0] - 1'b1,
                          N_RD_TO_WR = C_RD_TO_WR[CNT_BITS-1:0] - 1'b1;
localparam [WAIT_BITS-1:0] N_INIT = C_INIT[WAIT_BITS-1:0] - 1'b1, N_RFC = C_RFC[WAIT_BITS-1:0] - 1'b1,
                           N_MRD = C_MRD[WAIT_BITS-1:0] - 1'b1;
localparam [REF_BITS-1:0] N_REF_DUE = C_REF_DUE[REF_BITS-1:0];
// after a sync: the cycles since the pulse (sync_busy's C_SYNC + 1, then this cycle)
localparam C_SYNC_SINCE = C_SYNC + 2;
localparam [REF_BITS-1:0] N_SYNC_SINCE = C_SYNC_SINCE[REF_BITS-1:0];
localparam [SYNC_BITS-1:0] N_SYNC = C_SYNC[SYNC_BITS-1:0];
localparam [INIT_REF_BITS-1:0] N_INIT_REFS = INIT_REFRESHES;
localparam [7:0] N_RUN = MAX_RUN[7:0] - 1'b1;                 // 256 -> 255

/*
 * Engine state
 */
reg [2:0] state_reg = S_POWERUP, state_next;
reg powered_reg = 1'b0, powered_next;                         // the power-up wait is done
reg [WAIT_BITS-1:0] wait_reg = N_INIT, wait_next;             // no command while nonzero
reg [INIT_REF_BITS-1:0] init_refs_reg = N_INIT_REFS, init_refs_next;
reg [REF_BITS-1:0] since_ref_reg = {REF_BITS{1'b0}}, since_ref_next;   // cycles since REFRESH
reg done_reg = 1'b0, done_next;
// stage sync: under way, cycles left of its window, its REFRESH issued
reg sync_reg = 1'b0, sync_next;
reg [SYNC_BITS-1:0] sync_left_reg = {SYNC_BITS{1'b0}}, sync_left_next;
reg sync_refd_reg = 1'b0, sync_refd_next;

// banks: open flag, open row, timing counters (4 banks, flattened)
reg [3:0] open_reg = 4'b0000, open_next;
reg [4*ROW_BITS-1:0] row_reg = {4*ROW_BITS{1'b0}}, row_next;
reg [4*CNT_BITS-1:0] rcd_reg = {4*CNT_BITS{1'b0}}, rcd_next;
reg [4*CNT_BITS-1:0] ras_reg = {4*CNT_BITS{1'b0}}, ras_next;
reg [4*CNT_BITS-1:0] rc_reg = {4*CNT_BITS{1'b0}}, rc_next;
reg [4*CNT_BITS-1:0] rp_reg = {4*CNT_BITS{1'b0}}, rp_next;
reg [4*CNT_BITS-1:0] wr_reg = {4*CNT_BITS{1'b0}}, wr_next;
reg [CNT_BITS-1:0] rrd_reg = {CNT_BITS{1'b0}}, rrd_next;
reg [CNT_BITS-1:0] turn_reg = {CNT_BITS{1'b0}}, turn_next;    // READ -> WRITE

// arbitration
reg granted_reg = 1'b0, granted_next;
reg [1:0] grant_reg = 2'd0, grant_next;
reg [1:0] last_reg = 2'd3, last_next;                         // the stream with the last turn
reg [7:0] run_reg = 8'd0, run_next;

// reads in flight: valid and client per cycle since the READ
reg [RL:0] rd_pipe_reg = {(RL+1){1'b0}}, rd_pipe_next;
reg [2*RL+1:0] rd_client_reg = {(2*RL+2){1'b0}}, rd_client_next;

// pins (registered)
reg [3:0] cmd_reg = CMD_INHIBIT, cmd_next;
reg [1:0] ba_reg = 2'b00, ba_next;
reg [12:0] a_reg = 13'd0, a_next;
reg [1:0] dqm_reg = 2'b11, dqm_next;
reg [15:0] dq_o_reg = 16'd0, dq_o_next;
reg dq_oe_reg = 1'b0, dq_oe_next;
reg [15:0] dq_in_reg = 16'd0;

/*
 * Clients
 */
wire [3:0] req;
wire [3:0] we;
wire [4*ADDR_BITS-1:0] addr;
wire [63:0] wdata;
wire [7:0] wmask;
reg [3:0] ack;
reg do_act, do_pre, do_write;   // the engine's command for the granted bank this cycle
wire cache_idle;                // the CPU port has no fill and no posted write under way
wire cache_flushing;            // the CPU port's cache sweeps its entries (after a sync's pulse)
wire rvalid = rd_pipe_reg[RL];
reg [ADDR_BITS-1:0] wr_addr_reg = {ADDR_BITS{1'b0}};           // the stream writer's next halfword
wire [ADDR_BITS-1:0] wa_fifo_addr;                              // the addressed writer's next one
wire [1:0] rclient = rd_client_reg[2*RL +: 2];

// client 0: the CPU port
sdram_cache #(
    .HW_ADDR_BITS(ADDR_BITS),
    .LINES(CACHE_LINES),
    .LINE_WORDS(LINE_WORDS),
    .EPOCH_BITS(CACHE_EPOCH_BITS),
    .SWEEP(C_SWEEP)
) cache_inst (
    .clk(clk),
    .rst(rst),
    .cpu_valid(cpu_valid),
    .cpu_addr(cpu_addr),
    .cpu_wdata(cpu_wdata),
    .cpu_wstrb(cpu_wstrb),
    .cpu_ready(cpu_ready),
    .cpu_rdata(cpu_rdata),
    .snoop_valid(ack[2] || ack[3]),
    .snoop_addr(ack[3] ? wa_fifo_addr : wr_addr_reg),
    .flush(sync),
    .flushing(cache_flushing),
    .idle(cache_idle),
    .m_req(req[0]),
    .m_we(we[0]),
    .m_addr(addr[0 +: ADDR_BITS]),
    .m_wdata(wdata[0 +: 16]),
    .m_wmask(wmask[0 +: 2]),
    .m_ack(ack[0]),
    .s_rvalid(rvalid && rclient == 2'd0),
    .s_rdata(dq_in_reg)
);

// client 1: the stream reader
localparam RD_CREDIT_BITS = $clog2(RD_FIFO_DEPTH + 1);
localparam [RD_CREDIT_BITS-1:0] RD_CREDITS = RD_FIFO_DEPTH;
reg [ADDR_BITS-1:0] rd_addr_reg = {ADDR_BITS{1'b0}};
reg [LEN_BITS-1:0] rd_issue_reg = {LEN_BITS{1'b0}};          // reads still to issue
reg [LEN_BITS-1:0] rd_out_reg = {LEN_BITS{1'b0}};            // halfwords still to hand out (first command)
reg [LEN_BITS-1:0] rd_next_reg = {LEN_BITS{1'b0}};           // the second command's length (0: none)
reg [ADDR_BITS-1:0] rd_next_addr_reg = {ADDR_BITS{1'b0}};    // its address while it waits to issue
reg rd_wait_reg = 1'b0;                                       // the second command waits to issue
reg [RD_CREDIT_BITS-1:0] rd_credit_reg = RD_CREDITS;         // FIFO places not yet promised
wire rd_fifo_in_ready;
wire rd_beat = m_axis_rd_tvalid && m_axis_rd_tready;
wire rd_cmd = s_rd_cmd_valid && s_rd_cmd_ready;
wire rd_cmd_nz = rd_cmd && s_rd_cmd_len != {LEN_BITS{1'b0}};   // a length of 0 is taken and dropped
// the first command's last halfword goes out this cycle
wire rd_head_done = rd_beat && rd_out_reg == {{(LEN_BITS-1){1'b0}}, 1'b1};
// the command issuing now has no read left after this cycle
wire rd_issue_free = rd_issue_reg == {LEN_BITS{1'b0}} || (rd_issue_reg == {{(LEN_BITS-1){1'b0}}, 1'b1} && ack[1]);
wire [RD_CREDIT_BITS-1:0] rd_count_unused;

assign req[1] = rd_issue_reg != {LEN_BITS{1'b0}} && rd_credit_reg != {RD_CREDIT_BITS{1'b0}};
assign we[1] = 1'b0;
assign addr[ADDR_BITS +: ADDR_BITS] = rd_addr_reg;
assign wdata[16 +: 16] = 16'd0;
assign wmask[2 +: 2] = 2'b00;
// a queue of two commands: the next is taken while no second one is queued (rd_next_reg != 0 only
// while rd_out_reg != 0); its reads follow the first's without a gap
assign s_rd_cmd_ready = rd_next_reg == {LEN_BITS{1'b0}};
assign rd_busy = rd_out_reg != {LEN_BITS{1'b0}};
assign m_axis_rd_tlast = rd_out_reg == {{(LEN_BITS-1){1'b0}}, 1'b1};

wm_fifo #(
    .DATA_WIDTH(16),
    .DEPTH(RD_FIFO_DEPTH)
) rd_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(dq_in_reg),
    .s_valid(rvalid && rclient == 2'd1),
    .s_ready(rd_fifo_in_ready),
    .m_data(m_axis_rd_tdata),
    .m_valid(m_axis_rd_tvalid),
    .m_ready(m_axis_rd_tready),
    .count(rd_count_unused)
);

always @(posedge clk) begin
    // the reads to issue: the new command's once the last one's are all issued, else it waits (then
    // it follows in the cycle after the last one's last READ)
    if (rd_cmd_nz && rd_issue_free) begin
        rd_addr_reg <= s_rd_cmd_addr;
        rd_issue_reg <= s_rd_cmd_len;
    end else if (rd_wait_reg && rd_issue_free) begin
        rd_addr_reg <= rd_next_addr_reg;
        rd_issue_reg <= rd_next_reg;
        rd_wait_reg <= 1'b0;
    end else if (ack[1]) begin
        rd_addr_reg <= rd_addr_reg + 1'b1;
        rd_issue_reg <= rd_issue_reg - 1'b1;
    end
    if (rd_cmd_nz && !rd_issue_free) begin
        rd_next_addr_reg <= s_rd_cmd_addr;
        rd_wait_reg <= 1'b1;
    end
    // the halfwords to hand out: the first command's, then the second's
    if (rd_cmd_nz && (rd_out_reg == {LEN_BITS{1'b0}} || rd_head_done)) begin
        rd_out_reg <= s_rd_cmd_len;
    end else if (rd_head_done) begin
        rd_out_reg <= rd_next_reg;
        rd_next_reg <= {LEN_BITS{1'b0}};
    end else if (rd_beat) begin
        rd_out_reg <= rd_out_reg - 1'b1;
    end
    if (rd_cmd_nz && rd_out_reg != {LEN_BITS{1'b0}} && !rd_head_done) begin
        rd_next_reg <= s_rd_cmd_len;
    end
    rd_credit_reg <= rd_credit_reg - {{(RD_CREDIT_BITS-1){1'b0}}, ack[1]}
                     + {{(RD_CREDIT_BITS-1){1'b0}}, rd_beat};

    if (rst) begin
        rd_issue_reg <= {LEN_BITS{1'b0}};
        rd_out_reg <= {LEN_BITS{1'b0}};
        rd_next_reg <= {LEN_BITS{1'b0}};
        rd_wait_reg <= 1'b0;
        rd_credit_reg <= RD_CREDITS;
    end
end

// synthesis translate_off
always @(posedge clk) begin
    if (!rst && rvalid && rclient == 2'd1 && !rd_fifo_in_ready) begin
        $display("Error: sdram_ctrl: read FIFO full at a returning read (credits broken) (%m)");
    end
end
// synthesis translate_on

// client 2: the stream writer
reg [LEN_BITS-1:0] wr_left_reg = {LEN_BITS{1'b0}};            // halfwords still to write
wire wr_fifo_valid;
wire [15:0] wr_fifo_data;
wire [$clog2(WR_FIFO_DEPTH+1)-1:0] wr_count_unused;

assign req[2] = wr_left_reg != {LEN_BITS{1'b0}} && wr_fifo_valid;
assign we[2] = 1'b1;
assign addr[2*ADDR_BITS +: ADDR_BITS] = wr_addr_reg;
assign wdata[32 +: 16] = wr_fifo_data;
assign wmask[4 +: 2] = 2'b00;
assign s_wr_cmd_ready = wr_left_reg == {LEN_BITS{1'b0}};
assign wr_busy = !s_wr_cmd_ready;

wm_fifo #(
    .DATA_WIDTH(16),
    .DEPTH(WR_FIFO_DEPTH)
) wr_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(s_axis_wr_tdata),
    .s_valid(s_axis_wr_tvalid),
    .s_ready(s_axis_wr_tready),
    .m_data(wr_fifo_data),
    .m_valid(wr_fifo_valid),
    .m_ready(ack[2]),
    .count(wr_count_unused)
);

always @(posedge clk) begin
    if (s_wr_cmd_valid && s_wr_cmd_ready) begin
        wr_addr_reg <= s_wr_cmd_addr;
        wr_left_reg <= s_wr_cmd_len;
    end else if (ack[2]) begin
        wr_addr_reg <= wr_addr_reg + 1'b1;
        wr_left_reg <= wr_left_reg - 1'b1;
    end

    if (rst) begin
        wr_left_reg <= {LEN_BITS{1'b0}};
    end
end

// client 3: the addressed writer
wire wa_fifo_valid;
wire [15:0] wa_fifo_data;
wire [$clog2(WA_FIFO_DEPTH+1)-1:0] wa_count_unused;

assign req[3] = wa_fifo_valid;
assign we[3] = 1'b1;
assign addr[3*ADDR_BITS +: ADDR_BITS] = wa_fifo_addr;
assign wdata[48 +: 16] = wa_fifo_data;
assign wmask[6 +: 2] = 2'b00;
assign wa_busy = wa_fifo_valid;

wm_fifo #(
    .DATA_WIDTH(16 + ADDR_BITS),
    .DEPTH(WA_FIFO_DEPTH)
) wa_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data({s_axis_wa_tuser, s_axis_wa_tdata}),
    .s_valid(s_axis_wa_tvalid),
    .s_ready(s_axis_wa_tready),
    .m_data({wa_fifo_addr, wa_fifo_data}),
    .m_valid(wa_fifo_valid),
    .m_ready(ack[3]),
    .count(wa_count_unused)
);

/*
 * Engine
 */
// the granted client's beat
// (a multiplexer per field: an index times ADDR_BITS would become a multiplier)
reg [ADDR_BITS-1:0] g_addr;
reg [15:0] g_wdata;
reg [1:0] g_wmask;
always @* begin
    case (grant_reg)
        2'd0: {g_addr, g_wdata, g_wmask} = {addr[0 +: ADDR_BITS], wdata[0 +: 16], wmask[0 +: 2]};
        2'd1: {g_addr, g_wdata, g_wmask} = {addr[ADDR_BITS +: ADDR_BITS], wdata[16 +: 16], wmask[2 +: 2]};
        2'd2: {g_addr, g_wdata, g_wmask} = {addr[2*ADDR_BITS +: ADDR_BITS], wdata[32 +: 16], wmask[4 +: 2]};
        default: {g_addr, g_wdata, g_wmask} = {addr[3*ADDR_BITS +: ADDR_BITS], wdata[48 +: 16], wmask[6 +: 2]};
    endcase
end
wire g_we = we[grant_reg];
wire [1:0] g_bank = g_addr[COL_BITS +: 2];
wire [ROW_BITS-1:0] g_row = g_addr[COL_BITS+2 +: ROW_BITS];
wire [COL_BITS-1:0] g_col = g_addr[COL_BITS-1:0];
wire g_req = granted_reg && req[grant_reg];

// per-bank "may issue" flags
reg [3:0] rcd_ok, ras_ok, rc_ok, rp_ok, wr_ok;
integer k;
always @* begin
    for (k = 0; k < 4; k = k + 1) begin
        rcd_ok[k] = rcd_reg[k*CNT_BITS +: CNT_BITS] == {CNT_BITS{1'b0}};
        ras_ok[k] = ras_reg[k*CNT_BITS +: CNT_BITS] == {CNT_BITS{1'b0}};
        rc_ok[k] = rc_reg[k*CNT_BITS +: CNT_BITS] == {CNT_BITS{1'b0}};
        rp_ok[k] = rp_reg[k*CNT_BITS +: CNT_BITS] == {CNT_BITS{1'b0}};
        wr_ok[k] = wr_reg[k*CNT_BITS +: CNT_BITS] == {CNT_BITS{1'b0}};
    end
end
wire all_pre_ok = &(ras_ok & wr_ok);
wire all_ref_ok = &(rp_ok & rc_ok);
// the state a stage sync ends in: no command may wait for anything
wire quiet = state_reg == S_RUN && wait_reg == {WAIT_BITS{1'b0}} && open_reg == 4'b0000
             && &(rcd_ok & ras_ok & rc_ok & rp_ok & wr_ok) && rrd_reg == {CNT_BITS{1'b0}}
             && turn_reg == {CNT_BITS{1'b0}} && rd_pipe_reg == {(RL+1){1'b0}} && cache_idle
             && !cache_flushing;
wire sync_end = sync_reg && sync_left_reg == {SYNC_BITS{1'b0}} && sync_refd_reg && quiet;
wire wait_ok = wait_reg == {WAIT_BITS{1'b0}};
wire ref_due = since_ref_reg >= N_REF_DUE;
wire g_open = open_reg[g_bank];
reg [ROW_BITS-1:0] g_open_row;
always @* begin
    g_open_row = row_reg[0 +: ROW_BITS];
    for (k = 1; k < 4; k = k + 1) begin
        if (g_bank == k[1:0]) begin
            g_open_row = row_reg[k*ROW_BITS +: ROW_BITS];
        end
    end
end
wire g_hit = g_open && g_open_row == g_row;
// another client waits (for the run limit)
wire others = (req & ~(4'b0001 << grant_reg)) != 4'b0000;
// the streams in turn: the first one asking after the one that had the last turn
reg [1:0] next_stream;
always @* begin
    case (last_reg)
        2'd1: next_stream = req[2] ? 2'd2 : (req[3] ? 2'd3 : 2'd1);
        2'd2: next_stream = req[3] ? 2'd3 : (req[1] ? 2'd1 : 2'd2);
        default: next_stream = req[1] ? 2'd1 : (req[2] ? 2'd2 : 2'd3);
    endcase
end

always @* begin
    state_next = state_reg;
    powered_next = powered_reg;
    wait_next = wait_ok ? wait_reg : wait_reg - 1'b1;
    init_refs_next = init_refs_reg;
    since_ref_next = since_ref_reg == {REF_BITS{1'b1}} ? since_ref_reg : since_ref_reg + 1'b1;
    done_next = done_reg;
    sync_next = sync_reg;
    sync_left_next = sync_left_reg == {SYNC_BITS{1'b0}} ? sync_left_reg : sync_left_reg - 1'b1;
    sync_refd_next = sync_refd_reg;
    open_next = open_reg;
    row_next = row_reg;
    for (k = 0; k < 4; k = k + 1) begin
        rcd_next[k*CNT_BITS +: CNT_BITS] = rcd_ok[k] ? {CNT_BITS{1'b0}} : rcd_reg[k*CNT_BITS +: CNT_BITS] - 1'b1;
        ras_next[k*CNT_BITS +: CNT_BITS] = ras_ok[k] ? {CNT_BITS{1'b0}} : ras_reg[k*CNT_BITS +: CNT_BITS] - 1'b1;
        rc_next[k*CNT_BITS +: CNT_BITS] = rc_ok[k] ? {CNT_BITS{1'b0}} : rc_reg[k*CNT_BITS +: CNT_BITS] - 1'b1;
        rp_next[k*CNT_BITS +: CNT_BITS] = rp_ok[k] ? {CNT_BITS{1'b0}} : rp_reg[k*CNT_BITS +: CNT_BITS] - 1'b1;
        wr_next[k*CNT_BITS +: CNT_BITS] = wr_ok[k] ? {CNT_BITS{1'b0}} : wr_reg[k*CNT_BITS +: CNT_BITS] - 1'b1;
    end
    rrd_next = rrd_reg == {CNT_BITS{1'b0}} ? rrd_reg : rrd_reg - 1'b1;
    turn_next = turn_reg == {CNT_BITS{1'b0}} ? turn_reg : turn_reg - 1'b1;
    granted_next = granted_reg;
    grant_next = grant_reg;
    last_next = last_reg;
    run_next = run_reg;
    rd_pipe_next = {rd_pipe_reg[RL-1:0], 1'b0};
    rd_client_next = {rd_client_reg[2*RL-1:0], 2'b00};
    cmd_next = CMD_NOP;
    ba_next = ba_reg;
    a_next = a_reg;
    dqm_next = 2'b00;
    dq_o_next = dq_o_reg;
    dq_oe_next = 1'b0;
    ack = 4'b0000;
    do_act = 1'b0;
    do_pre = 1'b0;
    do_write = 1'b0;

    case (state_reg)
        S_POWERUP: begin
            // power-up: COMMAND INHIBIT for T_INIT_NS
            cmd_next = CMD_INHIBIT;
            dqm_next = 2'b11;
            if (wait_ok) begin
                powered_next = 1'b1;
                state_next = S_INIT_PRE;
            end
        end
        S_INIT_PRE: begin
            // PRECHARGE ALL (after a reset: once the open banks' tRAS and tWR have passed)
            dqm_next = 2'b11;
            if (wait_ok && all_pre_ok) begin
                cmd_next = CMD_PRE;
                a_next = 13'd1 << 10;
                open_next = 4'b0000;
                for (k = 0; k < 4; k = k + 1) begin
                    rp_next[k*CNT_BITS +: CNT_BITS] = N_RP;
                end
                init_refs_next = N_INIT_REFS;
                state_next = S_INIT_REF;
            end
        end
        S_INIT_REF: begin
            // INIT_REFRESHES x AUTO REFRESH, tRFC apart
            dqm_next = 2'b11;
            if (wait_ok && all_ref_ok) begin
                cmd_next = CMD_REF;
                wait_next = N_RFC;
                init_refs_next = init_refs_reg - 1'b1;
                if (init_refs_reg == {{(INIT_REF_BITS-1){1'b0}}, 1'b1}) begin
                    state_next = S_INIT_MRS;
                end
            end
        end
        S_INIT_MRS: begin
            // LOAD MODE REGISTER; the refresh interval starts here
            dqm_next = 2'b11;
            if (wait_ok) begin
                cmd_next = CMD_MRS;
                a_next = MODE;
                ba_next = 2'b00;
                wait_next = N_MRD;
                since_ref_next = {REF_BITS{1'b0}};
                done_next = 1'b1;
                granted_next = 1'b0;
                state_next = S_RUN;
            end
        end
        S_RUN: begin
            if (ref_due || (sync_reg && !sync_refd_reg && cache_idle)) begin
                // refresh first (a sync's once the CPU port is done): the grant is given again afterwards
                granted_next = 1'b0;
                state_next = S_REF;
            end else if (!g_req || (run_reg == 8'd0 && others) || (sync_reg && grant_reg != 2'd0)) begin
                // arbitrate (no command this cycle): the CPU port first, the streams in turn, and
                // during a sync the CPU port alone
                granted_next = sync_reg ? req[0] : req != 4'b0000;
                run_next = N_RUN;
                if (req[0]) begin
                    grant_next = 2'd0;
                end else if (req != 4'b0000 && !sync_reg) begin
                    grant_next = next_stream;
                    last_next = next_stream;
                end
            end else if (wait_ok) begin
                if (g_hit) begin
                    // the row is open: READ or WRITE (no auto precharge)
                    if (rcd_ok[g_bank] && (!g_we || turn_reg == {CNT_BITS{1'b0}})) begin
                        cmd_next = g_we ? CMD_WRITE : CMD_READ;
                        ba_next = g_bank;
                        a_next = {{(13-COL_BITS){1'b0}}, g_col};
                        ack[grant_reg] = 1'b1;
                        run_next = run_reg == 8'd0 ? run_reg : run_reg - 1'b1;
                        if (g_we) begin
                            dq_o_next = g_wdata;
                            dq_oe_next = 1'b1;
                            dqm_next = g_wmask;
                            do_write = 1'b1;
                        end else begin
                            rd_pipe_next[0] = 1'b1;
                            rd_client_next[1:0] = grant_reg;
                            turn_next = N_RD_TO_WR;
                        end
                    end
                end else if (g_open) begin
                    // another row is open: PRECHARGE the bank
                    if (ras_ok[g_bank] && wr_ok[g_bank]) begin
                        cmd_next = CMD_PRE;
                        ba_next = g_bank;
                        a_next = 13'd0;
                        open_next[g_bank] = 1'b0;
                        do_pre = 1'b1;
                    end
                end else begin
                    // the bank is idle: ACTIVATE the row
                    if (rp_ok[g_bank] && rc_ok[g_bank] && rrd_reg == {CNT_BITS{1'b0}}) begin
                        cmd_next = CMD_ACT;
                        ba_next = g_bank;
                        a_next = {{(13-ROW_BITS){1'b0}}, g_row};
                        open_next[g_bank] = 1'b1;
                        do_act = 1'b1;
                        rrd_next = N_RRD;
                    end
                end
            end
        end
        default: begin
            // S_REF: PRECHARGE ALL if a bank is open, then AUTO REFRESH
            if (wait_ok) begin
                if (open_reg != 4'b0000) begin
                    if (all_pre_ok) begin
                        cmd_next = CMD_PRE;
                        a_next = 13'd1 << 10;
                        open_next = 4'b0000;
                        for (k = 0; k < 4; k = k + 1) begin
                            rp_next[k*CNT_BITS +: CNT_BITS] = N_RP;
                        end
                    end
                end else if (all_ref_ok) begin
                    cmd_next = CMD_REF;
                    wait_next = N_RFC;
                    since_ref_next = {REF_BITS{1'b0}};
                    // the sync's refresh once the CPU port is done (it stays so: the CPU waits)
                    sync_refd_next = sync_refd_reg || (sync_reg && cache_idle);
                    state_next = S_RUN;
                end
            end
        end
    endcase

    // the stage sync: ends in the quiet state once its window is over; a new pulse starts it again
    if (sync_end) begin
        sync_next = 1'b0;
        since_ref_next = N_SYNC_SINCE;
        granted_next = 1'b0;
        grant_next = 2'd0;
        last_next = 2'd3;
        run_next = 8'd0;
    end
    if (sync) begin
        sync_next = 1'b1;
        sync_left_next = N_SYNC;
        sync_refd_next = 1'b0;
    end

    // the granted bank's counters and row (a loop over constant indices: no multipliers)
    for (k = 0; k < 4; k = k + 1) begin
        if (g_bank == k[1:0]) begin
            if (do_act) begin
                row_next[k*ROW_BITS +: ROW_BITS] = g_row;
                rcd_next[k*CNT_BITS +: CNT_BITS] = N_RCD;
                ras_next[k*CNT_BITS +: CNT_BITS] = N_RAS;
                rc_next[k*CNT_BITS +: CNT_BITS] = N_RC;
            end
            if (do_pre) begin
                rp_next[k*CNT_BITS +: CNT_BITS] = N_RP;
            end
            if (do_write) begin
                wr_next[k*CNT_BITS +: CNT_BITS] = N_WR;
            end
        end
    end
end

always @(posedge clk) begin
    state_reg <= state_next;
    powered_reg <= powered_next;
    wait_reg <= wait_next;
    init_refs_reg <= init_refs_next;
    since_ref_reg <= since_ref_next;
    done_reg <= done_next;
    sync_reg <= sync_next;
    sync_left_reg <= sync_left_next;
    sync_refd_reg <= sync_refd_next;
    open_reg <= open_next;
    row_reg <= row_next;
    rcd_reg <= rcd_next;
    ras_reg <= ras_next;
    rc_reg <= rc_next;
    rp_reg <= rp_next;
    wr_reg <= wr_next;
    rrd_reg <= rrd_next;
    turn_reg <= turn_next;
    granted_reg <= granted_next;
    grant_reg <= grant_next;
    last_reg <= last_next;
    run_reg <= run_next;
    rd_pipe_reg <= rd_pipe_next;
    rd_client_reg <= rd_client_next;
    cmd_reg <= cmd_next;
    ba_reg <= ba_next;
    a_reg <= a_next;
    dqm_reg <= dqm_next;
    dq_o_reg <= dq_o_next;
    dq_oe_reg <= dq_oe_next;
    dq_in_reg <= sdram_dq_i;

    if (rst) begin
        // the chip is initialised again (without the power-up wait once it was done); the timing
        // counters and the wait keep running, so nothing issued before is cut short
        state_reg <= powered_reg ? S_INIT_PRE : S_POWERUP;
        wait_reg <= powered_reg ? wait_next : N_INIT;
        done_reg <= 1'b0;
        granted_reg <= 1'b0;
        sync_reg <= 1'b0;
        sync_left_reg <= {SYNC_BITS{1'b0}};
        sync_refd_reg <= 1'b0;
        rd_pipe_reg <= {(RL+1){1'b0}};
        cmd_reg <= powered_reg ? CMD_NOP : CMD_INHIBIT;
        dq_oe_reg <= 1'b0;
    end
end

assign init_done = done_reg;
assign sync_busy = sync_reg;

// synthesis translate_off
// a sync that started on an initialised chip must end with its window (C_SYNC too short otherwise)
reg sync_timed_reg = 1'b0;
always @(posedge clk) begin
    if (sync) begin
        sync_timed_reg <= done_reg;
    end
    if (!rst && sync_reg && sync_timed_reg && sync_left_reg == {SYNC_BITS{1'b0}} && !sync_end) begin
        $display("Error: sdram_ctrl: stage sync not quiet at the end of its window (%m)");
        sync_timed_reg <= 1'b0;
    end
end
// synthesis translate_on
assign sdram_cke = 1'b1;
assign {sdram_cs_n, sdram_ras_n, sdram_cas_n, sdram_we_n} = cmd_reg;
assign sdram_ba = ba_reg;
assign sdram_a = a_reg[ROW_BITS-1:0];
assign sdram_dqm = dqm_reg;
assign sdram_dq_o = dq_o_reg;
assign sdram_dq_oe = dq_oe_reg;

endmodule

`resetall
