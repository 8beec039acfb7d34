/*
 * wavemesh: the CPU port of the SDRAM controller, a read cache with a posted write
 *
 * Between the PicoRV32's native memory interface and one client port of sdram_ctrl's command
 * engine.  Direct mapped, LINES lines of LINE_WORDS 32-bit words; write through with no write
 * allocate, through a one-word posted write buffer.  Data and tags are both in synchronous RAM
 * (block RAM when large), so the cache's size is not on the clock's path: each line's entry is
 * {valid, epoch, tag}, read at the CPU's index at every edge and compared in the next cycle.
 *
 *   read hit    2 cycles (request, then cpu_ready with the word) when the word is in the last line
 *               that hit or was filled (a register, compared in the request cycle: a run of reads
 *               in one line, such as a line refill of the CPU's own cache, looks the tags up once);
 *               3 cycles otherwise (request, the entry read at its edge compared, cpu_ready)
 *   read miss   decided in the look-up cycle; the line is filled from its first halfword
 *               (2 * LINE_WORDS column reads, issued after any posted write); the word is answered
 *               as soon as its two halfwords are in (early restart), and the CPU's next access waits
 *               for the rest of the line, whose entry is written when it completes
 *   write       taken in 2 cycles into the write buffer when it is empty (else it waits for it);
 *               in the next cycle the entry read at the write's edge is compared, and on a hit the
 *               line's bytes are updated; the buffer writes the word's halfwords that have strobes,
 *               with the others' bytes masked by DQM
 *
 * Coherence with the streaming port: every beat the engine writes for the stream writes an invalid
 * entry at that address's index (without comparing tags; the tag RAM's second port, so it never
 * waits); a line being filled when that happens answers its one pending read and stays invalid, and
 * a look-up whose entry was read at the same edge as such a write misses.  The CPU's own accesses
 * are answered in order; a posted write reaches the SDRAM before any later read of this port is
 * issued.
 *
 * Flush: an entry is valid only when its epoch is the current one, so `flush` (or reset) empties
 * the cache at once by stepping the epoch (when a line was filled since the last step: otherwise no
 * entry is valid in it anyway) and makes a fill under way stale.  An epoch then must not come round
 * again while lines of it are left: every step also clears the next SWEEP entries (round robin,
 * through the second port, a cycle each, stream writes first) before the CPU's next access is
 * looked up, and SWEEP * (2^EPOCH_BITS - 1) >= LINES clears every entry between two uses of an
 * epoch (and at power-up every entry, LINES cycles, well within the SDRAM's power-up wait; the
 * FPGA's block RAMs start at zero anyway).  `flushing` is high while the sweep runs: SWEEP cycles
 * from the pulse when no stream writes; the controller's stage sync pulses `flush` at its start and
 * waits for it, within its fixed window, so that the CPU's accesses after a sync hit and miss alike
 * whatever ran before (write through: no data are lost).
 *
 * CPU interface (PicoRV32 native): the CPU holds cpu_valid, cpu_addr, cpu_wdata, cpu_wstrb until
 * cpu_ready, a one-cycle pulse (with cpu_rdata for a read); a request is a cycle with cpu_valid
 * high and cpu_ready low.  cpu_wstrb = 0 reads.  cpu_addr is a byte address, bits 1:0 ignored;
 * a word holds halfwords 2w (bits 15:0) and 2w + 1 (bits 31:16), DQ[7:0] the lower byte.
 *
 * Engine client (sdram_ctrl, "Engine"): m_req says a beat can be issued now (registered state
 * only); m_ack is high in the cycle the engine issues it; read data come back in issue order on
 * s_rvalid / s_rdata, a fixed number of cycles later.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module sdram_cache #
(
    // halfword address bits of the SDRAM (24 for 16 M x 16)
    parameter HW_ADDR_BITS = 24,
    // lines, a power of two >= 2
    parameter LINES = 16,
    // 32-bit words per line, a power of two >= 1
    parameter LINE_WORDS = 4,
    // epoch bits in each line's entry (>= 1)
    parameter EPOCH_BITS = 7,
    // entries cleared per flush: SWEEP * (2^EPOCH_BITS - 1) >= LINES
    parameter SWEEP = (LINES + (1 << EPOCH_BITS) - 2) / ((1 << EPOCH_BITS) - 1)
)
(
    input  wire                       clk,
    input  wire                       rst,

    /*
     * CPU (PicoRV32 native memory interface)
     */
    input  wire                       cpu_valid,
    input  wire [HW_ADDR_BITS:0]      cpu_addr,
    input  wire [31:0]                cpu_wdata,
    input  wire [3:0]                 cpu_wstrb,
    output wire                       cpu_ready,
    output wire [31:0]                cpu_rdata,

    /*
     * Coherence: clear the line of a halfword the stream writes
     */
    input  wire                       snoop_valid,
    input  wire [HW_ADDR_BITS-1:0]    snoop_addr,

    /*
     * Flush: empty the cache (a pulse, any time); `flushing` while its sweep runs
     */
    input  wire                       flush,
    output wire                       flushing,
    output wire                       idle,

    /*
     * Engine client
     */
    output wire                       m_req,
    output wire                       m_we,
    output wire [HW_ADDR_BITS-1:0]    m_addr,
    output wire [15:0]                m_wdata,
    output wire [1:0]                 m_wmask,
    input  wire                       m_ack,
    input  wire                       s_rvalid,
    input  wire [15:0]                s_rdata
);

localparam OFF_BITS = LINE_WORDS > 1 ? $clog2(LINE_WORDS) : 0;
localparam IDX_BITS = $clog2(LINES);
localparam WADDR_BITS = HW_ADDR_BITS - 1;                     // word address bits
localparam TAG_BITS = WADDR_BITS - OFF_BITS - IDX_BITS;
localparam LINE_BITS = WADDR_BITS - OFF_BITS;                 // {tag, index}
localparam DEPTH = LINES * LINE_WORDS;                         // words held
localparam LINE_HW = 2 * LINE_WORDS;                           // halfwords per line
localparam CNT_BITS = OFF_BITS + 2;                            // counts 0 .. LINE_HW
localparam [CNT_BITS-1:0] CNT_LAST = LINE_HW[CNT_BITS-1:0] - 1'b1;
localparam [CNT_BITS-1:0] CNT_FULL = LINE_HW[CNT_BITS-1:0];
localparam ENTRY_BITS = 1 + EPOCH_BITS + TAG_BITS;             // {valid, epoch, tag}
localparam SW_BITS = $clog2(LINES + 1);
localparam [SW_BITS-1:0] N_SWEEP = SWEEP[SW_BITS-1:0];

// check configuration
initial begin
    if (LINES < 2 || (1 << IDX_BITS) != LINES || LINE_WORDS < 1 || (1 << OFF_BITS) != LINE_WORDS
            || TAG_BITS < 1) begin
        $error("Error: LINES and LINE_WORDS must be powers of two, LINES >= 2 (instance %m)");
        $finish;
    end
    if (EPOCH_BITS < 1 || EPOCH_BITS > 16 || SWEEP < 1 || SWEEP > LINES
            || SWEEP * ((1 << EPOCH_BITS) - 1) < LINES) begin
        $error("Error: SWEEP * (2^EPOCH_BITS - 1) must cover LINES (instance %m)");
        $finish;
    end
end

localparam [1:0] S_IDLE = 2'd0, S_LOOK = 2'd1, S_FILL = 2'd2, S_DONE = 2'd3;

// the CPU's address, split
wire [WADDR_BITS-1:0] cpu_word = cpu_addr[HW_ADDR_BITS:1+1];
wire [1:0] cpu_addr_unused = cpu_addr[1:0];
wire [IDX_BITS-1:0] cpu_index = cpu_word[OFF_BITS +: IDX_BITS];
wire [TAG_BITS-1:0] cpu_tag = cpu_word[WADDR_BITS-1 -: TAG_BITS];
wire [LINE_BITS-1:0] cpu_line = cpu_word[WADDR_BITS-1:OFF_BITS];
wire [IDX_BITS+OFF_BITS-1:0] cpu_slot = cpu_word[IDX_BITS+OFF_BITS-1:0];   // {index, offset}

wire [IDX_BITS-1:0] snoop_index = snoop_addr[1+OFF_BITS +: IDX_BITS];
wire [HW_ADDR_BITS-1:0] snoop_addr_unused = snoop_addr;   // only its index bits matter

// storage (no reset): data and entries read synchronously at the CPU's address
(* no_rw_check *)
reg [ENTRY_BITS-1:0] tag_mem[0:LINES-1];
reg [7:0] lane0_mem[0:DEPTH-1];
reg [7:0] lane1_mem[0:DEPTH-1];
reg [7:0] lane2_mem[0:DEPTH-1];
reg [7:0] lane3_mem[0:DEPTH-1];

reg [1:0] state_reg = S_IDLE, state_next;
reg ready_reg = 1'b0, ready_next;

// the entry read at the last edge, and whether a stream write's entry may not have been in it yet
reg [ENTRY_BITS-1:0] entry_reg = {ENTRY_BITS{1'b0}};
reg entry_snooped_reg = 1'b0;
// a stream write's index, written (invalid) into the entries one cycle later: registered addresses
reg snoop_d_valid_reg = 1'b0;
reg [IDX_BITS-1:0] snoop_d_index_reg = {IDX_BITS{1'b0}};
// the current epoch; a line has been filled in it; entries left to sweep, the next one
reg [EPOCH_BITS-1:0] epoch_reg = {EPOCH_BITS{1'b0}}, epoch_next;
reg used_reg = 1'b0, used_next;
// (at power-up every entry: the CPU's first access waits for it, within the SDRAM's power-up wait)
reg [SW_BITS-1:0] sweep_left_reg = LINES[SW_BITS-1:0], sweep_left_next;
reg [IDX_BITS-1:0] sweep_ptr_reg = {IDX_BITS{1'b0}}, sweep_ptr_next;
// the last line that hit or was filled (valid while its entry is)
reg [LINE_BITS-1:0] mru_line_reg = {LINE_BITS{1'b0}}, mru_line_next;
reg mru_valid_reg = 1'b0, mru_valid_next;

// the line being filled
reg [CNT_BITS-1:0] fill_issue_reg = {CNT_BITS{1'b0}}, fill_issue_next;   // halfwords requested
reg [CNT_BITS-1:0] fill_recv_reg = {CNT_BITS{1'b0}}, fill_recv_next;     // halfwords received
reg fill_stale_reg = 1'b0, fill_stale_next;
reg fill_answered_reg = 1'b0, fill_answered_next;                         // the CPU has its word
reg [LINE_BITS-1:0] fill_line_reg = {LINE_BITS{1'b0}};                    // {tag, index}
wire [IDX_BITS-1:0] fill_index = fill_line_reg[IDX_BITS-1:0];
wire [TAG_BITS-1:0] fill_tag = fill_line_reg[LINE_BITS-1 -: TAG_BITS];
// halfwords in when the CPU's word is complete: 2 * offset + 2
wire [CNT_BITS-1:0] fill_word_in;

// posted write: the word, its strobes, the halfwords still to write {hi, lo}; its entry compared
// in the cycle after it is taken
reg [WADDR_BITS-1:0] wb_word_reg = {WADDR_BITS{1'b0}};
reg [31:0] wb_data_reg = 32'd0;
reg [3:0] wb_strb_reg = 4'd0;
reg [1:0] wb_pend_reg = 2'b00, wb_pend_next;
reg wb_check_reg = 1'b0;

wire sweeping = sweep_left_reg != {SW_BITS{1'b0}};
wire flush_any = flush || rst;
// a request is looked up only when no sweep runs (the CPU waits)
wire request = cpu_valid && !ready_reg && !sweeping;
wire mru_hit = mru_valid_reg && mru_line_reg == cpu_line;
// the entry read at the last edge: valid in this epoch, and its tag
wire entry_live = entry_reg[ENTRY_BITS-1] && entry_reg[TAG_BITS +: EPOCH_BITS] == epoch_reg;
wire [TAG_BITS-1:0] entry_tag = entry_reg[TAG_BITS-1:0];
wire look_hit = entry_live && entry_tag == cpu_tag && !entry_snooped_reg;
wire wb_hit = wb_check_reg && entry_live && entry_tag == wb_word_reg[WADDR_BITS-1 -: TAG_BITS];
// the word at the CPU's address, read at every edge (synchronous: block RAM when the cache is large)
reg [31:0] line_word_reg = 32'd0;

// a write is taken when the buffer is empty
wire take_write = state_reg == S_IDLE && request && cpu_wstrb != 4'd0 && wb_pend_reg == 2'b00;
// fill data: the halfword goes into lanes 1:0 (even) or 3:2 (odd) of word fill_recv / 2
wire fill_write = state_reg == S_FILL && s_rvalid;
// the fill's last halfword: its entry is written unless a stream write or a flush came before (one
// in this cycle clears it in the next, a flush in this cycle steps the epoch past it); only
// registered signals choose the entry RAM's addresses
wire fill_last = fill_write && fill_recv_reg == CNT_LAST;
wire entry_write = fill_last && !fill_stale_reg;
wire fill_valid = entry_write && !(snoop_valid && snoop_index == fill_index) && !flush_any;
wire [IDX_BITS+OFF_BITS-1:0] fill_slot;
generate
    if (OFF_BITS > 0) begin : g_fill_slot
        assign fill_slot = {fill_index, fill_recv_reg[OFF_BITS:1]};
        assign fill_word_in = {1'b0, cpu_word[OFF_BITS-1:0], 1'b0} + {{(CNT_BITS-2){1'b0}}, 2'd2};
    end else begin : g_fill_slot_one
        assign fill_slot = fill_index;
        assign fill_word_in = CNT_FULL;   // one word per line: answered when the line is in
    end
endgenerate
wire [IDX_BITS+OFF_BITS-1:0] wr_slot = fill_write ? fill_slot : wb_word_reg[IDX_BITS+OFF_BITS-1:0];
wire [3:0] wr_lanes = fill_write ? (fill_recv_reg[0] ? 4'b1100 : 4'b0011)
                                 : (wb_hit ? wb_strb_reg : 4'b0000);
wire [31:0] wr_bytes = fill_write ? {s_rdata, s_rdata} : wb_data_reg;
// the entry RAM's ports: A reads at the CPU's index (or writes a filled line's entry), B writes
// invalid entries (stream writes, a cycle later, first; then the sweep)
wire [IDX_BITS-1:0] a_index = entry_write ? fill_index : cpu_index;
wire b_write = snoop_d_valid_reg || sweeping;
wire [IDX_BITS-1:0] b_index = snoop_d_valid_reg ? snoop_d_index_reg : sweep_ptr_reg;

// engine client: the posted write's halfwords first, then the fill's reads
wire wb_lo = wb_pend_reg[0];
assign m_req = wb_pend_reg != 2'b00 || (state_reg == S_FILL && fill_issue_reg != CNT_FULL);
assign m_we = wb_pend_reg != 2'b00;
generate
    if (OFF_BITS > 0) begin : g_fill_addr
        assign m_addr = m_we ? {wb_word_reg, !wb_lo}
                             : {fill_line_reg, fill_issue_reg[OFF_BITS:0]};
    end else begin : g_fill_addr_one
        assign m_addr = m_we ? {wb_word_reg, !wb_lo} : {fill_line_reg, fill_issue_reg[0]};
    end
endgenerate
assign m_wdata = wb_lo ? wb_data_reg[15:0] : wb_data_reg[31:16];
assign m_wmask = wb_lo ? ~wb_strb_reg[1:0] : ~wb_strb_reg[3:2];

assign idle = state_reg == S_IDLE && wb_pend_reg == 2'b00;
assign flushing = sweeping;
assign cpu_ready = ready_reg;
assign cpu_rdata = line_word_reg;   // read at the edge that raised cpu_ready

always @* begin
    state_next = state_reg;
    ready_next = 1'b0;
    fill_issue_next = fill_issue_reg;
    fill_recv_next = fill_recv_reg;
    fill_stale_next = fill_stale_reg;
    fill_answered_next = fill_answered_reg;
    wb_pend_next = wb_pend_reg;
    epoch_next = epoch_reg;
    used_next = used_reg;
    sweep_left_next = sweep_left_reg;
    sweep_ptr_next = sweep_ptr_reg;
    mru_line_next = mru_line_reg;
    mru_valid_next = mru_valid_reg;

    // the posted write: one halfword per acknowledged beat, low first
    if (m_ack && m_we) begin
        wb_pend_next = wb_lo ? {wb_pend_reg[1], 1'b0} : 2'b00;
    end

    case (state_reg)
        S_IDLE: begin
            if (request && cpu_wstrb == 4'd0) begin
                if (mru_hit) begin
                    // read hit in the last line: the word, read at this edge
                    ready_next = 1'b1;
                end else begin
                    // look the entry up: read at this edge, compared in the next cycle
                    state_next = S_LOOK;
                end
            end else if (take_write) begin
                // write: into the buffer; the halfwords with strobes
                wb_pend_next = {cpu_wstrb[3:2] != 2'b00, cpu_wstrb[1:0] != 2'b00};
                ready_next = 1'b1;
            end
        end
        S_LOOK: begin
            if (sweeping) begin
                // a flush came with the request: decide once the sweep is done
            end else if (look_hit) begin
                // read hit: the word, read at this edge; the line is the last one now
                ready_next = 1'b1;
                state_next = S_IDLE;
                mru_line_next = cpu_line;
                mru_valid_next = 1'b1;
            end else begin
                // read miss: fill the line (after the posted write, which goes first)
                state_next = S_FILL;
                mru_valid_next = 1'b0;
                fill_issue_next = {CNT_BITS{1'b0}};
                fill_recv_next = {CNT_BITS{1'b0}};
                fill_stale_next = 1'b0;
                fill_answered_next = 1'b0;
            end
        end
        S_FILL: begin
            if (m_ack && !m_we) begin
                // one more halfword requested
                fill_issue_next = fill_issue_reg + 1'b1;
            end
            if (!fill_answered_reg && fill_recv_reg == fill_word_in) begin
                // early restart: the CPU's word is in (its halfwords written at earlier edges), read
                // at this one; the fill goes on
                ready_next = 1'b1;
                fill_answered_next = 1'b1;
            end
            if (s_rvalid) begin
                // one more halfword in; the last completes the line (and answers the CPU if the
                // word was the line's last): its entry written, the last line
                fill_recv_next = fill_recv_reg + 1'b1;
                if (fill_recv_reg == CNT_LAST) begin
                    state_next = fill_answered_reg ? S_IDLE : S_DONE;
                    if (fill_valid) begin
                        mru_line_next = fill_line_reg;
                        mru_valid_next = 1'b1;
                        used_next = 1'b1;
                    end
                end
            end
        end
        default: begin
            // S_DONE: answer from the filled line (its last halfword was written at the last edge)
            ready_next = 1'b1;
            state_next = S_IDLE;
        end
    endcase

    // coherence: the stream's writes win over a fill's completion
    if (snoop_valid) begin
        if (snoop_index == mru_line_next[IDX_BITS-1:0]) begin
            mru_valid_next = 1'b0;
        end
        if (state_reg == S_FILL && snoop_index == fill_index) begin
            fill_stale_next = 1'b1;
        end
    end

    // the sweep: one entry a cycle when no stream write takes the port
    if (sweeping && !snoop_d_valid_reg) begin
        sweep_left_next = sweep_left_reg - 1'b1;
        sweep_ptr_next = sweep_ptr_reg + 1'b1;
    end

    if (flush_any) begin
        // a new epoch if the last one was used (or a line's entry is written now), and its sweep; a
        // fill under way stays invalid
        mru_valid_next = 1'b0;
        fill_stale_next = 1'b1;
        if (used_reg || entry_write) begin
            epoch_next = epoch_reg + 1'b1;
            used_next = 1'b0;
            sweep_left_next = N_SWEEP;
        end
    end
end

// storage
always @(posedge clk) begin
    line_word_reg <= {lane3_mem[cpu_slot], lane2_mem[cpu_slot], lane1_mem[cpu_slot], lane0_mem[cpu_slot]};
    if (wr_lanes[0]) begin
        lane0_mem[wr_slot] <= wr_bytes[7:0];
    end
    if (wr_lanes[1]) begin
        lane1_mem[wr_slot] <= wr_bytes[15:8];
    end
    if (wr_lanes[2]) begin
        lane2_mem[wr_slot] <= wr_bytes[23:16];
    end
    if (wr_lanes[3]) begin
        lane3_mem[wr_slot] <= wr_bytes[31:24];
    end
end

// the entries: port A reads (or writes a filled line's), port B clears
always @(posedge clk) begin
    if (entry_write) begin
        tag_mem[a_index] <= {1'b1, epoch_reg, fill_tag};
    end
    entry_reg <= tag_mem[a_index];
end

always @(posedge clk) begin
    if (b_write) begin
        tag_mem[b_index] <= {ENTRY_BITS{1'b0}};
    end
end

always @(posedge clk) begin
    state_reg <= state_next;
    ready_reg <= ready_next;
    entry_snooped_reg <= (snoop_valid && snoop_index == cpu_index)
                         || (snoop_d_valid_reg && snoop_d_index_reg == cpu_index);
    snoop_d_valid_reg <= snoop_valid;
    snoop_d_index_reg <= snoop_index;
    epoch_reg <= epoch_next;
    used_reg <= used_next;
    sweep_left_reg <= sweep_left_next;
    sweep_ptr_reg <= sweep_ptr_next;
    mru_line_reg <= mru_line_next;
    mru_valid_reg <= mru_valid_next;
    fill_issue_reg <= fill_issue_next;
    fill_recv_reg <= fill_recv_next;
    fill_stale_reg <= fill_stale_next;
    fill_answered_reg <= fill_answered_next;
    wb_pend_reg <= wb_pend_next;
    wb_check_reg <= take_write;
    if (state_reg == S_IDLE || state_reg == S_LOOK) begin
        fill_line_reg <= cpu_line;
    end
    if (take_write) begin
        wb_word_reg <= cpu_word;
        wb_data_reg <= cpu_wdata;
        wb_strb_reg <= cpu_wstrb;
    end

    // reset: as a flush for the entries (the epoch, its use and the sweep run on)
    if (rst) begin
        state_reg <= S_IDLE;
        ready_reg <= 1'b0;
        mru_valid_reg <= 1'b0;
        fill_stale_reg <= 1'b0;
        wb_pend_reg <= 2'b00;
        wb_check_reg <= 1'b0;
    end
end

endmodule

`resetall
