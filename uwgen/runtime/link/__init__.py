"""The link layer: when a packet leaves and what goes in it. The DESERT connection and its
pacing, the scheduler that picks messages by policy and waiting time, the packer, and the
Link that joins them. Builds on the wire layer; knows delivery only as packet hooks."""
