"""Tests of the DESERT emulator: channel physics, timing, loss, MAC, scenarios, sockets, CLI."""
