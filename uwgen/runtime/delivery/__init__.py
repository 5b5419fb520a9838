"""The delivery layer: what each message is owed once it is on a packet. Acknowledgement
reports, re-sends of reliable entries, the sender's ledger, staleness and freshness of
messages by their publication time. Plugs into the link as packet hooks."""
