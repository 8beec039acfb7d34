/*
 * wavemesh: the SoC's upload block, upload_rx behind the UPLOAD registers and the payload window
 *
 * With CTRL.ENABLE the block takes the bytes of the UART's RX FIFO (soc_uart's m_axis_rx) instead of
 * the CPU: it deframes and checks every frame, holds a good one for the CPU (STATUS.FRAME, HEADER,
 * the payload in the UPLOAD_BUF window) until a CTRL.RELEASE write, and with CTRL.ARM stores an
 * armed DATA frame's samples into HEIGHT itself (rtl/upload_rx.v).  Registers (UPLOAD block,
 * wm_memmap.vh; docs/soc.md has the bit tables):
 *
 *   0x00 CTRL     rw  bit 0 ENABLE, 1 ARM; w: bit 2 CLEAR, 3 FLUSH, 4 RELEASE (pulses)
 *   0x04 STATUS   r   bit 0 FRAME, 1 DATA, 6..4 CODE, 8 BUSY
 *   0x08 HEADER   r   type 7..0, seq 15..8, len 31..16 of the held frame
 *   0x0C WIDTH, 0x10 SAMPLES, 0x14 TOTAL, 0x18 TIMEOUT   rw  the session (W, W H, words) and the byte timeout
 *   0x1C NEXT, 0x20 CRC, 0x24 BAD_FRAMES                  r   samples stored, their CRC register, drops
 *
 * Bus: bus_valid (registers) or buf_valid (the payload window, a word per address, bus_addr[9:2])
 * is a one-cycle request; bus_rdata is valid in the next cycle, as the other register blocks.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_upload #
(
    // SDRAM halfword address bits
    parameter ADDR_BITS = 24,
    // halfword address of HEIGHT's sample 0
    parameter [ADDR_BITS-1:0] HEIGHT_BASE = {ADDR_BITS{1'b0}},
    // line buffer samples: a power of two above the largest W
    parameter LB_DEPTH = `WM_UPLOAD_LB_DEPTH
)
(
    input  wire                   clk,
    input  wire                   rst,

    /*
     * Register bus and the payload window
     */
    input  wire                   bus_valid,
    input  wire                   buf_valid,
    input  wire [9:0]             bus_addr,
    input  wire [31:0]            bus_wdata,
    input  wire [3:0]             bus_wstrb,
    output wire [31:0]            bus_rdata,

    /*
     * Bytes from the UART's RX FIFO, and whether the block takes them
     */
    input  wire [7:0]             s_axis_rx_tdata,
    input  wire                   s_axis_rx_tvalid,
    output wire                   s_axis_rx_tready,
    output wire                   rx_enable,

    /*
     * SDRAM: addressed writes, stream reads
     */
    output wire [15:0]            m_wa_tdata,
    output wire [ADDR_BITS-1:0]   m_wa_tuser,
    output wire                   m_wa_tvalid,
    input  wire                   m_wa_tready,
    input  wire                   wa_busy,
    output wire [ADDR_BITS-1:0]   m_rd_addr,
    output wire [ADDR_BITS:0]     m_rd_len,
    output wire                   m_rd_valid,
    input  wire                   m_rd_ready,
    input  wire [15:0]            s_rd_tdata,
    input  wire                   s_rd_tvalid,
    output wire                   s_rd_tready,

    output wire                   busy
);

localparam PB_AW = $clog2(`WM_UPLOAD_BUF_BYTES / 4);

// check configuration
initial begin
    if (`WM_UPLOAD_BUF_BYTES != 1024) begin
        $error("Error: the payload window is bus_addr[9:2]: UPLOAD_BUF_BYTES must be 1024 (instance %m)");
        $finish;
    end
end

reg        enable_reg = 1'b0;
reg        arm_reg = 1'b0;
reg [15:0] width_reg = 16'd0;
reg [31:0] samples_reg = 32'd0;
reg [31:0] total_reg = 32'd0;
reg [31:0] timeout_reg = 32'd0;
reg [31:0] rdata_reg = 32'd0, rdata_next;
reg        buf_read_reg = 1'b0;

wire        frame_valid, frame_data;
wire [7:0]  frame_type, frame_seq;
wire [15:0] frame_len;
wire [2:0]  frame_code;
wire [31:0] next_sample, crc, bad_frames;
wire [31:0] buf_rdata;
wire        up_busy;

wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire ctrl_write = bus_valid && bus_wstrb != 4'd0 && bus_addr[7:0] == `WM_UPLOAD_CTRL;
wire [1:0] bus_addr_low_unused = bus_addr[1:0];

assign bus_rdata = buf_read_reg ? buf_rdata : rdata_reg;
assign rx_enable = enable_reg;
assign busy = up_busy;

wire [31:0] status = {23'd0, up_busy, 1'b0, frame_code, 2'd0, frame_data && frame_valid, frame_valid};

always @* begin
    rdata_next = 32'd0;
    if (reg_read) begin
        case (bus_addr[7:0])
            `WM_UPLOAD_CTRL: rdata_next = {30'd0, arm_reg, enable_reg};
            `WM_UPLOAD_STATUS: rdata_next = status;
            `WM_UPLOAD_HEADER: rdata_next = {frame_len, frame_seq, frame_type};
            `WM_UPLOAD_WIDTH: rdata_next = {16'd0, width_reg};
            `WM_UPLOAD_SAMPLES: rdata_next = samples_reg;
            `WM_UPLOAD_TOTAL: rdata_next = total_reg;
            `WM_UPLOAD_TIMEOUT: rdata_next = timeout_reg;
            `WM_UPLOAD_NEXT: rdata_next = next_sample;
            `WM_UPLOAD_CRC: rdata_next = crc;
            `WM_UPLOAD_BAD_FRAMES: rdata_next = bad_frames;
            default: rdata_next = 32'd0;
        endcase
    end
end

always @(posedge clk) begin
    rdata_reg <= rdata_next;
    buf_read_reg <= buf_valid;
    if (bus_valid && bus_wstrb != 4'd0) begin
        case (bus_addr[7:0])
            `WM_UPLOAD_CTRL: begin
                enable_reg <= bus_wdata[`WM_UPLOAD_CTRL_ENABLE];
                arm_reg <= bus_wdata[`WM_UPLOAD_CTRL_ARM];
            end
            `WM_UPLOAD_WIDTH: width_reg <= bus_wdata[15:0];
            `WM_UPLOAD_SAMPLES: samples_reg <= bus_wdata;
            `WM_UPLOAD_TOTAL: total_reg <= bus_wdata;
            `WM_UPLOAD_TIMEOUT: timeout_reg <= bus_wdata;
            default: begin
                // read-only registers ignore writes
            end
        endcase
    end

    if (rst) begin
        enable_reg <= 1'b0;
        arm_reg <= 1'b0;
        buf_read_reg <= 1'b0;
    end
end

upload_rx #(
    .PB_BYTES(`WM_UPLOAD_BUF_BYTES),
    .LB_DEPTH(LB_DEPTH),
    .ADDR_BITS(ADDR_BITS),
    .HEIGHT_BASE(HEIGHT_BASE)
) upload_inst (
    .clk(clk),
    .rst(rst),
    .s_axis_tdata(s_axis_rx_tdata),
    .s_axis_tvalid(s_axis_rx_tvalid && enable_reg),
    .s_axis_tready(s_axis_rx_tready),
    .cfg_arm(arm_reg),
    .cfg_width(width_reg),
    .cfg_samples(samples_reg),
    .cfg_total(total_reg),
    .cfg_timeout(timeout_reg),
    .clear(ctrl_write && bus_wdata[`WM_UPLOAD_CTRL_CLEAR]),
    .flush(ctrl_write && bus_wdata[`WM_UPLOAD_CTRL_FLUSH]),
    .frame_release(ctrl_write && bus_wdata[`WM_UPLOAD_CTRL_RELEASE]),
    .frame_valid(frame_valid),
    .frame_type(frame_type),
    .frame_seq(frame_seq),
    .frame_len(frame_len),
    .frame_data(frame_data),
    .frame_code(frame_code),
    .next_sample(next_sample),
    .crc(crc),
    .bad_frames(bad_frames),
    .buf_addr(bus_addr[PB_AW+1:2]),
    .buf_rdata(buf_rdata),
    .m_wa_tdata(m_wa_tdata),
    .m_wa_tuser(m_wa_tuser),
    .m_wa_tvalid(m_wa_tvalid),
    .m_wa_tready(m_wa_tready),
    .wa_busy(wa_busy),
    .m_rd_addr(m_rd_addr),
    .m_rd_len(m_rd_len),
    .m_rd_valid(m_rd_valid),
    .m_rd_ready(m_rd_ready),
    .s_rd_tdata(s_rd_tdata),
    .s_rd_tvalid(s_rd_tvalid),
    .s_rd_tready(s_rd_tready),
    .busy(up_busy)
);

endmodule

`resetall
