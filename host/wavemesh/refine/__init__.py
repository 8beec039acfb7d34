"""The refiner: the firmware's C built natively and bound through ctypes, and what runs around it."""
