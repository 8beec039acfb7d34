/*
 * wavemesh: the SoC, a PicoRV32 (RV32IMC) with its memories and peripherals
 *
 * The CPU comes from the pythondata-cpu-picorv32 package (picorv32.v, never copied here); with
 * WM_CPU_VEXRISCV defined it is the VexRiscv of pythondata-cpu-vexriscv behind the same native bus
 * (soc_cpu_vexriscv; host/wavemesh/device/soc_cpu.py chooses, docs/soc.md "The CPU").  Memory
 * map (docs/soc.md; generated from host/wavemesh/device/memmap.py into wm_memmap.vh):
 *
 *   0x0000_0000  FW_RAM  firmware RAM (block RAM), FW_RAM_BYTES, loaded from FW_HEX; reset vector 0
 *   0x8000_0000  UART    soc_uart registers
 *   0x8000_0100  SYS     soc_sys registers (cycles, timer, LEDs, stage, halt, configuration)
 *   0x8000_0200  ACCEL   soc_accel registers: the FPGA stage (filter bank, template stage)
 *   0x8000_0300  ENGINE  soc_engine registers: the triangle error engine (E(T)'s scan of HEIGHT)
 *   0x8000_0400  UPLOAD  soc_upload registers: frames from the UART checked, DATA's samples into HEIGHT
 *   0x8000_0800  UPLOAD_BUF  the upload block's payload buffer (1 KB, read only)
 *   0x5000_0000  SDRAM   the 32 MB SDRAM through sdram_ctrl's CPU port (sdram_cache); its areas
 *                        HEIGHT, COEF, TOUT (the stage's) and HEAP start at the *_OFFSET bytes
 *
 * The triangle error engine (soc_engine, tri_engine) reads HEIGHT a row span at a time through the
 * same stream reader (the stage runs before the refiner, never beside it).
 *
 * The upload block (soc_upload, upload_rx), once the firmware enables it, takes the UART's received
 * bytes instead of the CPU: it checks every frame, holds a good one for the CPU and writes an armed
 * DATA frame's samples into HEIGHT through the addressed writer (beside the stage's entries: the two
 * never run together), reading the samples before a Rice frame through the stream reader when its
 * line buffer does not hold them.
 *
 * The FPGA stage (soc_accel) streams HEIGHT from the SDRAM (the controller's stream reader) and
 * hands its coefficient and template entries to sdram_words, which writes each as a sign- or
 * zero-extended 32-bit word through the addressed writer; every halfword the stage writes clears
 * its line in the CPU's cache, so the CPU reads the results after DONE without a flush.
 *
 * Address bits 31..28 select the region; an offset beyond a region's size, or any other address,
 * reads 0 and ignores writes.  Every access but the SDRAM's and a SYS.STAGE write completes in two
 * cycles (request, then mem_ready with the registered read data), so a bad address never stalls the
 * CPU, and with the VexRiscv a write into the firmware RAM in one; an SDRAM access takes 2 cycles on a
 * cache hit and 9-25 on a miss (rtl/README.md, "SDRAM controller").
 *
 * Stage sync: a SYS.STAGE write (the firmware's marker at every switch of its cycle clocks) also
 * starts sdram_ctrl's stage sync and is answered when that ends, a fixed number of cycles later
 * (C_SYNC + 4 in all), with the SDRAM, its controller and the CPU's cache in one fixed state: the
 * cycles of the work after a marker depend on that work alone, not on where the refresh clock
 * stood or what the cache held (docs/soc.md, "Cycle accounting").
 *
 * The simulation ports (uart_bypass and the two byte streams, the stage/halt strobes, uart_div,
 * trap) serve the Verilator board model in sim/; a board ties uart_bypass low and leaves the
 * others open.
 */

`resetall
`timescale 1ns / 1ps
`default_nettype none

`include "wm_memmap.vh"

module soc_top #
(
    // system clock in Hz (reported by SYS.CLK_HZ)
    parameter CLK_HZ = `WM_CLK_HZ,
    // firmware RAM in bytes; a multiple of 4, <= 256 MiB
    parameter FW_RAM_BYTES = `WM_FW_RAM_ENTRIES * 4,
    // $readmemh image of the firmware RAM (one 32-bit word per line), "" for none
    parameter FW_HEX = "",
    // the stage's SDRAM areas: byte offsets (multiples of 4) and sizes in entries (HEIGHT: 16-bit
    // samples, even; COEF and TOUT: 32-bit words)
    parameter HEIGHT_OFFSET = `WM_HEIGHT_OFFSET,
    parameter HEIGHT_SAMPLES = `WM_HEIGHT_ENTRIES,
    parameter COEF_OFFSET = `WM_COEF_OFFSET,
    parameter COEF_ENTRIES = `WM_COEF_ENTRIES,
    parameter TOUT_OFFSET = `WM_TOUT_OFFSET,
    parameter TOUT_ENTRIES = `WM_TOUT_ENTRIES,
    // SDRAM: CAS latency, and the reset's power-up wait in ns (the datasheet's; a simulation that
    // starts with a powered chip model may shorten it)
    parameter SDRAM_CAS_LATENCY = `WM_SDRAM_CAS_LATENCY,
    parameter SDRAM_T_INIT_NS = `WM_SDRAM_T_INIT_NS,
    // the CPU port's cache: lines (power of two >= 2) of LINE_WORDS words
    parameter SDRAM_CACHE_LINES = `WM_SDRAM_CACHE_LINES,
    parameter SDRAM_LINE_WORDS = `WM_SDRAM_LINE_WORDS,
    // UART FIFO depths in bytes; powers of two >= 2
    parameter UART_RX_DEPTH = `WM_UART_RX_DEPTH,
    parameter UART_TX_DEPTH = `WM_UART_TX_DEPTH,
    // UART baud divisor after reset (clock cycles per bit)
    parameter UART_DIV_RESET = `WM_UART_DIV_RESET,
    // LED outputs, 1..32
    parameter LED_COUNT = `WM_LED_COUNT
)
(
    input  wire                  clk,
    input  wire                  rst,

    /*
     * UART pins
     */
    input  wire                  uart_rxd,
    output wire                  uart_txd,

    /*
     * LEDs
     */
    output wire [LED_COUNT-1:0]  led,

    /*
     * SDRAM pins (clocked by the inverted clk; the DQ tristate buffer is at the board's top)
     */
    output wire                  sdram_cke,
    output wire                  sdram_cs_n,
    output wire                  sdram_ras_n,
    output wire                  sdram_cas_n,
    output wire                  sdram_we_n,
    output wire [1:0]            sdram_ba,
    output wire [`WM_SDRAM_ROW_BITS-1:0] sdram_a,
    output wire [1:0]            sdram_dqm,
    output wire [15:0]           sdram_dq_o,
    output wire                  sdram_dq_oe,
    input  wire [15:0]           sdram_dq_i,

    /*
     * Simulation: UART FIFO bypass (fast mode) and observation
     */
    input  wire                  uart_bypass,
    input  wire [7:0]            s_axis_uart_rx_tdata,
    input  wire                  s_axis_uart_rx_tvalid,
    output wire                  s_axis_uart_rx_tready,
    output wire [7:0]            m_axis_uart_tx_tdata,
    output wire                  m_axis_uart_tx_tvalid,
    input  wire                  m_axis_uart_tx_tready,
    output wire [15:0]           uart_div,       // current baud divisor
    output wire                  stage_valid,    // SYS.STAGE written
    output wire [31:0]           stage,
    output wire                  halt_valid,     // SYS.HALT written
    output wire [31:0]           halt_code,
    output wire                  trap            // the CPU trapped (illegal instruction, misaligned)
);


localparam FW_WORDS = FW_RAM_BYTES / 4;
localparam FW_AW = $clog2(FW_WORDS);
localparam COEF_AW = $clog2(COEF_ENTRIES);
localparam TOUT_AW = $clog2(TOUT_ENTRIES);
localparam ROW_BITS = `WM_SDRAM_ROW_BITS;
localparam COL_BITS = `WM_SDRAM_COL_BITS;
localparam HW_BITS = ROW_BITS + 2 + COL_BITS;   // SDRAM halfword address bits

// region limits as byte offsets
localparam [31:0] FW_LIMIT = FW_RAM_BYTES;
localparam [31:0] SDRAM_LIMIT = 32'd2 << HW_BITS;

// check configuration
initial begin
    if (FW_RAM_BYTES < 8 || FW_RAM_BYTES % 4 != 0 || FW_RAM_BYTES > (1 << 28)) begin
        $error("Error: FW_RAM_BYTES must be a multiple of 4, 8 .. 256 MiB (instance %m)");
        $finish;
    end
    if (HEIGHT_SAMPLES < 4 || HEIGHT_SAMPLES % 2 != 0 || COEF_ENTRIES < 2 || TOUT_ENTRIES < 2
            || HEIGHT_OFFSET % 4 != 0 || COEF_OFFSET % 4 != 0 || TOUT_OFFSET % 4 != 0
            || HEIGHT_OFFSET + 2 * HEIGHT_SAMPLES > SDRAM_LIMIT || COEF_OFFSET + 4 * COEF_ENTRIES > SDRAM_LIMIT
            || TOUT_OFFSET + 4 * TOUT_ENTRIES > SDRAM_LIMIT) begin
        $error("Error: the SDRAM areas must be word aligned, inside the SDRAM, HEIGHT_SAMPLES even (instance %m)");
        $finish;
    end
end

/*
 * CPU
 */
wire        mem_valid;
wire        mem_instr_unused;
wire [31:0] mem_addr;
wire [31:0] mem_wdata;
wire [3:0]  mem_wstrb;
reg         mem_ready_reg = 1'b0;   // the two-cycle answer of every region but the SDRAM
wire        sdram_cpu_ready;
wire [31:0] sdram_cpu_rdata;
wire        mem_ready;
reg  [31:0] mem_rdata;

// the VexRiscv's instruction bus: the firmware RAM's port B (word address, the RAM's own bits)
wire        ibus_en;
wire [29:0] ibus_addr;
wire [31:0] ibus_rdata;

`ifdef WM_CPU_VEXRISCV
// the VexRiscv with its caches: its data bus on the native bus, its instruction bus on the firmware
// RAM's port B (host/wavemesh/device/soc_cpu.py chooses)
soc_cpu_vexriscv #(
    .PROGADDR_RESET(32'h0000_0000),
    .FETCH_LIMIT(FW_LIMIT)
) cpu_inst (
    .clk(clk),
    .rst(rst),
    .trap(trap),
    .mem_valid(mem_valid),
    .mem_instr(mem_instr_unused),
    .mem_ready(mem_ready),
    .mem_addr(mem_addr),
    .mem_wdata(mem_wdata),
    .mem_wstrb(mem_wstrb),
    .mem_rdata(mem_rdata),
    .ibus_en(ibus_en),
    .ibus_addr(ibus_addr),
    .ibus_rdata(ibus_rdata)
);
`else
// the PicoRV32 fetches on the native bus
assign ibus_en = 1'b0;
assign ibus_addr = 30'd0;
wire ibus_rdata_unused = ^ibus_rdata;

wire        mem_la_read_unused;
wire        mem_la_write_unused;
wire [31:0] mem_la_addr_unused;
wire [31:0] mem_la_wdata_unused;
wire [3:0]  mem_la_wstrb_unused;
wire        pcpi_valid_unused;
wire [31:0] pcpi_insn_unused;
wire [31:0] pcpi_rs1_unused;
wire [31:0] pcpi_rs2_unused;
wire [31:0] eoi_unused;
wire        trace_valid_unused;
wire [35:0] trace_data_unused;

picorv32 #(
    .ENABLE_COUNTERS(1),
    .ENABLE_COUNTERS64(1),
    .ENABLE_REGS_16_31(1),
    .ENABLE_REGS_DUALPORT(1),
    .BARREL_SHIFTER(1),
    .COMPRESSED_ISA(1),
    .CATCH_MISALIGN(1),
    .CATCH_ILLINSN(1),
    .ENABLE_PCPI(0),
    .ENABLE_MUL(0),
    .ENABLE_FAST_MUL(1),
    .ENABLE_DIV(1),
    .ENABLE_IRQ(0),
    .ENABLE_TRACE(0),
    .PROGADDR_RESET(32'h0000_0000),
    .STACKADDR(FW_LIMIT)
) cpu_inst (
    .clk(clk),
    .resetn(!rst),
    .trap(trap),
    .mem_valid(mem_valid),
    .mem_instr(mem_instr_unused),
    .mem_ready(mem_ready),
    .mem_addr(mem_addr),
    .mem_wdata(mem_wdata),
    .mem_wstrb(mem_wstrb),
    .mem_rdata(mem_rdata),
    .mem_la_read(mem_la_read_unused),
    .mem_la_write(mem_la_write_unused),
    .mem_la_addr(mem_la_addr_unused),
    .mem_la_wdata(mem_la_wdata_unused),
    .mem_la_wstrb(mem_la_wstrb_unused),
    .pcpi_valid(pcpi_valid_unused),
    .pcpi_insn(pcpi_insn_unused),
    .pcpi_rs1(pcpi_rs1_unused),
    .pcpi_rs2(pcpi_rs2_unused),
    .pcpi_wr(1'b0),
    .pcpi_rd(32'd0),
    .pcpi_wait(1'b0),
    .pcpi_ready(1'b0),
    .irq(32'd0),
    .eoi(eoi_unused),
    .trace_valid(trace_valid_unused),
    .trace_data(trace_data_unused)
);
`endif

/*
 * Address decoding
 */
localparam [2:0]
    SEL_NONE   = 3'd0,
    SEL_FW     = 3'd1,
    SEL_ENGINE = 3'd2,
    SEL_UPLOAD = 3'd3,
    SEL_UART   = 3'd5,
    SEL_SYS    = 3'd6,
    SEL_ACCEL  = 3'd7;

reg [2:0] sel_reg = SEL_NONE;

wire [3:0] region = mem_addr[31:28];
wire [31:0] offset = {4'd0, mem_addr[27:0]};
wire io_page = region == `WM_REGION_IO && mem_addr[27:12] == 16'd0;

wire fw_hit = region == `WM_REGION_FW_RAM && offset < FW_LIMIT;
wire sdram_hit = region == `WM_REGION_SDRAM && offset < SDRAM_LIMIT;
wire uart_hit = io_page && mem_addr[11:8] == `WM_IO_UART;
wire sys_hit = io_page && mem_addr[11:8] == `WM_IO_SYS;
wire accel_hit = io_page && mem_addr[11:8] == `WM_IO_ACCEL;
wire engine_hit = io_page && mem_addr[11:8] == `WM_IO_ENGINE;
wire upload_hit = io_page && mem_addr[11:8] == `WM_IO_UPLOAD;
// the payload window: I/O blocks WM_IO_UPLOAD_BUF .. + 3 (1 KB)
localparam [3:0] UPBUF_BLOCK = `WM_IO_UPLOAD_BUF;
wire upbuf_hit = region == `WM_REGION_IO && mem_addr[27:12] == 16'd0 && mem_addr[11:10] == UPBUF_BLOCK[3:2];

// a request is the first cycle of mem_valid; mem_ready answers it in the next cycle, except in the
// SDRAM, whose port holds the request until it answers, and for a SYS.STAGE write, answered when
// the stage sync it starts has ended
reg sync_wait_reg = 1'b0;
wire sdram_sync_busy;
wire req = mem_valid && !mem_ready_reg && !sdram_hit && !sync_wait_reg;
// With the VexRiscv a write into the firmware RAM is answered in its own cycle (the RAM takes it at
// that cycle's edge), so that its write-through stores (a call's saved registers, the stack's spills)
// go one a cycle instead of one every two; the PicoRV32 keeps the two-cycle answer.
`ifdef WM_CPU_VEXRISCV
localparam FW_WRITE_NOW = 1'b1;
`else
localparam FW_WRITE_NOW = 1'b0;
`endif
wire fw_write_now = FW_WRITE_NOW && req && fw_hit && mem_wstrb != 4'd0;
assign mem_ready = mem_ready_reg || sdram_cpu_ready || fw_write_now;
wire stage_write = req && sys_hit && mem_wstrb != 4'd0 && mem_addr[7:0] == `WM_SYS_STAGE;

reg [2:0] sel;
always @* begin
    if (fw_hit) sel = SEL_FW;
    else if (uart_hit) sel = SEL_UART;
    else if (sys_hit) sel = SEL_SYS;
    else if (accel_hit) sel = SEL_ACCEL;
    else if (engine_hit) sel = SEL_ENGINE;
    else if (upload_hit || upbuf_hit) sel = SEL_UPLOAD;
    else sel = SEL_NONE;
end

always @(posedge clk) begin
    // every other request is answered in the next cycle, mapped or not
    mem_ready_reg <= (req && !stage_write && !fw_write_now) || (sync_wait_reg && !sdram_sync_busy);
    sync_wait_reg <= sync_wait_reg ? sdram_sync_busy : stage_write;
    if (req) begin
        sel_reg <= sel;
    end

    if (rst) begin
        mem_ready_reg <= 1'b0;
        sync_wait_reg <= 1'b0;
        sel_reg <= SEL_NONE;
    end
end

wire [31:0] fw_rdata;
wire [31:0] uart_rdata;
wire [31:0] sys_rdata;
wire [31:0] accel_rdata;
wire [31:0] engine_rdata;
wire [31:0] upload_rdata;

always @* begin
    if (sdram_cpu_ready) begin
        mem_rdata = sdram_cpu_rdata;
    end else begin
        case (sel_reg)
            SEL_FW: mem_rdata = fw_rdata;
            SEL_UART: mem_rdata = uart_rdata;
            SEL_SYS: mem_rdata = sys_rdata;
            SEL_ACCEL: mem_rdata = accel_rdata;
            SEL_ENGINE: mem_rdata = engine_rdata;
            SEL_UPLOAD: mem_rdata = upload_rdata;
            default: mem_rdata = 32'd0;
        endcase
    end
end

/*
 * The FPGA stage and its streams into the SDRAM
 */
wire                accel_busy_unused;
wire                height_start;
wire [31:0]         height_count;
wire [15:0]         height_tdata;
wire                height_tvalid, height_tready;
wire [17:0]         coef_tdata;
wire [COEF_AW-1:0]  coef_tuser;
wire                coef_tvalid, coef_tready;
wire [15:0]         tout_tdata;
wire [TOUT_AW-1:0]  tout_tuser;
wire                tout_tvalid, tout_tready;
wire                words_busy, wa_busy;
// soc_accel refuses W H above HEIGHT_SAMPLES, so the count fits the stream reader's length
wire height_count_unused = ^height_count[31:HW_BITS+1];

soc_accel #(
    .HEIGHT_SAMPLES(HEIGHT_SAMPLES),
    .COEF_ENTRIES(COEF_ENTRIES),
    .TOUT_ENTRIES(TOUT_ENTRIES)
) accel_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && accel_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(accel_rdata),
    .busy(accel_busy_unused),
    .height_start(height_start),
    .height_count(height_count),
    .s_axis_height_tdata(height_tdata),
    .s_axis_height_tvalid(height_tvalid),
    .s_axis_height_tready(height_tready),
    .m_axis_coef_tdata(coef_tdata),
    .m_axis_coef_tuser(coef_tuser),
    .m_axis_coef_tvalid(coef_tvalid),
    .m_axis_coef_tready(coef_tready),
    .m_axis_tout_tdata(tout_tdata),
    .m_axis_tout_tuser(tout_tuser),
    .m_axis_tout_tvalid(tout_tvalid),
    .m_axis_tout_tready(tout_tready),
    .mem_idle(!words_busy && !wa_busy && !coef_tvalid && !tout_tvalid)
);

// the height stream's command: held from height_start until the reader takes it (it is idle then:
// the last run's stream ended before its DONE)
reg rd_cmd_valid_reg = 1'b0;
reg [HW_BITS:0] rd_cmd_len_reg = {(HW_BITS+1){1'b0}};
wire rd_cmd_ready;

always @(posedge clk) begin
    if (height_start) begin
        rd_cmd_valid_reg <= 1'b1;
        rd_cmd_len_reg <= height_count[HW_BITS:0];
    end else if (rd_cmd_ready) begin
        rd_cmd_valid_reg <= 1'b0;
    end
    if (rst) begin
        rd_cmd_valid_reg <= 1'b0;
    end
end

localparam [HW_BITS-2:0] COEF_WORD = COEF_OFFSET / 4;
localparam [HW_BITS-2:0] TOUT_WORD = TOUT_OFFSET / 4;
localparam [HW_BITS-1:0] HEIGHT_HW = HEIGHT_OFFSET / 2;

/*
 * The triangle error engine: its row spans through the same stream reader.  The reader holds two
 * commands (the one handing out its data and the next, whose reads follow the first's), so the data go
 * to the commands' owners in the order they were taken (a queue of two, below); the stage's command wins
 * (the two never run together: the stage runs before the refiner).
 */
localparam ENGINE_CB = `WM_ENGINE_COORD_BITS;
wire [HW_BITS-1:0]  eng_rd_addr;
wire [ENGINE_CB:0]  eng_rd_len;
wire                eng_rd_valid, eng_rd_ready;
wire                eng_data_valid, eng_data_ready;
wire                engine_busy_unused;
wire [15:0]         rd_tdata;
wire                rd_tvalid, rd_tready;
reg  [1:0]          rd_owner_reg = 2'd0;     // whose data the reader hands out now
reg                 rd_owner_valid_reg = 1'b0;
reg  [1:0]          rd_owner2_reg = 2'd0;    // the next command's owner, taken before those data are out
reg                 rd_owner2_valid_reg = 1'b0;
wire                rd_tlast;

soc_engine #(
    .ADDR_BITS(HW_BITS),
    .HEIGHT_BASE(HEIGHT_HW)
) engine_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && engine_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(engine_rdata),
    .m_rd_addr(eng_rd_addr),
    .m_rd_len(eng_rd_len),
    .m_rd_valid(eng_rd_valid),
    .m_rd_ready(eng_rd_ready),
    .s_rd_data(rd_tdata),
    .s_rd_valid(eng_data_valid),
    .s_rd_ready(eng_data_ready),
    .busy(engine_busy_unused)
);

/*
 * The upload block: the UART's received bytes (while it is enabled), its samples through the addressed
 * writer (below), its line buffer's reloads through the stream reader (it never runs beside the
 * stage or the engine: the upload ends before the job starts)
 */
wire [7:0]          up_rx_tdata;
wire                up_rx_tvalid, up_rx_tready, up_rx_enable;
wire [15:0]         up_wa_tdata;
wire [HW_BITS-1:0]  up_wa_tuser;
wire                up_wa_tvalid, up_wa_tready;
wire [HW_BITS-1:0]  up_rd_addr;
wire [HW_BITS:0]    up_rd_len;
wire                up_rd_valid, up_rd_ready;
wire                up_data_valid, up_data_ready;
wire                upload_busy_unused;

soc_upload #(
    .ADDR_BITS(HW_BITS),
    .HEIGHT_BASE(HEIGHT_HW)
) upload_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && upload_hit),
    .buf_valid(req && upbuf_hit),
    .bus_addr(mem_addr[9:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(upload_rdata),
    .s_axis_rx_tdata(up_rx_tdata),
    .s_axis_rx_tvalid(up_rx_tvalid),
    .s_axis_rx_tready(up_rx_tready),
    .rx_enable(up_rx_enable),
    .m_wa_tdata(up_wa_tdata),
    .m_wa_tuser(up_wa_tuser),
    .m_wa_tvalid(up_wa_tvalid),
    .m_wa_tready(up_wa_tready),
    .wa_busy(wa_busy),
    .m_rd_addr(up_rd_addr),
    .m_rd_len(up_rd_len),
    .m_rd_valid(up_rd_valid),
    .m_rd_ready(up_rd_ready),
    .s_rd_tdata(rd_tdata),
    .s_rd_tvalid(up_data_valid),
    .s_rd_tready(up_data_ready),
    .busy(upload_busy_unused)
);

// the stream reader's commands: the stage's first, then the engine's, then the upload's; the data go to
// the owner of the oldest command not yet done (rd_owner_reg: 0 the stage, 1 the engine, 2 the upload)
localparam [1:0] OWN_STAGE = 2'd0, OWN_ENGINE = 2'd1, OWN_UPLOAD = 2'd2;
wire [HW_BITS-1:0] rd_addr = rd_cmd_valid_reg ? HEIGHT_HW : eng_rd_valid ? eng_rd_addr : up_rd_addr;
wire [HW_BITS:0] rd_len = rd_cmd_valid_reg ? rd_cmd_len_reg
                        : eng_rd_valid ? {{(HW_BITS-ENGINE_CB){1'b0}}, eng_rd_len} : up_rd_len;
wire rd_valid = rd_cmd_valid_reg || eng_rd_valid || up_rd_valid;
assign eng_rd_ready = rd_cmd_ready && !rd_cmd_valid_reg;
assign up_rd_ready = rd_cmd_ready && !rd_cmd_valid_reg && !eng_rd_valid;
assign height_tdata = rd_tdata;
assign height_tvalid = rd_tvalid && rd_owner_reg == OWN_STAGE;
assign eng_data_valid = rd_tvalid && rd_owner_reg == OWN_ENGINE;
assign up_data_valid = rd_tvalid && rd_owner_reg == OWN_UPLOAD;
assign rd_tready = rd_owner_reg == OWN_ENGINE ? eng_data_ready
                 : rd_owner_reg == OWN_UPLOAD ? up_data_ready : height_tready;

// the owners in the reader's order (it holds two commands: the one handing out its data and the next,
// popped at each command's tlast); a command of length 0 hands out nothing and is not queued
wire rd_push = rd_valid && rd_cmd_ready && rd_len != {(HW_BITS+1){1'b0}};
wire rd_pop = rd_tvalid && rd_tready && rd_tlast;
wire [1:0] rd_push_owner = rd_cmd_valid_reg ? OWN_STAGE : eng_rd_valid ? OWN_ENGINE : OWN_UPLOAD;
always @(posedge clk) begin
    if (rd_push && (!rd_owner_valid_reg || rd_pop)) begin
        rd_owner_reg <= rd_push_owner;
        rd_owner_valid_reg <= 1'b1;
    end else if (rd_pop) begin
        rd_owner_reg <= rd_owner2_reg;
        rd_owner_valid_reg <= rd_owner2_valid_reg;
        rd_owner2_valid_reg <= 1'b0;
    end
    if (rd_push && rd_owner_valid_reg && !rd_pop) begin
        rd_owner2_reg <= rd_push_owner;
        rd_owner2_valid_reg <= 1'b1;
    end
    if (rst) begin
        rd_owner_reg <= OWN_STAGE;
        rd_owner_valid_reg <= 1'b0;
        rd_owner2_valid_reg <= 1'b0;
    end
end

// entries as words: details sign-extended into COEF, template entries zero-extended into TOUT
wire [15:0]        words_tdata;
wire [HW_BITS-1:0] words_tuser;
wire               words_tvalid, words_tready;
// the addressed writer takes the stage's words or the upload's samples (never both at once; the
// stage's first)
wire [15:0]        wa_tdata = words_tvalid ? words_tdata : up_wa_tdata;
wire [HW_BITS-1:0] wa_tuser = words_tvalid ? words_tuser : up_wa_tuser;
wire               wa_tvalid = words_tvalid || up_wa_tvalid;
wire               wa_tready;
assign words_tready = wa_tready;
assign up_wa_tready = wa_tready && !words_tvalid;

sdram_words #(
    .HW_ADDR_BITS(HW_BITS)
) words_inst (
    .clk(clk),
    .rst(rst),
    .s_axis_a_tdata({{14{coef_tdata[17]}}, coef_tdata}),
    .s_axis_a_tuser(COEF_WORD + {{(HW_BITS-1-COEF_AW){1'b0}}, coef_tuser}),
    .s_axis_a_tvalid(coef_tvalid),
    .s_axis_a_tready(coef_tready),
    .s_axis_b_tdata({16'd0, tout_tdata}),
    .s_axis_b_tuser(TOUT_WORD + {{(HW_BITS-1-TOUT_AW){1'b0}}, tout_tuser}),
    .s_axis_b_tvalid(tout_tvalid),
    .s_axis_b_tready(tout_tready),
    .m_axis_tdata(words_tdata),
    .m_axis_tuser(words_tuser),
    .m_axis_tvalid(words_tvalid),
    .m_axis_tready(words_tready),
    .busy(words_busy)
);

/*
 * SDRAM controller: the CPU port (cache), the stage's height stream and its entries; the stream
 * writer is not used
 */
wire init_done_unused, rd_busy_unused, wr_busy_unused;
wire wr_cmd_ready_unused, wr_tready_unused;

sdram_ctrl #(
    .CLK_HZ(CLK_HZ),
    .CAS_LATENCY(SDRAM_CAS_LATENCY),
    .ROW_BITS(ROW_BITS),
    .COL_BITS(COL_BITS),
    .T_INIT_NS(SDRAM_T_INIT_NS),
    .T_RCD_NS(`WM_SDRAM_T_RCD_NS),
    .T_RP_NS(`WM_SDRAM_T_RP_NS),
    .T_RAS_NS(`WM_SDRAM_T_RAS_NS),
    .T_RC_NS(`WM_SDRAM_T_RC_NS),
    .T_RFC_NS(`WM_SDRAM_T_RFC_NS),
    .T_RRD_NS(`WM_SDRAM_T_RRD_NS),
    .T_WR_NS(`WM_SDRAM_T_WR_NS),
    .T_WR_MIN_CK(`WM_SDRAM_T_WR_MIN_CK),
    .T_MRD_CK(`WM_SDRAM_T_MRD_CK),
    .T_HZ_NS(`WM_SDRAM_T_HZ_NS),
    .T_REFI_NS(`WM_SDRAM_T_REFI_NS),
    .CACHE_LINES(SDRAM_CACHE_LINES),
    .LINE_WORDS(SDRAM_LINE_WORDS)
) sdram_inst (
    .clk(clk),
    .rst(rst),
    .cpu_valid(mem_valid && sdram_hit),
    .cpu_addr(mem_addr[HW_BITS:0]),
    .cpu_wdata(mem_wdata),
    .cpu_wstrb(mem_wstrb),
    .cpu_ready(sdram_cpu_ready),
    .cpu_rdata(sdram_cpu_rdata),
    .s_rd_cmd_addr(rd_addr),
    .s_rd_cmd_len(rd_len),
    .s_rd_cmd_valid(rd_valid),
    .s_rd_cmd_ready(rd_cmd_ready),
    .m_axis_rd_tdata(rd_tdata),
    .m_axis_rd_tvalid(rd_tvalid),
    .m_axis_rd_tready(rd_tready),
    .m_axis_rd_tlast(rd_tlast),
    .s_wr_cmd_addr({HW_BITS{1'b0}}),
    .s_wr_cmd_len({(HW_BITS+1){1'b0}}),
    .s_wr_cmd_valid(1'b0),
    .s_wr_cmd_ready(wr_cmd_ready_unused),
    .s_axis_wr_tdata(16'd0),
    .s_axis_wr_tvalid(1'b0),
    .s_axis_wr_tready(wr_tready_unused),
    .s_axis_wa_tdata(wa_tdata),
    .s_axis_wa_tuser(wa_tuser),
    .s_axis_wa_tvalid(wa_tvalid),
    .s_axis_wa_tready(wa_tready),
    .init_done(init_done_unused),
    .rd_busy(rd_busy_unused),
    .wr_busy(wr_busy_unused),
    .wa_busy(wa_busy),
    .sync(stage_write),
    .sync_busy(sdram_sync_busy),
    .sdram_cke(sdram_cke),
    .sdram_cs_n(sdram_cs_n),
    .sdram_ras_n(sdram_ras_n),
    .sdram_cas_n(sdram_cas_n),
    .sdram_we_n(sdram_we_n),
    .sdram_ba(sdram_ba),
    .sdram_a(sdram_a),
    .sdram_dqm(sdram_dqm),
    .sdram_dq_o(sdram_dq_o),
    .sdram_dq_oe(sdram_dq_oe),
    .sdram_dq_i(sdram_dq_i)
);

/*
 * Firmware RAM
 */
soc_ram #(
    .WIDTH(32),
    .DEPTH(FW_WORDS),
    .INIT_FILE(FW_HEX)
) fw_ram_inst (
    .clk(clk),
    .en(req && fw_hit),
    .wstrb(mem_wstrb),
    .addr(mem_addr[FW_AW+1:2]),
    .wdata(mem_wdata),
    .rdata(fw_rdata),
    .b_en(ibus_en),
    .b_addr(ibus_addr[FW_AW-1:0]),
    .b_rdata(ibus_rdata)
);
wire ibus_addr_unused = ^ibus_addr[29:FW_AW];

/*
 * Peripherals
 */
soc_uart #(
    .RX_DEPTH(UART_RX_DEPTH),
    .TX_DEPTH(UART_TX_DEPTH),
    .DIV_RESET(UART_DIV_RESET),
    .DIV_MIN(`WM_UART_DIV_MIN)
) uart_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && uart_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(uart_rdata),
    .rxd(uart_rxd),
    .txd(uart_txd),
    .rx_redirect(up_rx_enable),
    .m_axis_rx_tdata(up_rx_tdata),
    .m_axis_rx_tvalid(up_rx_tvalid),
    .m_axis_rx_tready(up_rx_tready),
    .bypass(uart_bypass),
    .s_axis_rx_tdata(s_axis_uart_rx_tdata),
    .s_axis_rx_tvalid(s_axis_uart_rx_tvalid),
    .s_axis_rx_tready(s_axis_uart_rx_tready),
    .m_axis_tx_tdata(m_axis_uart_tx_tdata),
    .m_axis_tx_tvalid(m_axis_uart_tx_tvalid),
    .m_axis_tx_tready(m_axis_uart_tx_tready),
    .div(uart_div)
);

soc_sys #(
    .LED_COUNT(LED_COUNT),
    .CLK_HZ(CLK_HZ),
    .FW_RAM_BYTES(FW_RAM_BYTES),
    .HEIGHT_SAMPLES(HEIGHT_SAMPLES),
    .COEF_ENTRIES(COEF_ENTRIES),
    .TOUT_ENTRIES(TOUT_ENTRIES)
) sys_inst (
    .clk(clk),
    .rst(rst),
    .bus_valid(req && sys_hit),
    .bus_addr(mem_addr[7:0]),
    .bus_wdata(mem_wdata),
    .bus_wstrb(mem_wstrb),
    .bus_rdata(sys_rdata),
    .led(led),
    .stage_valid(stage_valid),
    .stage(stage),
    .halt_valid(halt_valid),
    .halt_code(halt_code)
);

endmodule

`resetall
