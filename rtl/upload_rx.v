/*
 * wavemesh: the upload block: frames from the UART checked and DATA's samples stored without the CPU
 *
 * Bytes from the UART's RX FIFO in; per frame (docs/protocol.md, "Framing"): SLIP removed, the
 * header (type, seq, len) kept, the payload written into a payload buffer the CPU reads, the CRC-32
 * checked (the register after the frame and its CRC is the residue 0xDEBB20E3).  A good frame is
 * held (frame_valid) until the CPU releases it; no byte is taken meanwhile (the RX FIFO waits).  A
 * frame that is not one (shorter than 8 bytes, len above MAX_PAYLOAD, bytes after the CRC, a bad
 * escape, a wrong CRC, a silence of cfg_timeout cycles inside it) is dropped and counted
 * (bad_frames), never held.
 *
 * While cfg_arm is high, a DATA frame's samples also go through the sample path on the fly: the DATA
 * header's checks (the firmware's, in the same order: code 1 BAD_LENGTH, 2 BAD_OFFSET, 3 GAP: a
 * start beyond `next`), then every sample i < cfg_samples (W H) of the frame, raw words or
 * CODING_RICE decoded (the prediction from the line buffer, exactly as wavemesh.device.coding.decode), into
 * the line buffer and, for i >= next, into the SDRAM (HEIGHT_BASE + i, through the addressed writer)
 * and a tentative CRC of the samples.  When the frame turns out good and its code is 0, next moves to
 * the frame's end and the CRC is committed; a bad frame, or a Rice stream that is not one (code 4),
 * commits nothing: its samples from next on are junk no one reads, the ones before next are never
 * written.  So next and crc always describe samples 0 .. next-1 as the host sent them (RUN's CRC:
 * crc is the register, init all ones, not inverted).  Words at cfg_samples and beyond (the mask's)
 * are left to the CPU (it reads them from the payload buffer).
 *
 * The line buffer holds the last LB_DEPTH samples by index (i mod LB_DEPTH), LB_DEPTH > W, so the
 * above (i - W) and above-left (i - W - 1) samples of a Rice frame are at hand; [lb_lo, lb_hi) is
 * the range it holds as committed.  A Rice frame whose offset needs samples outside it (after a lost
 * frame, a repeat, a bad frame that wrote junk) first reloads the W + 1 samples before its offset
 * from the SDRAM through the stream reader (m_rd, s_rd), once the addressed writer is idle.
 *
 * Timing: one byte a cycle at most; a raw sample one cycle more, a Rice sample four (the quotient's
 * leading ones, the bits and the line-buffer read, the prediction, the sum and the stores) and a
 * block header two; per DATA frame 8 cycles of checks, 32 of the division that finds the offset's
 * column (Rice), 3 line-buffer reads and the reload when one is needed; per frame two cycles at its
 * end (its code, then the commit).  Every comparison of a frame's position with its length is a
 * register, computed a cycle ahead from pos_next and len_next, so no 16-bit compare sits between a
 * byte and the state it selects; the longest paths left are a carry chain or two deep.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module upload_rx #
(
    // payload buffer bytes: at least the protocol's MAX_PAYLOAD, 4 x a power of two
    parameter PB_BYTES = 1024,
    // line buffer samples: a power of two above the largest W
    parameter LB_DEPTH = 2048,
    // SDRAM halfword address bits
    parameter ADDR_BITS = 24,
    // halfword address of HEIGHT's sample 0
    parameter [ADDR_BITS-1:0] HEIGHT_BASE = {ADDR_BITS{1'b0}}
)
(
    input  wire                   clk,
    input  wire                   rst,

    /*
     * Bytes from the UART
     */
    input  wire [7:0]             s_axis_tdata,
    input  wire                   s_axis_tvalid,
    output wire                   s_axis_tready,

    /*
     * Configuration and commands
     */
    input  wire                   cfg_arm,        // DATA frames go through the sample path
    input  wire [15:0]            cfg_width,      // W (>= 2)
    input  wire [31:0]            cfg_samples,    // W H
    input  wire [31:0]            cfg_total,      // words the session takes (W H and the mask's)
    input  wire [31:0]            cfg_timeout,    // a frame is dropped after this many idle cycles (0: never)
    input  wire                   clear,          // a new session: next = 0, crc all ones, line buffer empty
    input  wire                   flush,          // drop a frame under way (the rate changed)
    input  wire                   frame_release,        // the CPU is done with the held frame

    /*
     * The held frame and the session's state
     */
    output wire                   frame_valid,
    output wire [7:0]             frame_type,
    output wire [7:0]             frame_seq,
    output wire [15:0]            frame_len,
    output wire                   frame_data,     // it went through the sample path
    output wire [2:0]             frame_code,     // 0 stored, 1 BAD_LENGTH, 2 BAD_OFFSET, 3 GAP, 4 bad Rice stream
    output wire [31:0]            next_sample,
    output wire [31:0]            crc,
    output wire [31:0]            bad_frames,
    input  wire [$clog2(PB_BYTES/4)-1:0] buf_addr,   // payload word
    output wire [31:0]            buf_rdata,      // in the next cycle

    /*
     * SDRAM: the samples (addressed writer), the reload (stream reader)
     */
    output wire [15:0]            m_wa_tdata,
    output wire [ADDR_BITS-1:0]   m_wa_tuser,
    output wire                   m_wa_tvalid,
    input  wire                   m_wa_tready,
    input  wire                   wa_busy,        // the addressed writer holds beats
    output wire [ADDR_BITS-1:0]   m_rd_addr,
    output wire [ADDR_BITS:0]     m_rd_len,
    output wire                   m_rd_valid,
    input  wire                   m_rd_ready,
    input  wire [15:0]            s_rd_tdata,
    input  wire                   s_rd_tvalid,
    output wire                   s_rd_tready,

    output wire                   busy
);

`include "wm_protocol.vh"

localparam PB_AW = $clog2(PB_BYTES / 4);
localparam LB_AW = $clog2(LB_DEPTH);
localparam [31:0] LB_SIZE = LB_DEPTH;
localparam [15:0] PB_LIMIT = WM_PROTO_MAX_PAYLOAD[15:0];

// check configuration
initial begin
    if (PB_BYTES < WM_PROTO_MAX_PAYLOAD || PB_BYTES % 4 != 0 || (1 << PB_AW) != PB_BYTES / 4) begin
        $error("Error: PB_BYTES must be 4 x a power of two (instance %m)");
        $finish;
    end
    if ((1 << LB_AW) != LB_DEPTH || LB_DEPTH < 4 || ADDR_BITS < LB_AW) begin
        $error("Error: LB_DEPTH must be a power of two (instance %m)");
        $finish;
    end
    if (WM_PROTO_RICE_PRED_BITS != 1 || WM_PROTO_RICE_K_BITS != 4 || WM_PROTO_RICE_ESCAPE != 16
            || WM_PROTO_RICE_BLOCK != 16 || WM_PROTO_HEADER_BYTES != 4 || WM_PROTO_CRC_BYTES != 4
            || WM_PROTO_DATA_BYTES != 8 || WM_PROTO_DATA_OFFSET != 0 || WM_PROTO_DATA_COUNT != 4
            || WM_PROTO_DATA_CODING != 6) begin
        $error("Error: the protocol's Rice layout changed: update upload_rx (instance %m)");
        $finish;
    end
end

localparam [4:0]
    S_BYTE = 5'd0,      // take the next byte
    S_CHECK = 5'd1,     // the DATA header is in: its checks
    S_DIV = 5'd2,       // the offset's column (offset mod W), a bit a cycle
    S_RLD_WAIT = 5'd3,  // reload: wait until every sample written is in the SDRAM
    S_RLD_CMD = 5'd4,   // reload: the read command
    S_RLD_DATA = 5'd5,  // reload: the samples into the line buffer
    S_INIT1 = 5'd6,     // read the left sample
    S_INIT2 = 5'd7,     // read the above-left sample
    S_INIT3 = 5'd8,
    S_DECQ = 5'd9,      // Rice: the leading ones of the next bits (q)
    S_DEC = 5'd10,      // Rice: a block header, or a sample's bits and its above sample's read
    S_PRED = 5'd11,     // Rice: the prediction
    S_DEC2 = 5'd12,     // Rice: the sample (prediction + residual) stored
    S_RAW = 5'd13,      // raw: a word stored
    S_END = 5'd14,      // the frame ended: good or not, its code
    S_COMMIT = 5'd15,   // commit or not
    S_HOLD = 5'd16;     // a good frame waits for the CPU

localparam [2:0] CODE_OK = 3'd0, CODE_LENGTH = 3'd1, CODE_OFFSET = 3'd2, CODE_GAP = 3'd3, CODE_STREAM = 3'd4;

reg [4:0]  state_reg = S_BYTE, state_next;

// the frame
reg [10:0] pos_reg = 11'd0, pos_next;           // unescaped bytes so far
reg        esc_reg = 1'b0, esc_next;
reg        bad_reg = 1'b0, bad_next;
reg        ended_reg = 1'b0, ended_next;        // S_END: by a delimiter (1) or the timeout (0)
reg [31:0] fcrc_reg = 32'hFFFFFFFF, fcrc_next;
reg [7:0]  type_reg = 8'd0, type_next;
reg [7:0]  seq_reg = 8'd0, seq_next;
reg [15:0] len_reg = 16'd0, len_next;
reg [31:0] idle_reg = 32'd0, idle_next;
reg [31:0] bad_frames_reg = 32'd0, bad_frames_next;
reg        flush_reg = 1'b0, flush_next;        // a flush waits for S_BYTE
reg        quiet_reg = 1'b0, quiet_next;        // the frame was flushed: not counted
// pos against len, a cycle ahead (from pos_next and len_next): the byte at pos is ...
reg        pay_reg = 1'b0, pay_next;            // ... a payload byte (4 <= pos < len + 4)
reg        over_reg = 1'b0, over_next;          // ... after the CRC (pos >= 4, pos >= len + 8)
reg        last_reg = 1'b0, last_next;          // ... the payload's last (pos == len + 3)
reg        tail_reg = 1'b0, tail_next;          // no payload byte is left (pos >= len + 4, 11 bits)
reg        full_reg = 1'b0, full_next;          // the frame has its length (pos == len + 8)
// S_END's outcome, carried out in S_COMMIT
reg        good_reg = 1'b0, good_next;          // the frame is good: held
reg        commit_reg = 1'b0, commit_next;      // its samples are committed
reg        junk_reg = 1'b0, junk_next;          // junk reached the line buffer
reg [31:0] cand_lo_reg = 32'd0, cand_lo_next;   // the line buffer's range after the commit or the junk
reg [31:0] cand_hi_reg = 32'd0, cand_hi_next;

// the sample path
reg        dp_reg = 1'b0, dp_next;              // this frame is an armed DATA frame
reg        st_reg = 1'b0, st_next;              // its samples are stored (checks passed, below W H)
reg [2:0]  code_reg = CODE_OK, code_next;
reg [31:0] off_reg = 32'd0, off_next;
reg [15:0] cnt_reg = 16'd0, cnt_next;           // n
reg [7:0]  coding_reg = 8'd0, coding_next;
reg [31:0] i_reg = 32'd0, i_next;               // the next sample's index
reg [32:0] end_reg = 33'd0, end_next;           // offset + n
reg [15:0] x_reg = 16'd0, x_next;               // its column
reg [16:0] rem_reg = 17'd0, rem_next;           // the division's remainder
reg [5:0]  div_reg = 6'd0, div_next;            // its step
reg [7:0]  lo_byte_reg = 8'd0, lo_byte_next;    // raw: a word's low byte
reg [15:0] val_reg = 16'd0, val_next;           // raw: the word
reg [39:0] acc_reg = 40'd0, acc_next;           // Rice: the bits, the next one at bit 39, zeros below nb
reg [5:0]  nb_reg = 6'd0, nb_next;
reg [4:0]  blk_reg = 5'd0, blk_next;            // samples left in the block (0: a header is next)
reg        pick_reg = 1'b0, pick_next;
reg [3:0]  k_reg = 4'd0, k_next;
reg [16:0] z_reg = 17'd0, z_next;
reg        fail_reg = 1'b0, fail_next;          // the Rice stream is not one
reg        extra_reg = 1'b0, extra_next;        // a byte came after the last sample
reg [15:0] left_reg = 16'd0, left_next;
reg [15:0] ul_reg = 16'd0, ul_next;
reg [31:0] lb_end_reg = 32'd0, lb_end_next;     // one past the last sample written to the line buffer
reg [31:0] scrc_reg = 32'hFFFFFFFF, scrc_next;  // tentative CRC of the samples from next on
reg [ADDR_BITS:0] rld_reg = {(ADDR_BITS+1){1'b0}}, rld_next;  // reload: samples left
reg [4:0]  q_reg = 5'd0;                        // Rice: the leading ones (S_DECQ)
reg [15:0] pred_reg = 16'd0;                    // Rice: the prediction (S_PRED)
reg [31:0] rld_m_reg = 32'd0;                   // rld_m and off - rld_m, registered (off and W are
reg [31:0] off_lo_reg = 32'd0;                  // steady through the division's 33 cycles)

// the session
reg [31:0] next_reg = 32'd0, next_next;
reg [31:0] crc_reg = 32'hFFFFFFFF, crc_next;
reg [31:0] lb_lo_reg = 32'd0, lb_lo_next;
reg [31:0] lb_hi_reg = 32'd0, lb_hi_next;

// outputs
reg        wa_valid_reg = 1'b0, wa_valid_next;
reg [15:0] wa_data_reg = 16'd0, wa_data_next;
reg [ADDR_BITS-1:0] wa_addr_reg = {ADDR_BITS{1'b0}}, wa_addr_next;

// memories: the payload buffer (four byte lanes) and the line buffer
reg [7:0]  pb0_mem [0:PB_BYTES/4-1];
reg [7:0]  pb1_mem [0:PB_BYTES/4-1];
reg [7:0]  pb2_mem [0:PB_BYTES/4-1];
reg [7:0]  pb3_mem [0:PB_BYTES/4-1];
reg [31:0] pb_rdata_reg = 32'd0;
reg [15:0] lb_mem [0:LB_DEPTH-1];
reg [15:0] lb_rdata_reg = 16'd0;

// the byte's write into the payload buffer and the line buffer's ports (from the next-state logic)
reg        pb_we;
reg [10:0] pos_la;
reg [PB_AW+1:0] pb_waddr;
reg        lb_we;
reg [LB_AW-1:0] lb_waddr, lb_raddr;
reg [15:0] lb_wdata;

function [31:0] crc_byte(input [31:0] c, input [7:0] d);
    integer b;
    begin
        crc_byte = c;
        for (b = 0; b < 8; b = b + 1) begin
            crc_byte = (crc_byte >> 1) ^ ((crc_byte[0] ^ d[b]) ? 32'hEDB88320 : 32'd0);
        end
    end
endfunction

// leading ones of the next 16 bits (16: all ones, the escape), by halving (four levels, not a chain)
function [4:0] ones16(input [15:0] v);
    reg [15:0] n;
    begin
        n = ~v;
        ones16 = 5'd0;
        if (n[15:8] == 8'd0) begin ones16 = ones16 + 5'd8; n = n << 8; end
        if (n[15:12] == 4'd0) begin ones16 = ones16 + 5'd4; n = n << 4; end
        if (n[15:14] == 2'd0) begin ones16 = ones16 + 5'd2; n = n << 2; end
        if (!n[15]) begin ones16 = ones16 + 5'd1; n = n << 1; end
        if (!n[15]) ones16 = ones16 + 5'd1;
    end
endfunction

assign s_axis_tready = state_reg == S_BYTE && !flush_reg;
assign frame_valid = state_reg == S_HOLD;
assign frame_type = type_reg;
assign frame_seq = seq_reg;
assign frame_len = len_reg;
assign frame_data = dp_reg;
assign frame_code = code_reg;
assign next_sample = next_reg;
assign crc = crc_reg;
assign bad_frames = bad_frames_reg;
assign buf_rdata = pb_rdata_reg;
assign m_wa_tdata = wa_data_reg;
assign m_wa_tuser = wa_addr_reg;
assign m_wa_tvalid = wa_valid_reg;
assign m_rd_addr = HEIGHT_BASE + off_reg[ADDR_BITS-1:0] - rld_reg[ADDR_BITS-1:0];
assign m_rd_len = rld_reg;
assign m_rd_valid = state_reg == S_RLD_CMD;
assign s_rd_tready = state_reg == S_RLD_DATA;
assign busy = state_reg != S_BYTE || pos_reg != 11'd0 || esc_reg || bad_reg || wa_valid_reg;

// the byte as a data byte of the frame
wire       byte_in = s_axis_tvalid && s_axis_tready;
wire       is_end = s_axis_tdata == WM_PROTO_SLIP_END;
wire       is_esc = s_axis_tdata == WM_PROTO_SLIP_ESC;
wire [7:0] data_byte = !esc_reg ? s_axis_tdata
                     : s_axis_tdata == WM_PROTO_SLIP_ESC_END ? WM_PROTO_SLIP_END : WM_PROTO_SLIP_ESC;
wire       esc_bad = esc_reg && s_axis_tdata != WM_PROTO_SLIP_ESC_END && s_axis_tdata != WM_PROTO_SLIP_ESC_ESC;
wire [15:0] pay_idx = {5'd0, pos_reg} - 16'd4;   // the payload byte's index (pos >= 4)
wire [15:0] len_at = pos_reg == 11'd3 ? {data_byte, len_reg[7:0]} : len_reg;

// the DATA header's checks
wire [31:0] tail_len = {16'd0, len_reg} - WM_PROTO_DATA_BYTES;
wire        is_raw = coding_reg == WM_PROTO_CODING_RAW;
wire        is_rice = coding_reg == WM_PROTO_CODING_RICE;
wire        chk_length = {16'd0, len_reg} < WM_PROTO_DATA_BYTES + 1 || cnt_reg == 16'd0
                         || (is_raw && tail_len != {15'd0, cnt_reg, 1'b0}) || (!is_raw && !is_rice);
wire [32:0] off_end = {1'b0, off_reg} + {17'd0, cnt_reg};
wire        chk_offset = off_reg > cfg_total || {16'd0, cnt_reg} > cfg_total - off_reg
                         || (is_rice && off_end > {1'b0, cfg_samples});
wire        chk_gap = off_reg > next_reg && off_reg < cfg_samples;
// Rice: the W + 1 samples before the offset (fewer at the start) must be in the line buffer
wire [31:0] w_plus = {16'd0, cfg_width} + 32'd1;
wire [31:0] rld_m = off_reg < w_plus ? off_reg : w_plus;
wire        need_reload = rld_m_reg != 32'd0 && (lb_lo_reg > off_lo_reg || off_reg > lb_hi_reg);

// Rice: the next item from the bits
wire        can_decode = nb_reg >= 6'd32 || tail_reg;  // or no tail byte is left
wire [4:0]  q = q_reg;
wire        escape = q == 5'd16;
wire [5:0]  need = escape ? 6'd32 : {1'b0, q} + 6'd1 + {2'd0, k_reg};
wire [39:0] acc_q = acc_reg << (q + 5'd1);
wire [15:0] acc_q_top = acc_q[39:24];
wire [23:0] acc_q_unused = acc_q[23:0];
wire [15:0] low_k = k_reg == 4'd0 ? 16'd0 : acc_q_top >> (5'd16 - {1'b0, k_reg});
// z's bits above 16 do not reach the 16-bit residual
wire [31:0] z_full = escape ? {16'd0, acc_reg[23:8]} : ({27'd0, q} << k_reg) | {16'd0, low_k};
wire [14:0] z_full_unused = z_full[31:17];
wire [39:0] acc_used = acc_reg << need;

// Rice: the prediction of sample i from left, above (the line buffer's read) and above-left
wire        row0 = i_reg < {16'd0, cfg_width};
wire [15:0] above = lb_rdata_reg;
wire [15:0] hi_ab = left_reg > above ? left_reg : above;
wire [15:0] lo_ab = left_reg > above ? above : left_reg;
wire [15:0] plane = left_reg + above - ul_reg;
wire [15:0] pred = row0 ? (x_reg != 16'd0 ? left_reg : 16'd0)
                 : x_reg == 16'd0 ? above
                 : (pick_reg == WM_PROTO_RICE_PRED_PLANE[0] || (ul_reg < hi_ab && ul_reg > lo_ab)) ? plane
                 : ul_reg >= hi_ab ? lo_ab : hi_ab;
wire [15:0] resid = z_reg[16:1] ^ {16{z_reg[0]}};
wire [15:0] dec_val = pred_reg + resid;

// a sample is put (S_DEC2, S_RAW): line buffer, and from next on the SDRAM and the CRC
wire [15:0] put_val = state_reg == S_DEC2 ? dec_val : val_reg;
wire        put_mem = i_reg < cfg_samples;
wire        put_new = put_mem && i_reg >= next_reg;
wire        put_stall = put_new && wa_valid_reg && !m_wa_tready;

// the line buffer's range after a frame wrote samples off .. lb_end - 1 into it (each into slot i mod
// LB_DEPTH): good samples extend a range they start in (the clamp below drops what they overwrote),
// else they are the range; junk ends the range at off and overwrites the slots of off - LB_DEPTH ..
// lb_end - LB_DEPTH - 1, or, written below the range, may have hit any of it
wire        lb_in = off_reg >= lb_lo_reg && off_reg <= lb_hi_reg;
wire [31:0] lb_hi_good = !lb_in ? lb_end_reg : (lb_end_reg > lb_hi_reg ? lb_end_reg : lb_hi_reg);
wire [31:0] lb_lo_good = !lb_in ? off_reg : lb_lo_reg;
wire [31:0] lb_lo_bad = off_reg < lb_lo_reg ? 32'd0
                      : lb_end_reg > LB_SIZE && lb_end_reg - LB_SIZE > lb_lo_reg ? lb_end_reg - LB_SIZE : lb_lo_reg;
wire [31:0] lb_hi_bad = off_reg < lb_lo_reg ? 32'd0 : off_reg < lb_hi_reg ? off_reg : lb_hi_reg;
wire [31:0] store_end = end_reg > {1'b0, cfg_samples} ? cfg_samples : end_reg[31:0];
wire        frame_good = !bad_reg && !esc_reg && ended_reg && full_reg
                         && fcrc_reg == WM_PROTO_CRC_RESIDUE;
wire        in_frame = pos_reg != 11'd0 || esc_reg || bad_reg;
// the range after a commit or junk never spans more than the line buffer holds (the only ranges that
// can: a reload's spans rld_m <= W + 1 < LB_DEPTH samples, a clear none)
wire [31:0] cand_lo_span = cand_hi_reg > LB_SIZE && cand_lo_reg < cand_hi_reg - LB_SIZE ? cand_hi_reg - LB_SIZE
                         : cand_lo_reg;
wire [31:0] cand_lo_clamp = cand_lo_span > cand_hi_reg ? cand_hi_reg : cand_lo_span;

always @* begin
    state_next = state_reg;
    pos_next = pos_reg;
    esc_next = esc_reg;
    bad_next = bad_reg;
    ended_next = ended_reg;
    fcrc_next = fcrc_reg;
    type_next = type_reg;
    seq_next = seq_reg;
    len_next = len_reg;
    idle_next = idle_reg;
    bad_frames_next = bad_frames_reg;
    flush_next = flush_reg || flush;
    quiet_next = quiet_reg;
    dp_next = dp_reg;
    st_next = st_reg;
    code_next = code_reg;
    off_next = off_reg;
    cnt_next = cnt_reg;
    coding_next = coding_reg;
    i_next = i_reg;
    end_next = end_reg;
    x_next = x_reg;
    rem_next = rem_reg;
    div_next = div_reg;
    lo_byte_next = lo_byte_reg;
    val_next = val_reg;
    acc_next = acc_reg;
    nb_next = nb_reg;
    blk_next = blk_reg;
    pick_next = pick_reg;
    k_next = k_reg;
    z_next = z_reg;
    fail_next = fail_reg;
    extra_next = extra_reg;
    left_next = left_reg;
    ul_next = ul_reg;
    lb_end_next = lb_end_reg;
    scrc_next = scrc_reg;
    rld_next = rld_reg;
    next_next = next_reg;
    crc_next = crc_reg;
    lb_lo_next = lb_lo_reg;
    lb_hi_next = lb_hi_reg;
    good_next = good_reg;
    commit_next = commit_reg;
    junk_next = junk_reg;
    cand_lo_next = cand_lo_reg;
    cand_hi_next = cand_hi_reg;
    wa_valid_next = wa_valid_reg && !m_wa_tready;
    wa_data_next = wa_data_reg;
    wa_addr_next = wa_addr_reg;

    pb_we = 1'b0;
    pb_waddr = pay_idx[PB_AW+1:0];
    lb_we = 1'b0;
    lb_waddr = i_reg[LB_AW-1:0];
    lb_wdata = put_val;
    lb_raddr = i_reg[LB_AW-1:0] - cfg_width[LB_AW-1:0];

    case (state_reg)
        S_BYTE: begin
            if (flush_reg) begin
                // the rate changed: whatever was under way is dropped, uncounted
                flush_next = flush;
                ended_next = 1'b0;
                quiet_next = in_frame;
                state_next = in_frame ? S_END : S_BYTE;
            end else if (byte_in) begin
                idle_next = 32'd0;
                if (is_end) begin
                    ended_next = 1'b1;
                    state_next = in_frame ? S_END : S_BYTE;
                end else if (bad_reg) begin
                    // discarding until the next delimiter
                end else if (esc_bad) begin
                    bad_next = 1'b1;
                    esc_next = 1'b0;
                end else if (!esc_reg && is_esc) begin
                    esc_next = 1'b1;
                end else begin
                    // a data byte at pos
                    esc_next = 1'b0;
                    pos_next = pos_reg + 11'd1;
                    fcrc_next = crc_byte(fcrc_reg, data_byte);
                    if (pos_reg == 11'd0) type_next = data_byte;
                    if (pos_reg == 11'd1) seq_next = data_byte;
                    if (pos_reg == 11'd2) len_next = {8'd0, data_byte};
                    if (pos_reg == 11'd3) begin
                        len_next = len_at;
                        if (len_at > PB_LIMIT) bad_next = 1'b1;   // longer than any frame
                        dp_next = cfg_arm && type_reg == WM_PROTO_T_DATA;
                        st_next = 1'b0;
                        code_next = CODE_OK;
                    end
                    if (over_reg) begin
                        bad_next = 1'b1;                          // bytes after the CRC
                    end else if (pay_reg) begin
                        // a payload byte: into the buffer, and for an armed DATA frame into its fields
                        pb_we = 1'b1;
                        if (dp_reg) begin
                            case (pay_idx)
                                16'd0: off_next[7:0] = data_byte;
                                16'd1: off_next[15:8] = data_byte;
                                16'd2: off_next[23:16] = data_byte;
                                16'd3: off_next[31:24] = data_byte;
                                16'd4: cnt_next[7:0] = data_byte;
                                16'd5: cnt_next[15:8] = data_byte;
                                16'd6: coding_next = data_byte;
                                16'd7: state_next = S_CHECK;
                                default: begin
                                    // a tail byte: the sample path's
                                    if (st_reg && coding_reg == WM_PROTO_CODING_RAW) begin
                                        if (!pay_idx[0]) begin
                                            lo_byte_next = data_byte;
                                        end else begin
                                            val_next = {data_byte, lo_byte_reg};
                                            state_next = S_RAW;
                                        end
                                    end else if (st_reg) begin
                                        if (i_reg[32 - 1:0] == end_reg[31:0] || fail_reg) begin
                                            extra_next = extra_reg || i_reg == end_reg[31:0];
                                        end else begin
                                            acc_next = acc_reg | ({32'd0, data_byte} << (6'd32 - nb_reg));
                                            nb_next = nb_reg + 6'd8;
                                            if (nb_reg + 6'd8 >= 6'd32 || last_reg) begin
                                                state_next = S_DECQ;
                                            end
                                        end
                                    end
                                end
                            endcase
                        end
                    end
                end
            end else if (in_frame && cfg_timeout != 32'd0) begin
                idle_next = idle_reg + 32'd1;
                if (idle_reg + 32'd1 >= cfg_timeout) begin
                    // the rest of this frame is not coming
                    ended_next = 1'b0;
                    state_next = S_END;
                end
            end
        end
        S_CHECK: begin
            // the DATA header is in (and the reserved byte): the firmware's checks, in its order
            end_next = off_end;
            i_next = off_reg;
            lb_end_next = off_reg;
            scrc_next = crc_reg;
            acc_next = 40'd0;
            nb_next = 6'd0;
            blk_next = 5'd0;
            fail_next = 1'b0;
            extra_next = 1'b0;
            state_next = S_BYTE;
            if (chk_length) begin
                code_next = CODE_LENGTH;
            end else if (chk_offset) begin
                code_next = CODE_OFFSET;
            end else if (chk_gap) begin
                code_next = CODE_GAP;
            end else if (off_reg < cfg_samples) begin
                st_next = 1'b1;
                if (is_rice) begin
                    rem_next = 17'd0;
                    div_next = 6'd0;
                    state_next = S_DIV;
                end
            end
        end
        S_DIV: begin
            // restoring division of the offset by W, a bit a cycle: the remainder is its column
            if (div_reg == 6'd32) begin
                x_next = rem_reg[15:0];
                rld_next = rld_m_reg[ADDR_BITS:0];
                state_next = need_reload ? S_RLD_WAIT : S_INIT1;
            end else begin
                if ({rem_reg[15:0], off_reg[31 - div_reg[4:0]]} >= {1'b0, cfg_width}) begin
                    rem_next = {rem_reg[15:0], off_reg[31 - div_reg[4:0]]} - {1'b0, cfg_width};
                end else begin
                    rem_next = {rem_reg[15:0], off_reg[31 - div_reg[4:0]]};
                end
                div_next = div_reg + 6'd1;
            end
        end
        S_RLD_WAIT: begin
            // every sample written before is in the SDRAM before the reader reads it
            if (!wa_valid_reg && !wa_busy) state_next = S_RLD_CMD;
        end
        S_RLD_CMD: begin
            if (m_rd_ready) begin
                lb_lo_next = off_lo_reg;
                lb_hi_next = off_lo_reg;
                state_next = S_RLD_DATA;
            end
        end
        S_RLD_DATA: begin
            lb_waddr = lb_hi_reg[LB_AW-1:0];
            lb_wdata = s_rd_tdata;
            if (s_rd_tvalid) begin
                lb_we = 1'b1;
                lb_hi_next = lb_hi_reg + 32'd1;
                rld_next = rld_reg - 1'b1;
                if (rld_reg == {{ADDR_BITS{1'b0}}, 1'b1}) state_next = S_INIT1;
            end
        end
        S_INIT1: begin
            lb_raddr = off_reg[LB_AW-1:0] - 1'b1;
            state_next = S_INIT2;
        end
        S_INIT2: begin
            lb_raddr = off_reg[LB_AW-1:0] - cfg_width[LB_AW-1:0] - 1'b1;
            left_next = lb_rdata_reg;
            state_next = S_INIT3;
        end
        S_INIT3: begin
            ul_next = lb_rdata_reg;
            state_next = S_BYTE;
        end
        S_DECQ: begin
            // q_reg: the leading ones of the next bits
            state_next = S_DEC;
        end
        S_DEC: begin
            // the next item when its bits are all here (32 is the longest), or no byte is left
            if (i_reg == end_reg[31:0] || fail_reg || !can_decode) begin
                state_next = S_BYTE;
            end else if (blk_reg == 5'd0) begin
                if (nb_reg < 6'd5) begin
                    fail_next = 1'b1;
                    state_next = S_BYTE;
                end else begin
                    pick_next = acc_reg[39];
                    k_next = acc_reg[38:35];
                    acc_next = acc_reg << 5;
                    nb_next = nb_reg - 6'd5;
                    blk_next = 5'd16;
                    state_next = S_DECQ;
                end
            end else if (need > nb_reg) begin
                fail_next = 1'b1;                 // the stream ends inside a sample
                state_next = S_BYTE;
            end else begin
                z_next = z_full[16:0];
                acc_next = acc_used;
                nb_next = nb_reg - need;
                state_next = S_PRED;              // lb_raddr: the above sample
            end
        end
        S_PRED: begin
            // pred_reg: the prediction from left, above (read in S_DEC) and above-left
            state_next = S_DEC2;
        end
        S_DEC2, S_RAW: begin
            if (!put_stall) begin
                if (put_mem) begin
                    lb_we = 1'b1;
                    lb_end_next = i_reg + 32'd1;
                end
                if (put_new) begin
                    wa_valid_next = 1'b1;
                    wa_data_next = put_val;
                    wa_addr_next = HEIGHT_BASE + i_reg[ADDR_BITS-1:0];
                    scrc_next = crc_byte(crc_byte(scrc_reg, put_val[7:0]), put_val[15:8]);
                end
                if (state_reg == S_DEC2) begin
                    left_next = dec_val;
                    if (!row0) ul_next = above;
                    blk_next = blk_reg - 5'd1;
                end
                i_next = i_reg + 32'd1;
                x_next = x_reg + 16'd1 == cfg_width ? 16'd0 : x_reg + 16'd1;
                state_next = state_reg == S_DEC2 ? S_DECQ : S_BYTE;
            end
        end
        S_END: begin
            // the frame is over: good or not, its code; an armed DATA frame commits (S_COMMIT) when
            // good and stored
            state_next = S_COMMIT;
            if (dp_reg && {16'd0, len_reg} < WM_PROTO_DATA_BYTES) code_next = CODE_LENGTH;   // no whole DATA header
            if (st_reg && is_rice && !(i_reg == end_reg[31:0] && !fail_reg && !extra_reg && nb_reg < 6'd8)) begin
                code_next = CODE_STREAM;
            end
            good_next = frame_good;
            commit_next = frame_good && st_reg && code_next == CODE_OK && !clear;
            // junk may have reached the line buffer from off on
            junk_next = st_reg && !(frame_good && code_next == CODE_OK) && lb_end_reg > off_reg && !clear;
            cand_hi_next = frame_good && code_next == CODE_OK ? lb_hi_good : lb_hi_bad;
            cand_lo_next = frame_good && code_next == CODE_OK ? lb_lo_good : lb_lo_bad;
            if (!frame_good && !quiet_reg) begin
                bad_frames_next = bad_frames_reg + 32'd1;
            end
        end
        S_COMMIT: begin
            state_next = good_reg ? S_HOLD : S_BYTE;
            if (commit_reg) begin
                if (store_end > next_reg) next_next = store_end;
                crc_next = scrc_reg;
            end
            if (commit_reg || junk_reg) begin
                lb_hi_next = cand_hi_reg;
                lb_lo_next = cand_lo_clamp;
            end
        end
        S_HOLD: begin
            if (frame_release) state_next = S_BYTE;
        end
        default: state_next = S_BYTE;
    endcase

    if ((state_reg == S_COMMIT || state_reg == S_HOLD) && state_next == S_BYTE) begin
        // the frame dropped or released: ready for the next (quiet is already clear in S_HOLD:
        // a flushed frame ends with ended clear, so it is never good)
        pos_next = 11'd0;
        esc_next = 1'b0;
        bad_next = 1'b0;
        fcrc_next = 32'hFFFFFFFF;
        dp_next = 1'b0;
        st_next = 1'b0;
        idle_next = 32'd0;
        quiet_next = 1'b0;
    end

    if (clear) begin
        next_next = 32'd0;
        crc_next = 32'hFFFFFFFF;
        lb_lo_next = 32'd0;
        lb_hi_next = 32'd0;
    end

    // pos against len for the next cycle (pos is 0 after a reset)
    pos_la = rst ? 11'd0 : pos_next;
    pay_next = pos_la >= 11'd4 && {5'd0, pos_la} < len_next + 16'd4;
    over_next = pos_la >= 11'd4 && {5'd0, pos_la} >= len_next + 16'd8;
    last_next = {5'd0, pos_la} - 16'd4 + 16'd1 == len_next;
    tail_next = pos_la >= len_next[10:0] + 11'd4;
    full_next = {5'd0, pos_la} == len_next + 16'd8;
end

always @(posedge clk) begin
    state_reg <= state_next;
    pos_reg <= pos_next;
    esc_reg <= esc_next;
    bad_reg <= bad_next;
    ended_reg <= ended_next;
    fcrc_reg <= fcrc_next;
    type_reg <= type_next;
    seq_reg <= seq_next;
    len_reg <= len_next;
    idle_reg <= idle_next;
    bad_frames_reg <= bad_frames_next;
    flush_reg <= flush_next;
    quiet_reg <= quiet_next;
    pay_reg <= pay_next;
    over_reg <= over_next;
    last_reg <= last_next;
    tail_reg <= tail_next;
    full_reg <= full_next;
    good_reg <= good_next;
    commit_reg <= commit_next;
    junk_reg <= junk_next;
    cand_lo_reg <= cand_lo_next;
    cand_hi_reg <= cand_hi_next;
    rld_m_reg <= rld_m;
    off_lo_reg <= off_reg - rld_m_reg;
    if (state_reg == S_DECQ) q_reg <= ones16(acc_reg[39:24]);
    if (state_reg == S_PRED) pred_reg <= pred;
    dp_reg <= dp_next;
    st_reg <= st_next;
    code_reg <= code_next;
    off_reg <= off_next;
    cnt_reg <= cnt_next;
    coding_reg <= coding_next;
    i_reg <= i_next;
    end_reg <= end_next;
    x_reg <= x_next;
    rem_reg <= rem_next;
    div_reg <= div_next;
    lo_byte_reg <= lo_byte_next;
    val_reg <= val_next;
    acc_reg <= acc_next;
    nb_reg <= nb_next;
    blk_reg <= blk_next;
    pick_reg <= pick_next;
    k_reg <= k_next;
    z_reg <= z_next;
    fail_reg <= fail_next;
    extra_reg <= extra_next;
    left_reg <= left_next;
    ul_reg <= ul_next;
    lb_end_reg <= lb_end_next;
    scrc_reg <= scrc_next;
    rld_reg <= rld_next;
    next_reg <= next_next;
    crc_reg <= crc_next;
    lb_lo_reg <= lb_lo_next;
    lb_hi_reg <= lb_hi_next;
    wa_valid_reg <= wa_valid_next;
    wa_data_reg <= wa_data_next;
    wa_addr_reg <= wa_addr_next;

    if (rst) begin
        state_reg <= S_BYTE;
        pos_reg <= 11'd0;
        esc_reg <= 1'b0;
        bad_reg <= 1'b0;
        fcrc_reg <= 32'hFFFFFFFF;
        idle_reg <= 32'd0;
        bad_frames_reg <= 32'd0;
        flush_reg <= 1'b0;
        quiet_reg <= 1'b0;
        dp_reg <= 1'b0;
        st_reg <= 1'b0;
        next_reg <= 32'd0;
        crc_reg <= 32'hFFFFFFFF;
        lb_lo_reg <= 32'd0;
        lb_hi_reg <= 32'd0;
        wa_valid_reg <= 1'b0;
    end
end

// the payload buffer: a byte written per payload byte, the CPU reads words
always @(posedge clk) begin
    if (pb_we) begin
        case (pb_waddr[1:0])
            2'd0: pb0_mem[pb_waddr[PB_AW+1:2]] <= data_byte;
            2'd1: pb1_mem[pb_waddr[PB_AW+1:2]] <= data_byte;
            2'd2: pb2_mem[pb_waddr[PB_AW+1:2]] <= data_byte;
            default: pb3_mem[pb_waddr[PB_AW+1:2]] <= data_byte;
        endcase
    end
    pb_rdata_reg <= {pb3_mem[buf_addr], pb2_mem[buf_addr], pb1_mem[buf_addr], pb0_mem[buf_addr]};
end

// the line buffer: one write, one read a cycle
always @(posedge clk) begin
    if (lb_we) lb_mem[lb_waddr] <= lb_wdata;
    lb_rdata_reg <= lb_mem[lb_raddr];
end

endmodule

`resetall
