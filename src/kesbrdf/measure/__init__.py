"""Paper step 1, acquire: measurements, the virtual and image-based instruments, protocol planning."""
