"""A faithful emulator of DESERT UW/APPLICATION sockets and the acoustic channel between them."""
