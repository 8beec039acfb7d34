/*
 * wavemesh: the FPGA stage alone behind a UART (the iCEBreaker configuration, docs/boards.md)
 *
 * No CPU and no frame buffer: the host streams a job's samples over the UART, they go straight
 * into the filter bank (haar_bank) and the template stage (tlut_stage), and every block's TOUT
 * entry (template id, label) goes straight back, in raster order.  The host builds the initial
 * triangulation from those entries and refines it itself.
 *
 * Wire format (little-endian; docs/boards.md, "The iCEBreaker's stream"):
 *
 *   host -> device   header: "WM", W (u16), H (u16), M (u8), tau (u24)     10 bytes
 *   device -> host   "OK" (0x4F 0x4B), or "E" and a reason byte when the header is out of range
 *                    (then the device waits for the next header)
 *   host -> device   W x H samples (u16), row-major
 *   device -> host   one u16 per block in raster order: bits 5..0 template id, 8..6 label
 *                    (the TOUT entry of docs/soc.md), ceil((W-1)/2^M) x ceil((H-1)/2^M) of them
 *
 * The device is then ready for the next header.  Reasons: "W" W or H out of 2..MAX_WIDTH /
 * 2..MAX_HEIGHT, "M" M out of 1..MAX_LEVELS, "C" too many block columns for the template stage.
 *
 * HELLO (docs/protocol.md): between jobs the device also reads the wire protocol's SLIP frames.  A
 * HELLO frame (0xC0, type HELLO, seq, ...) is answered with a HELLO_REPLY frame of the same seq
 * stating what the stage is (name "wm-stage", FEATURE_STAGE, its largest grid and M, its clock,
 * baud rate and silence timeout; the layout from the generated wm_protocol.vh, the CRC-32 computed
 * bit by bit as the reply goes out); any other host frame (types 1..0x3F) is skipped to its closing
 * 0xC0.  So `wavemesh stream` and `wavemesh devices` find the stage as they find a board, and the
 * host then sends the job in the stream above.  The HELLO's length and CRC are not checked (a
 * damaged HELLO is answered; the host checks the reply); a HELLO that ends while a reply is still
 * going out is not answered (the host repeats it).
 *
 * Nothing a host sends can hang it: between jobs the device skips every byte until "WM" outside a
 * frame (so any garbage is passed over; a header with a bad field is answered and dropped), and a
 * header, a frame or a job whose next byte does not come within 2^TIMEOUT_BITS clocks (0.7 s at
 * 12 MHz) is dropped: the filter bank and the template stage are reset and the device waits for the
 * next "WM" or frame.
 *
 * Flow: the receiver has no back-pressure, so the stage must keep up with the line.  It does: the
 * filter bank takes a sample per clock, and the only stall, the template stage waiting for the
 * transmitter, lasts at most one block row's entries (2 ceil((W-1)/2^M) bytes, sent while the next
 * sample row, 2 W bytes at the same baud rate, comes in); RX_DEPTH bytes absorb the rest.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

module stage_uart #
(
    // the clock in Hz, and the UART's baud rate (8N1; CLK_HZ / BAUD clocks per bit, rounded, >= 2)
    parameter CLK_HZ = 12_000_000,
    parameter BAUD = 115_200,
    // the filter bank's maxima
    parameter MAX_WIDTH = 256,
    parameter MAX_HEIGHT = 4096,
    parameter MAX_LEVELS = 3,
    // the template stage's row buffer: block columns of the finest M, ceil((MAX_WIDTH - 1) / 2)
    parameter MAX_COLS = 128,
    // byte FIFOs (flip-flops on the iCE40: keep them small)
    parameter RX_DEPTH = 16,
    parameter TX_DEPTH = 8,
    // a header or job is dropped after 2^TIMEOUT_BITS clocks without a received byte
    parameter TIMEOUT_BITS = 23
)
(
    input  wire        clk,
    input  wire        rst,
    input  wire        rxd,
    output wire        txd,
    output wire        busy,       // a job is in progress (header accepted, entries outstanding)
    output wire        rx_overrun  // sticky: a received byte found the RX FIFO full (the job is lost)
);

`include "wm_protocol.vh"

localparam integer DIV = (CLK_HZ + BAUD / 2) / BAUD;
localparam [15:0] DIV16 = DIV[15:0];

// the stage's version (HELLO_REPLY's fw_major, fw_minor): the byte stream's
localparam [7:0] VERSION_MAJOR = 8'd1;
localparam [7:0] VERSION_MINOR = 8'd0;
// the silence timeout in ms (HELLO_REPLY's byte and session timeouts)
localparam [63:0] SILENCE_MS = ((64'd1 << TIMEOUT_BITS) * 64'd1000) / CLK_HZ;

// HELLO_REPLY's payload: every field the stage states, at the generated offsets (little-endian)
function [8*WM_PROTO_HELLO_REPLY_BYTES-1:0] hello_payload;
    input integer unused;
    integer k;
    reg [63:0] name;
    begin
        hello_payload = {(8*WM_PROTO_HELLO_REPLY_BYTES){1'b0}};
        name = "wm-stage";
        hello_payload[8*WM_PROTO_HELLO_REPLY_VERSION +: 16] = WM_PROTO_VERSION;
        hello_payload[8*WM_PROTO_HELLO_REPLY_FW_MAJOR +: 8] = VERSION_MAJOR;
        hello_payload[8*WM_PROTO_HELLO_REPLY_FW_MINOR +: 8] = VERSION_MINOR;
        for (k = 0; k < 8; k = k + 1) begin
            hello_payload[8*(WM_PROTO_HELLO_REPLY_NAME + k) +: 8] = name[8*(7-k) +: 8];
        end
        hello_payload[8*WM_PROTO_HELLO_REPLY_MAX_WIDTH +: 16] = MAX_WIDTH;
        hello_payload[8*WM_PROTO_HELLO_REPLY_MAX_HEIGHT +: 16] = MAX_HEIGHT;
        // no frame buffer: the samples stream through, so any W x H within the sides
        hello_payload[8*WM_PROTO_HELLO_REPLY_MAX_SAMPLES +: 32] = MAX_WIDTH * MAX_HEIGHT;
        hello_payload[8*WM_PROTO_HELLO_REPLY_TRI_CAPACITY +: 32] = 32'd0;  // no refiner
        hello_payload[8*WM_PROTO_HELLO_REPLY_MAX_LEVELS +: 8] = MAX_LEVELS;
        // no DATA frames: the smallest window and payload a device may state
        hello_payload[8*WM_PROTO_HELLO_REPLY_WINDOW +: 8] = 8'd1;
        hello_payload[8*WM_PROTO_HELLO_REPLY_MAX_PAYLOAD +: 16] = WM_PROTO_MIN_PAYLOAD;
        hello_payload[8*WM_PROTO_HELLO_REPLY_CLK_HZ +: 32] = CLK_HZ;
        hello_payload[8*WM_PROTO_HELLO_REPLY_BAUD +: 32] = BAUD;
        hello_payload[8*WM_PROTO_HELLO_REPLY_FEATURES +: 32] = WM_PROTO_FEATURE_STAGE;
        hello_payload[8*WM_PROTO_HELLO_REPLY_BYTE_TIMEOUT_MS +: 16] = SILENCE_MS[15:0];
        hello_payload[8*WM_PROTO_HELLO_REPLY_ACK_TIMEOUT_MS +: 16] = 16'd0;  // nothing is acknowledged
        hello_payload[8*WM_PROTO_HELLO_REPLY_SESSION_TIMEOUT_MS +: 32] = SILENCE_MS[31:0];
        hello_payload[8*WM_PROTO_HELLO_REPLY_ACK_RETRIES +: 16] = 16'd0;
        hello_payload[8*WM_PROTO_HELLO_REPLY_IDLE_TIMEOUT_MS +: 32] = 32'd0;  // a UART: never closed
        hello_payload[8*WM_PROTO_HELLO_REPLY_WRITE_TIMEOUT_MS +: 32] = 32'd0;
    end
endfunction

localparam [8*WM_PROTO_HELLO_REPLY_BYTES-1:0] HELLO_PAYLOAD = hello_payload(0);
localparam [15:0] HELLO_LEN = WM_PROTO_HELLO_REPLY_BYTES;
localparam [6:0] HELLO_CRC_AT = 7'd4 + HELLO_LEN[6:0];  // raw frame bytes: type, seq, len, payload, CRC
localparam [6:0] HELLO_LAST = HELLO_CRC_AT + 7'd3;
localparam [31:0] CRC32_POLY = 32'hEDB88320;  // zlib's CRC-32, reflected

/*
 * Receiver and its FIFO
 */
wire [7:0] rx_pin_tdata;
wire       rx_pin_tvalid;
wire       rx_busy_unused;
wire       rx_frame_error_unused;

uart_rx rx_inst (
    .clk(clk),
    .rst(rst),
    .rxd(rxd),
    .div(DIV16),
    .m_axis_tdata(rx_pin_tdata),
    .m_axis_tvalid(rx_pin_tvalid),
    .busy(rx_busy_unused),
    .frame_error(rx_frame_error_unused)
);

wire [7:0] rx_tdata;
wire       rx_tvalid;
reg        rx_tready;
wire       rx_fifo_ready;
wire [$clog2(RX_DEPTH + 1)-1:0] rx_count_unused;

wm_fifo #(
    .DATA_WIDTH(8),
    .DEPTH(RX_DEPTH)
) rx_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(rx_pin_tdata),
    .s_valid(rx_pin_tvalid),
    .s_ready(rx_fifo_ready),
    .m_data(rx_tdata),
    .m_valid(rx_tvalid),
    .m_ready(rx_tready),
    .count(rx_count_unused)
);

reg overrun_reg = 1'b0;

/*
 * Header, samples, state
 */
localparam [1:0]
    STATE_HEADER = 2'd0,
    STATE_REPLY = 2'd1,
    STATE_SAMPLES = 2'd2,
    STATE_DRAIN = 2'd3;

reg [1:0]  state_reg = STATE_HEADER;
reg [3:0]  hdr_count_reg = 4'd0;     // header bytes in, the two of "WM" included
reg [63:0] hdr_reg = 64'd0;
reg [15:0] width_reg = 16'd2;
reg [15:0] height_reg = 16'd2;
reg [3:0]  levels_reg = 4'd1;
reg [17:0] tau_reg = 18'd0;
reg [7:0]  reason_reg = 8'd0;     // 0: OK
reg [1:0]  reply_count_reg = 2'd0;
reg        checked_reg = 1'b0;     // the header has been checked (reply bytes may go)
reg [31:0] samples_left_reg = 32'd0;
reg [31:0] blocks_left_reg = 32'd0;
reg        low_valid_reg = 1'b0;   // the sample's low byte is in
reg [7:0]  low_reg = 8'd0;

/*
 * Wire-protocol frames between jobs (HELLO), and the HELLO_REPLY sender
 */
localparam [2:0]
    FRAME_NONE = 3'd0,     // outside a frame: bytes go to the "WM" matcher
    FRAME_START = 3'd1,    // after a 0xC0: the next byte is a frame type (or raw, or another 0xC0)
    FRAME_SEQ = 3'd2,      // a HELLO's seq is next
    FRAME_SEQ_ESC = 3'd3,  // ... escaped
    FRAME_HELLO = 3'd4,    // the rest of a HELLO, to its closing 0xC0
    FRAME_SKIP = 3'd5;     // another host frame, to its closing 0xC0

reg [2:0]  frame_reg = FRAME_NONE;
reg [7:0]  seq_reg = 8'd0;            // the seq of the HELLO being read

localparam [2:0]
    SEND_IDLE = 3'd0,
    SEND_START = 3'd1,     // the opening 0xC0
    SEND_CRC = 3'd2,       // the raw byte through the CRC, a bit per clock
    SEND_BYTE = 3'd3,      // the raw byte, or the escape
    SEND_ESC = 3'd4,       // the escaped byte's second half
    SEND_END = 3'd5;       // the closing 0xC0

reg [2:0]  send_reg = SEND_IDLE;
reg        hello_pending_reg = 1'b0;  // a HELLO is to be answered
reg [7:0]  hello_seq_reg = 8'd0;      // ... with this seq
reg [7:0]  send_seq_reg = 8'd0;       // the seq of the reply going out
reg [6:0]  send_idx_reg = 7'd0;       // its raw byte: 0 type, 1 seq, 2..3 length, payload, CRC
reg [2:0]  crc_bit_reg = 3'd0;
reg [31:0] crc_reg = 32'hFFFFFFFF;

wire hello_busy = send_reg != SEND_IDLE;
wire [31:0] crc_final = ~crc_reg;

reg [7:0] send_raw;
always @* begin
    if (send_idx_reg == 7'd0) begin
        send_raw = WM_PROTO_T_HELLO_REPLY;
    end else if (send_idx_reg == 7'd1) begin
        send_raw = send_seq_reg;
    end else if (send_idx_reg == 7'd2) begin
        send_raw = HELLO_LEN[7:0];
    end else if (send_idx_reg == 7'd3) begin
        send_raw = HELLO_LEN[15:8];
    end else if (send_idx_reg < HELLO_CRC_AT) begin
        send_raw = HELLO_PAYLOAD[8*(send_idx_reg - 7'd4) +: 8];
    end else begin
        send_raw = crc_final[8*(send_idx_reg - HELLO_CRC_AT) +: 8];
    end
end

wire send_escaped = send_raw == WM_PROTO_SLIP_END || send_raw == WM_PROTO_SLIP_ESC;

wire [15:0] hdr_w = hdr_reg[15:0];
wire [15:0] hdr_h = hdr_reg[31:16];
wire [7:0]  hdr_m = hdr_reg[39:32];
wire [23:0] hdr_tau = hdr_reg[63:40];

// blocks per row and column for a header: ceil((n - 1) / 2^M)
function [15:0] blocks;
    input [15:0] n;
    input [3:0] m;
    begin
        blocks = ((n - 16'd1) + ((16'd1 << m) - 16'd1)) >> m;
    end
endfunction

/*
 * Silence timeout: a header or job that stops mid-way is dropped, the stage reset
 */
reg [TIMEOUT_BITS:0] silence_reg = {(TIMEOUT_BITS + 1){1'b0}};
reg                  stage_rst_reg = 1'b0;
wire                 timed_out = silence_reg[TIMEOUT_BITS];
wire                 stage_rst = rst || stage_rst_reg;

/*
 * The stage: haar_bank -> tlut_stage, the block-end beats to the transmitter
 */
wire [15:0] bank_s_tdata = {rx_tdata, low_reg};
wire        bank_s_tvalid = state_reg == STATE_SAMPLES && rx_tvalid && low_valid_reg;
wire        bank_s_tready;

wire [69:0] rec_tdata;
wire [35:0] rec_tuser;
wire        rec_tvalid;
wire        rec_tready;
wire        rec_tlast;
wire        bank_busy_unused;
wire        bank_done_unused;

haar_bank #(
    .MAX_WIDTH(MAX_WIDTH),
    .MAX_HEIGHT(MAX_HEIGHT),
    .MAX_LEVELS(MAX_LEVELS)
) bank_inst (
    .clk(clk),
    .rst(stage_rst),
    .cfg_width(width_reg),
    .cfg_height(height_reg),
    .cfg_levels(levels_reg),
    .s_axis_tdata(bank_s_tdata),
    .s_axis_tvalid(bank_s_tvalid),
    .s_axis_tready(bank_s_tready),
    .m_axis_tdata(rec_tdata),
    .m_axis_tuser(rec_tuser),
    .m_axis_tvalid(rec_tvalid),
    .m_axis_tready(rec_tready),
    .m_axis_tlast(rec_tlast),
    .busy(bank_busy_unused),
    .frame_done(bank_done_unused)
);

// the template stage without its expander: one beat per block
wire [95:0] tri_tdata_unused;
wire [44:0] tri_tuser;
wire        tri_tvalid;
wire        tri_tready;
wire        tri_tlast_unused;
wire        cfg_error;

tlut_stage #(
    .MAX_COLS(MAX_COLS),
    .EXPAND(0)
) stage_inst (
    .clk(clk),
    .rst(stage_rst),
    .s_axis_tdata(rec_tdata),
    .s_axis_tuser(rec_tuser),
    .s_axis_tvalid(rec_tvalid),
    .s_axis_tready(rec_tready),
    .s_axis_tlast(rec_tlast),
    .m_axis_tdata(tri_tdata_unused),
    .m_axis_tuser(tri_tuser),
    .m_axis_tvalid(tri_tvalid),
    .m_axis_tready(tri_tready),
    .m_axis_tlast(tri_tlast_unused),
    .cfg_width(width_reg),
    .cfg_height(height_reg),
    .cfg_levels(levels_reg),
    .cfg_tau(tau_reg),
    .status_cfg_error(cfg_error)
);

/*
 * Transmitter: the reply bytes, then two bytes per block-end beat
 */
wire [15:0] entry = {7'd0, tri_tuser[11:9], tri_tuser[8:3]};
wire        block_end = tri_tuser[44];

reg        tx_hi_reg = 1'b0;       // the entry's high byte is next
reg [7:0]  tx_tdata;
reg        tx_tvalid;
wire       tx_tready;

// the header's reply waits for a HELLO_REPLY in progress (and the job's entries for the header's reply)
wire reply_go = checked_reg && !hello_busy && !hello_pending_reg;

always @* begin
    tx_tdata = 8'd0;
    tx_tvalid = 1'b0;
    if (hello_busy) begin
        // a HELLO_REPLY frame: only between jobs (a HELLO is read only then, and a header's reply
        // waits for it), so it never splits the job's bytes
        tx_tvalid = send_reg != SEND_CRC;
        case (send_reg)
            SEND_BYTE: tx_tdata = send_escaped ? WM_PROTO_SLIP_ESC : send_raw;
            SEND_ESC: tx_tdata = send_raw == WM_PROTO_SLIP_END ? WM_PROTO_SLIP_ESC_END : WM_PROTO_SLIP_ESC_ESC;
            default: tx_tdata = WM_PROTO_SLIP_END;
        endcase
    end else if (state_reg == STATE_REPLY) begin
        tx_tvalid = reply_go;
        if (reason_reg == 8'd0) begin
            tx_tdata = reply_count_reg == 2'd0 ? "O" : "K";
        end else begin
            tx_tdata = reply_count_reg == 2'd0 ? "E" : reason_reg;
        end
    end else if (tri_tvalid && block_end) begin
        tx_tvalid = 1'b1;
        tx_tdata = tx_hi_reg ? entry[15:8] : entry[7:0];
    end
end

// triangles that are not a block's last are taken at once; a block's last after its second byte
assign tri_tready = !block_end || (state_reg != STATE_REPLY && tx_tready && tx_hi_reg);

wire [7:0] txf_tdata;
wire       txf_tvalid;
wire       txf_tready;
wire [$clog2(TX_DEPTH + 1)-1:0] tx_count_unused;

wm_fifo #(
    .DATA_WIDTH(8),
    .DEPTH(TX_DEPTH)
) tx_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(tx_tdata),
    .s_valid(tx_tvalid),
    .s_ready(tx_tready),
    .m_data(txf_tdata),
    .m_valid(txf_tvalid),
    .m_ready(txf_tready),
    .count(tx_count_unused)
);

wire tx_busy_unused;

uart_tx tx_inst (
    .clk(clk),
    .rst(rst),
    .s_axis_tdata(txf_tdata),
    .s_axis_tvalid(txf_tvalid),
    .s_axis_tready(txf_tready),
    .txd(txd),
    .div(DIV16),
    .busy(tx_busy_unused)
);

/*
 * Control
 */
always @* begin
    rx_tready = 1'b0;
    case (state_reg)
        STATE_HEADER: rx_tready = 1'b1;
        STATE_SAMPLES: rx_tready = !low_valid_reg || bank_s_tready;
        default: rx_tready = 1'b0;
    endcase
end

always @(posedge clk) begin
    if (rx_pin_tvalid && !rx_fifo_ready) begin
        overrun_reg <= 1'b1;
    end

    case (state_reg)
        STATE_HEADER: begin
            if (rx_tvalid) begin
                if (hdr_count_reg < 4'd2 && (frame_reg != FRAME_NONE || rx_tdata == WM_PROTO_SLIP_END)) begin
                    // a wire-protocol frame (not inside a header: its fields may hold any byte)
                    hdr_count_reg <= 4'd0;
                    case (frame_reg)
                        FRAME_START: begin
                            if (rx_tdata == WM_PROTO_T_HELLO) begin
                                frame_reg <= FRAME_SEQ;
                            end else if (rx_tdata != WM_PROTO_SLIP_END && rx_tdata != 8'd0
                                         && rx_tdata <= WM_PROTO_HOST_TYPE_MAX) begin
                                frame_reg <= FRAME_SKIP;
                            end else if (rx_tdata != WM_PROTO_SLIP_END) begin
                                // not a frame after all: the byte goes to the "WM" matcher
                                frame_reg <= FRAME_NONE;
                                hdr_count_reg <= rx_tdata == "W" ? 4'd1 : 4'd0;
                            end
                        end
                        FRAME_SEQ: begin
                            seq_reg <= rx_tdata;
                            frame_reg <= rx_tdata == WM_PROTO_SLIP_END ? FRAME_START
                                       : (rx_tdata == WM_PROTO_SLIP_ESC ? FRAME_SEQ_ESC : FRAME_HELLO);
                        end
                        FRAME_SEQ_ESC: begin
                            seq_reg <= rx_tdata == WM_PROTO_SLIP_ESC_END ? WM_PROTO_SLIP_END : WM_PROTO_SLIP_ESC;
                            frame_reg <= FRAME_HELLO;
                        end
                        FRAME_HELLO, FRAME_SKIP: begin
                            if (rx_tdata == WM_PROTO_SLIP_END) begin
                                // the frame's end (and maybe the next one's start)
                                frame_reg <= FRAME_START;
                                if (frame_reg == FRAME_HELLO && !hello_busy) begin
                                    hello_pending_reg <= 1'b1;
                                    hello_seq_reg <= seq_reg;
                                end
                            end
                        end
                        default: frame_reg <= FRAME_START;  // FRAME_NONE: its 0xC0
                    endcase
                end else if (hdr_count_reg == 4'd0) begin
                    // skip to the "W" of "WM"
                    hdr_count_reg <= rx_tdata == "W" ? 4'd1 : 4'd0;
                end else if (hdr_count_reg == 4'd1) begin
                    hdr_count_reg <= rx_tdata == "M" ? 4'd2 : (rx_tdata == "W" ? 4'd1 : 4'd0);
                end else begin
                    hdr_reg <= {rx_tdata, hdr_reg[63:8]};
                    hdr_count_reg <= hdr_count_reg + 4'd1;
                    if (hdr_count_reg == 4'd9) begin
                        state_reg <= STATE_REPLY;
                        reply_count_reg <= 2'd0;
                    end
                end
            end
        end
        STATE_REPLY: begin
            // the header is complete in hdr_reg: check it while the first reply byte waits
            if (!checked_reg) begin
                width_reg <= hdr_w;
                height_reg <= hdr_h;
                levels_reg <= hdr_m[3:0];
                tau_reg <= hdr_tau > 24'h3FFFF ? 18'h3FFFF : hdr_tau[17:0];
                if (hdr_w < 16'd2 || hdr_w > MAX_WIDTH || hdr_h < 16'd2 || hdr_h > MAX_HEIGHT) begin
                    reason_reg <= "W";
                end else if (hdr_m < 8'd1 || hdr_m > MAX_LEVELS) begin
                    reason_reg <= "M";
                end else if (blocks(hdr_w, hdr_m[3:0]) > MAX_COLS) begin
                    reason_reg <= "C";
                end else begin
                    reason_reg <= 8'd0;
                end
                samples_left_reg <= hdr_w * hdr_h;
                blocks_left_reg <= blocks(hdr_w, hdr_m[3:0]) * blocks(hdr_h, hdr_m[3:0]);
                checked_reg <= 1'b1;
            end else if (reply_go && tx_tready) begin
                reply_count_reg <= reply_count_reg + 2'd1;
                if (reply_count_reg == 2'd1) begin
                    checked_reg <= 1'b0;
                    tx_hi_reg <= 1'b0;
                    state_reg <= reason_reg == 8'd0 ? STATE_SAMPLES : STATE_HEADER;
                    low_valid_reg <= 1'b0;
                end
            end
        end
        STATE_SAMPLES, STATE_DRAIN: begin
            if (state_reg == STATE_SAMPLES && rx_tvalid && rx_tready) begin
                if (!low_valid_reg) begin
                    low_reg <= rx_tdata;
                    low_valid_reg <= 1'b1;
                end else begin
                    low_valid_reg <= 1'b0;
                    samples_left_reg <= samples_left_reg - 32'd1;
                    if (samples_left_reg == 32'd1) begin
                        state_reg <= STATE_DRAIN;
                    end
                end
            end
            if (tri_tvalid && block_end && tx_tready) begin
                tx_hi_reg <= !tx_hi_reg;
                if (tx_hi_reg) begin
                    blocks_left_reg <= blocks_left_reg - 32'd1;
                end
            end
            if (state_reg == STATE_DRAIN && blocks_left_reg == 32'd0) begin
                state_reg <= STATE_HEADER;
            end
        end
        default: state_reg <= STATE_HEADER;
    endcase

    if (state_reg != STATE_HEADER) begin
        hdr_count_reg <= 4'd0;
    end

    // silence: counted while a header is partly in or samples are due; any received byte restarts it
    stage_rst_reg <= 1'b0;
    if (rx_pin_tvalid || !(state_reg == STATE_SAMPLES
                           || (state_reg == STATE_HEADER && (hdr_count_reg != 4'd0
                                                             || frame_reg > FRAME_START)))) begin
        silence_reg <= {(TIMEOUT_BITS + 1){1'b0}};
    end else if (!timed_out) begin
        silence_reg <= silence_reg + 1'b1;
    end
    if (timed_out) begin
        // drop the header or job: back to looking for "WM", the stage reset for a cycle
        silence_reg <= {(TIMEOUT_BITS + 1){1'b0}};
        state_reg <= STATE_HEADER;
        hdr_count_reg <= 4'd0;
        frame_reg <= FRAME_NONE;
        low_valid_reg <= 1'b0;
        tx_hi_reg <= 1'b0;
        stage_rst_reg <= 1'b1;
    end

    // the HELLO_REPLY sender: C0, then each raw byte through the CRC and out (escaped), then C0
    case (send_reg)
        SEND_IDLE: begin
            if (hello_pending_reg) begin
                hello_pending_reg <= 1'b0;
                send_seq_reg <= hello_seq_reg;
                send_idx_reg <= 7'd0;
                crc_reg <= 32'hFFFFFFFF;
                send_reg <= SEND_START;
            end
        end
        SEND_START: begin
            if (tx_tready) begin
                crc_bit_reg <= 3'd0;
                send_reg <= SEND_CRC;
            end
        end
        SEND_CRC: begin
            // the CRC covers type .. payload; its own bytes are sent as they are
            if (send_idx_reg < HELLO_CRC_AT) begin
                crc_reg <= (crc_reg >> 1) ^ ((crc_reg[0] ^ send_raw[crc_bit_reg]) ? CRC32_POLY : 32'd0);
            end
            crc_bit_reg <= crc_bit_reg + 3'd1;
            if (crc_bit_reg == 3'd7 || send_idx_reg >= HELLO_CRC_AT) begin
                send_reg <= SEND_BYTE;
            end
        end
        SEND_BYTE, SEND_ESC: begin
            if (tx_tready) begin
                if (send_reg == SEND_BYTE && send_escaped) begin
                    send_reg <= SEND_ESC;
                end else if (send_idx_reg == HELLO_LAST) begin
                    send_reg <= SEND_END;
                end else begin
                    send_idx_reg <= send_idx_reg + 7'd1;
                    crc_bit_reg <= 3'd0;
                    send_reg <= SEND_CRC;
                end
            end
        end
        SEND_END: begin
            if (tx_tready) begin
                send_reg <= SEND_IDLE;
            end
        end
        default: send_reg <= SEND_IDLE;
    endcase

    if (rst) begin
        state_reg <= STATE_HEADER;
        hdr_count_reg <= 4'd0;
        frame_reg <= FRAME_NONE;
        send_reg <= SEND_IDLE;
        hello_pending_reg <= 1'b0;
        reply_count_reg <= 2'd0;
        silence_reg <= {(TIMEOUT_BITS + 1){1'b0}};
        stage_rst_reg <= 1'b0;
        checked_reg <= 1'b0;
        low_valid_reg <= 1'b0;
        tx_hi_reg <= 1'b0;
        overrun_reg <= 1'b0;
        samples_left_reg <= 32'd0;
        blocks_left_reg <= 32'd0;
    end
end

wire cfg_error_unused = cfg_error;
wire [34:0] tri_tuser_unused = {tri_tuser[43:12], tri_tuser[2:0]};

assign busy = state_reg != STATE_HEADER;
assign rx_overrun = overrun_reg;

endmodule

`resetall
