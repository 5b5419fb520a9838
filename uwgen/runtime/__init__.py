"""What every bridge and generated package shares, in three layers that import only downward.

    uwgen.runtime.clock, .stats   clocks (injectable) and counters: used by every layer
    uwgen.runtime.wire            bytes: CBOR and bit-packed codecs, the codec table, DESERT
                                  framing, the wire-format-2 envelope and message heads,
                                  fragments and their repair (FEC)
    uwgen.runtime.link            when and how a packet leaves: the DESERT connection and its
                                  pacing, the link's scheduler and packer, the Link itself
    uwgen.runtime.delivery        what a packet's messages are owed: acknowledgements and
                                  re-sends of reliable entries, staleness and freshness

wire imports nothing of link or delivery; link imports wire; delivery plugs into the link
through its packet hooks (`uwgen.runtime.link.hooks.PacketHooks`).
tests/structure/test_imports.py holds the order.
"""
