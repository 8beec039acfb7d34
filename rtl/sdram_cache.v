/*
 * wavemesh: the CPU port of the SDRAM controller, a small read cache with a posted write
 *
 * Between the PicoRV32's native memory interface and one client port of sdram_ctrl's command
 * engine.  Direct mapped, LINES lines of LINE_WORDS 32-bit words; write through with no write
 * allocate, through a one-word posted write buffer.
 *
 *   read hit    2 cycles, like the SoC's block RAMs (request, then cpu_ready with the word): the
 *               tags are LUT RAM, read asynchronously in the request cycle; the data are read at
 *               the CPU's address at every edge (synchronous: LUT RAM and a register when small,
 *               block RAM when large)
 *   read miss   the line is filled from its first halfword (2 * LINE_WORDS column reads, issued
 *               after any posted write); the word is answered as soon as its two halfwords are in
 *               (early restart), and the CPU's next access waits for the rest of the line
 *   write       taken in 2 cycles into the write buffer when it is empty (else it waits for it);
 *               a hit also updates the line's bytes; the buffer then writes the word's halfwords
 *               that have strobes, with the others' bytes masked by DQM
 *
 * Coherence with the streaming port: every beat the engine writes for the stream clears the valid
 * bit of the line at that address's index (without comparing tags); a line being filled when that
 * happens answers its one pending read and stays invalid.  The CPU's own accesses are answered in
 * order; a posted write reaches the SDRAM before any later read of this port is issued.
 *
 * Flush: `flush` (while `idle`: no fill, no posted write) invalidates every line in one cycle; the
 * controller's stage sync uses it, so that the CPU's accesses after a sync hit and miss alike
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
    parameter LINE_WORDS = 4
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
     * Flush: invalidate every line (only while idle)
     */
    input  wire                       flush,
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
localparam DEPTH = LINES * LINE_WORDS;                         // words held
localparam LINE_HW = 2 * LINE_WORDS;                           // halfwords per line
localparam CNT_BITS = OFF_BITS + 2;                            // counts 0 .. LINE_HW
localparam [CNT_BITS-1:0] CNT_LAST = LINE_HW[CNT_BITS-1:0] - 1'b1;
localparam [CNT_BITS-1:0] CNT_FULL = LINE_HW[CNT_BITS-1:0];

// check configuration
initial begin
    if (LINES < 2 || (1 << IDX_BITS) != LINES || LINE_WORDS < 1 || (1 << OFF_BITS) != LINE_WORDS
            || TAG_BITS < 1) begin
        $error("Error: LINES and LINE_WORDS must be powers of two, LINES >= 2 (instance %m)");
        $finish;
    end
end

localparam [1:0] S_IDLE = 2'd0, S_FILL = 2'd1, S_DONE = 2'd2;

// the CPU's address, split
wire [WADDR_BITS-1:0] cpu_word = cpu_addr[HW_ADDR_BITS:1+1];
wire [1:0] cpu_addr_unused = cpu_addr[1:0];
wire [IDX_BITS-1:0] cpu_index = cpu_word[OFF_BITS +: IDX_BITS];
wire [TAG_BITS-1:0] cpu_tag = cpu_word[WADDR_BITS-1 -: TAG_BITS];
wire [IDX_BITS+OFF_BITS-1:0] cpu_slot = cpu_word[IDX_BITS+OFF_BITS-1:0];   // {index, offset}

wire [IDX_BITS-1:0] snoop_index = snoop_addr[1+OFF_BITS +: IDX_BITS];
wire [HW_ADDR_BITS-1:0] snoop_addr_unused = snoop_addr;   // only its index bits matter

// storage (no reset): tags read asynchronously, data synchronously, both at the CPU's address
reg [TAG_BITS-1:0] tag_mem[0:LINES-1];
reg [7:0] lane0_mem[0:DEPTH-1];
reg [7:0] lane1_mem[0:DEPTH-1];
reg [7:0] lane2_mem[0:DEPTH-1];
reg [7:0] lane3_mem[0:DEPTH-1];

reg [1:0] state_reg = S_IDLE, state_next;
reg [LINES-1:0] valid_reg = {LINES{1'b0}}, valid_next;
reg ready_reg = 1'b0, ready_next;

// the line being filled
reg [CNT_BITS-1:0] fill_issue_reg = {CNT_BITS{1'b0}}, fill_issue_next;   // halfwords requested
reg [CNT_BITS-1:0] fill_recv_reg = {CNT_BITS{1'b0}}, fill_recv_next;     // halfwords received
reg fill_stale_reg = 1'b0, fill_stale_next;
reg fill_answered_reg = 1'b0, fill_answered_next;                         // the CPU has its word
reg [WADDR_BITS-OFF_BITS-1:0] fill_line_reg = {(WADDR_BITS-OFF_BITS){1'b0}};  // {tag, index}
wire [IDX_BITS-1:0] fill_index = fill_line_reg[IDX_BITS-1:0];
// halfwords in when the CPU's word is complete: 2 * offset + 2
wire [CNT_BITS-1:0] fill_word_in;

// posted write: the word, its strobes, the halfwords still to write {hi, lo}
reg [WADDR_BITS-1:0] wb_word_reg = {WADDR_BITS{1'b0}};
reg [31:0] wb_data_reg = 32'd0;
reg [3:0] wb_strb_reg = 4'd0;
reg [1:0] wb_pend_reg = 2'b00, wb_pend_next;

wire request = cpu_valid && !ready_reg;
wire hit = valid_reg[cpu_index] && tag_mem[cpu_index] == cpu_tag;
// the word at the CPU's address, read at every edge (synchronous: block RAM when the cache is large)
reg [31:0] line_word_reg = 32'd0;

// a write is taken when the buffer is empty; a hit also goes into the line
wire take_write = state_reg == S_IDLE && request && cpu_wstrb != 4'd0 && wb_pend_reg == 2'b00;
wire write_line = take_write && hit;
// fill data: the halfword goes into lanes 1:0 (even) or 3:2 (odd) of word fill_recv / 2
wire fill_write = state_reg == S_FILL && s_rvalid;
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
wire [IDX_BITS+OFF_BITS-1:0] wr_slot = fill_write ? fill_slot : cpu_slot;
wire [3:0] wr_lanes = fill_write ? (fill_recv_reg[0] ? 4'b1100 : 4'b0011)
                                 : (write_line ? cpu_wstrb : 4'b0000);
wire [31:0] wr_bytes = fill_write ? {s_rdata, s_rdata} : cpu_wdata;

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
assign cpu_ready = ready_reg;
assign cpu_rdata = line_word_reg;   // read at the edge that raised cpu_ready

always @* begin
    state_next = state_reg;
    valid_next = valid_reg;
    ready_next = 1'b0;
    fill_issue_next = fill_issue_reg;
    fill_recv_next = fill_recv_reg;
    fill_stale_next = fill_stale_reg;
    fill_answered_next = fill_answered_reg;
    wb_pend_next = wb_pend_reg;

    // the posted write: one halfword per acknowledged beat, low first
    if (m_ack && m_we) begin
        wb_pend_next = wb_lo ? {wb_pend_reg[1], 1'b0} : 2'b00;
    end

    case (state_reg)
        S_IDLE: begin
            if (request && cpu_wstrb == 4'd0) begin
                if (hit) begin
                    // read hit: the word, read at this edge
                    ready_next = 1'b1;
                end else begin
                    // read miss: fill the line (after the posted write, which goes first)
                    state_next = S_FILL;
                    valid_next[cpu_index] = 1'b0;
                    fill_issue_next = {CNT_BITS{1'b0}};
                    fill_recv_next = {CNT_BITS{1'b0}};
                    fill_stale_next = 1'b0;
                    fill_answered_next = 1'b0;
                end
            end else if (take_write) begin
                // write: into the buffer (and the line, on a hit); the halfwords with strobes
                wb_pend_next = {cpu_wstrb[3:2] != 2'b00, cpu_wstrb[1:0] != 2'b00};
                ready_next = 1'b1;
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
                // word was the line's last)
                fill_recv_next = fill_recv_reg + 1'b1;
                if (fill_recv_reg == CNT_LAST) begin
                    state_next = fill_answered_reg ? S_IDLE : S_DONE;
                    valid_next[fill_index] = !fill_stale_reg;
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
        valid_next[snoop_index] = 1'b0;
        if (state_reg == S_FILL && snoop_index == fill_index) begin
            fill_stale_next = 1'b1;
        end
    end

    if (flush) begin
        valid_next = {LINES{1'b0}};
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
    if (state_reg == S_IDLE && request && cpu_wstrb == 4'd0 && !hit) begin
        // the line's tag, set when its fill starts (the line is invalid until the fill completes)
        tag_mem[cpu_index] <= cpu_tag;
    end
end

always @(posedge clk) begin
    state_reg <= state_next;
    valid_reg <= valid_next;
    ready_reg <= ready_next;
    fill_issue_reg <= fill_issue_next;
    fill_recv_reg <= fill_recv_next;
    fill_stale_reg <= fill_stale_next;
    fill_answered_reg <= fill_answered_next;
    wb_pend_reg <= wb_pend_next;
    if (state_reg == S_IDLE) begin
        fill_line_reg <= cpu_word[WADDR_BITS-1:OFF_BITS];
    end
    if (take_write) begin
        wb_word_reg <= cpu_word;
        wb_data_reg <= cpu_wdata;
        wb_strb_reg <= cpu_wstrb;
    end

    if (rst) begin
        state_reg <= S_IDLE;
        valid_reg <= {LINES{1'b0}};
        ready_reg <= 1'b0;
        fill_stale_reg <= 1'b0;
        wb_pend_reg <= 2'b00;
    end
end

endmodule

`resetall
