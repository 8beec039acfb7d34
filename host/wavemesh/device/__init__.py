"""The device path: the wire protocol, the link, a session with a board, the memory map, codegen."""
