"""Tests of the link layer: framing, fragments, scheduler, pacing, connection, link."""
