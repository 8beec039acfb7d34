# The real boards (docs/boards.md): bitstreams and flashing through tools/boards.py.  Included by the
# Makefile.
#   make bitstream BOARD=ulx3s|icebreaker   synthesis, place and route, packing into build/boards/BOARD/;
#                                           the firmware image (ULX3S) is built first and built in; the
#                                           board's utilisation and fmax go to docs/boards.md
#   make bitstreams                         both
#   make flash BOARD=...                    openFPGALoader: the FPGA's SRAM (FLASH=1: the SPI flash)
#   make postsynth                          the iCEBreaker's synthesised netlist through its cocotb bench
#                                           (Icarus Verilog; minutes, not part of make test)
BOARD ?=
BOARDS := ulx3s icebreaker
SEED ?=  # nextpnr's seed; empty: the board's own (tools/boards.py, BOARDS)
FLASH ?=

.PHONY: bitstream bitstreams flash postsynth

bitstream: $(SETUP_STAMP) gen
	@case " $(BOARDS) " in *" $(BOARD) "*) ;; \
	 *) echo "error: BOARD=$(BOARD) is not a board: make bitstream BOARD=<one of: $(BOARDS)>" >&2; exit 2;; esac
	$(VPY) tools/boards.py bitstream $(BOARD) $(if $(SEED),--seed $(SEED))

bitstreams:
	@for b in $(BOARDS); do $(MAKE) --no-print-directory bitstream BOARD=$$b || exit 1; done

flash: $(SETUP_STAMP)
	@case " $(BOARDS) " in *" $(BOARD) "*) ;; \
	 *) echo "error: BOARD=$(BOARD) is not a board: make flash BOARD=<one of: $(BOARDS)>" >&2; exit 2;; esac
	@$(VPY) tools/boards.py flash $(BOARD) $(if $(FLASH),--flash)

postsynth: $(SETUP_STAMP) gen
	$(VPY) tools/postsynth.py
