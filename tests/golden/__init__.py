"""Golden encoded payloads that pin the wire format (docs/protocol.md)."""
