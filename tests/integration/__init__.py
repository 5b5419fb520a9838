"""Tests across packages: the runtime link against the emulated DESERT nodes."""
