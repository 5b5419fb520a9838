"""The wire layer: bytes in, values out, and back. Codecs (CBOR and bit-packed), the codec
table by manifest id, DESERT framing, the wire-format-2 envelope and its message heads,
fragments and their repair. Pure: no sockets, no scheduling (docs/wire-format.md)."""
