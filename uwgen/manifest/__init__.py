"""The network manifest: ids, types, sides and link policy of every topic and service."""
