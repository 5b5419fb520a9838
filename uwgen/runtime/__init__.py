"""What all generated code shares: CBOR primitives, framing, fragments, the DESERT connection, the link scheduler, clocks."""
