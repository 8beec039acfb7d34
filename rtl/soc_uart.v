/*
 * wavemesh: the SoC's UART register block (DATA, STATUS, DIV)
 *
 * uart_rx -> RX FIFO -> DATA reads; DATA writes -> TX FIFO -> uart_tx.  Registers (offsets in the
 * block, bits in docs/soc.md, generated from host/wavemesh/device/memmap.py):
 *
 *   0x00 DATA    read: pop the oldest byte [7:0], bit 31 EMPTY when there was none; write: queue [7:0]
 *   0x04 STATUS  RX_VALID, RX_FULL, TX_FULL, TX_EMPTY, TX_IDLE; sticky RX_OVERRUN, RX_FRAME_ERR,
 *                TX_OVERRUN (write 1 to clear); RX_COUNT [31:16]
 *   0x08 DIV     clock cycles per bit [15:0] (writes below DIV_MIN store DIV_MIN)
 *
 * Redirect (rx_redirect, the upload block's CTRL.ENABLE): the RX FIFO's bytes go out on m_axis_rx to
 * the upload block instead of to DATA reads (which then read EMPTY and pop nothing).
 *
 * Bypass (simulation's fast mode; tie bypass low on a board): received bytes come from s_axis_rx
 * into the RX FIFO (with back-pressure, so none are lost) instead of from the pin, and the TX FIFO
 * drains to m_axis_tx instead of the transmitter.
 *
 * Bus: bus_valid is a one-cycle request (bus_wstrb = 0 for a read); bus_rdata is valid in the next
 * cycle.  Any non-zero bus_wstrb writes the whole register.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_uart #
(
    // RX FIFO depth in bytes; 2 .. 32767 (any number: RX_COUNT is 16 bits)
    parameter RX_DEPTH = 64,
    // TX FIFO depth in bytes; 2 .. 32767 (any number)
    parameter TX_DEPTH = 64,
    // baud divisor after reset, clock cycles per bit; DIV_MIN..65535
    parameter DIV_RESET = 217,
    // smallest divisor (the receiver samples mid-bit: >= 4)
    parameter DIV_MIN = 4
)
(
    input  wire        clk,
    input  wire        rst,

    /*
     * Register bus
     */
    input  wire        bus_valid,
    input  wire [7:0]  bus_addr,
    input  wire [31:0] bus_wdata,
    input  wire [3:0]  bus_wstrb,
    output wire [31:0] bus_rdata,

    /*
     * Pins
     */
    input  wire        rxd,
    output wire        txd,

    /*
     * FIFO bypass (simulation fast mode)
     */
    input  wire        bypass,
    input  wire [7:0]  s_axis_rx_tdata,
    input  wire        s_axis_rx_tvalid,
    output wire        s_axis_rx_tready,
    output wire [7:0]  m_axis_tx_tdata,
    output wire        m_axis_tx_tvalid,
    input  wire        m_axis_tx_tready,

    /*
     * Received bytes to the upload block (while rx_redirect)
     */
    input  wire        rx_redirect,
    output wire [7:0]  m_axis_rx_tdata,
    output wire        m_axis_rx_tvalid,
    input  wire        m_axis_rx_tready,

    /*
     * Configuration out
     */
    output wire [15:0] div
);


// check configuration
initial begin
    if (DIV_MIN < 4 || DIV_RESET < DIV_MIN || DIV_RESET > 65535) begin
        $error("Error: need 4 <= DIV_MIN <= DIV_RESET <= 65535 (instance %m)");
        $finish;
    end
end

localparam [15:0] DIV_MIN_W = DIV_MIN[15:0];
localparam [15:0] DIV_RESET_W = DIV_RESET[15:0];

reg [15:0] div_reg = DIV_RESET_W, div_next;
reg rx_overrun_reg = 1'b0, rx_overrun_next;
reg rx_frame_err_reg = 1'b0, rx_frame_err_next;
reg tx_overrun_reg = 1'b0, tx_overrun_next;
reg [31:0] rdata_reg = 32'd0, rdata_next;

// receiver and RX FIFO
wire [7:0] rx_pin_tdata;
wire rx_pin_tvalid;
wire rx_pin_frame_error;
wire rx_busy_unused;

wire [7:0] rx_fifo_in_tdata = bypass ? s_axis_rx_tdata : rx_pin_tdata;
wire rx_fifo_in_tvalid = bypass ? s_axis_rx_tvalid : rx_pin_tvalid;
wire rx_fifo_in_tready;
wire [7:0] rx_fifo_out_tdata;
wire rx_fifo_out_tvalid;
wire [$clog2(RX_DEPTH+1)-1:0] rx_count;

// transmitter and TX FIFO
wire tx_fifo_in_tready;
wire [7:0] tx_fifo_out_tdata;
wire tx_fifo_out_tvalid;
wire tx_fifo_out_tready;
wire [$clog2(TX_DEPTH+1)-1:0] tx_count_unused;
wire tx_pin_tready;
wire tx_busy;

// register accesses (registers use bus_wdata[15:0] at most)
wire [15:0] bus_wdata_high_unused = bus_wdata[31:16];
wire reg_read = bus_valid && bus_wstrb == 4'd0;
wire reg_write = bus_valid && bus_wstrb != 4'd0;
wire data_read = reg_read && bus_addr == `WM_UART_DATA && !rx_redirect;
wire rx_fifo_out_tready = rx_redirect ? m_axis_rx_tready : data_read;
wire data_write = reg_write && bus_addr == `WM_UART_DATA;

assign s_axis_rx_tready = bypass && rx_fifo_in_tready;
assign m_axis_rx_tdata = rx_fifo_out_tdata;
assign m_axis_rx_tvalid = rx_redirect && rx_fifo_out_tvalid;
assign m_axis_tx_tdata = tx_fifo_out_tdata;
assign m_axis_tx_tvalid = bypass && tx_fifo_out_tvalid;
assign tx_fifo_out_tready = bypass ? m_axis_tx_tready : tx_pin_tready;
assign bus_rdata = rdata_reg;
assign div = div_reg;

wire tx_empty = !tx_fifo_out_tvalid;
wire [31:0] status = {
    {(16 - $clog2(RX_DEPTH+1)){1'b0}}, rx_count,        // 31:16 RX_COUNT
    5'd0, tx_overrun_reg, rx_frame_err_reg, rx_overrun_reg, // 10 TX_OVERRUN, 9 FRAME_ERR, 8 RX_OVERRUN
    3'd0,
    tx_empty && !tx_busy,                                 // 4 TX_IDLE
    tx_empty,                                             // 3 TX_EMPTY
    !tx_fifo_in_tready,                                   // 2 TX_FULL
    !rx_fifo_in_tready,                                   // 1 RX_FULL
    rx_fifo_out_tvalid                                    // 0 RX_VALID
};

always @* begin
    div_next = div_reg;
    rx_overrun_next = rx_overrun_reg;
    rx_frame_err_next = rx_frame_err_reg;
    tx_overrun_next = tx_overrun_reg;
    rdata_next = 32'd0;

    if (reg_read) begin
        // read: registered data for the next cycle
        case (bus_addr)
            `WM_UART_DATA: rdata_next = rx_fifo_out_tvalid && !rx_redirect ? {24'd0, rx_fifo_out_tdata}
                                                                           : 32'h8000_0000;
            `WM_UART_STATUS: rdata_next = status;
            `WM_UART_DIV: rdata_next = {16'd0, div_reg};
            default: rdata_next = 32'd0;
        endcase
    end

    if (reg_write) begin
        case (bus_addr)
            `WM_UART_STATUS: begin
                // write 1 to clear the sticky bits
                if (bus_wdata[`WM_UART_STATUS_RX_OVERRUN]) rx_overrun_next = 1'b0;
                if (bus_wdata[`WM_UART_STATUS_RX_FRAME_ERR]) rx_frame_err_next = 1'b0;
                if (bus_wdata[`WM_UART_STATUS_TX_OVERRUN]) tx_overrun_next = 1'b0;
            end
            `WM_UART_DIV: begin
                // new divisor, raised to the smallest the receiver can sample
                div_next = bus_wdata[15:0] < DIV_MIN_W ? DIV_MIN_W : bus_wdata[15:0];
            end
            default: begin
                // DATA is handled by the FIFO; other offsets ignore writes
            end
        endcase
    end

    if (!bypass && rx_pin_tvalid && !rx_fifo_in_tready) begin
        // a byte from the pin found the RX FIFO full
        rx_overrun_next = 1'b1;
    end
    if (!bypass && rx_pin_frame_error) begin
        // a bad stop bit
        rx_frame_err_next = 1'b1;
    end
    if (data_write && !tx_fifo_in_tready) begin
        // a DATA write found the TX FIFO full
        tx_overrun_next = 1'b1;
    end
end

always @(posedge clk) begin
    div_reg <= div_next;
    rx_overrun_reg <= rx_overrun_next;
    rx_frame_err_reg <= rx_frame_err_next;
    tx_overrun_reg <= tx_overrun_next;
    rdata_reg <= rdata_next;

    if (rst) begin
        div_reg <= DIV_RESET_W;
        rx_overrun_reg <= 1'b0;
        rx_frame_err_reg <= 1'b0;
        tx_overrun_reg <= 1'b0;
    end
end

uart_rx uart_rx_inst (
    .clk(clk),
    .rst(rst),
    .rxd(rxd),
    .div(div_reg),
    .m_axis_tdata(rx_pin_tdata),
    .m_axis_tvalid(rx_pin_tvalid),
    .busy(rx_busy_unused),
    .frame_error(rx_pin_frame_error)
);

wm_fifo #(
    .DATA_WIDTH(8),
    .DEPTH(RX_DEPTH)
) rx_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(rx_fifo_in_tdata),
    .s_valid(rx_fifo_in_tvalid),
    .s_ready(rx_fifo_in_tready),
    .m_data(rx_fifo_out_tdata),
    .m_valid(rx_fifo_out_tvalid),
    .m_ready(rx_fifo_out_tready),
    .count(rx_count)
);

wm_fifo #(
    .DATA_WIDTH(8),
    .DEPTH(TX_DEPTH)
) tx_fifo_inst (
    .clk(clk),
    .rst(rst),
    .s_data(bus_wdata[7:0]),
    .s_valid(data_write),
    .s_ready(tx_fifo_in_tready),
    .m_data(tx_fifo_out_tdata),
    .m_valid(tx_fifo_out_tvalid),
    .m_ready(tx_fifo_out_tready),
    .count(tx_count_unused)
);

uart_tx uart_tx_inst (
    .clk(clk),
    .rst(rst),
    .s_axis_tdata(tx_fifo_out_tdata),
    .s_axis_tvalid(tx_fifo_out_tvalid && !bypass),
    .s_axis_tready(tx_pin_tready),
    .txd(txd),
    .div(div_reg),
    .busy(tx_busy)
);

endmodule

`resetall
