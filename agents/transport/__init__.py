"""The Zenoh transport: one session per process (:mod:`.session`), the fleet bus (:mod:`.bus`), traffic counters."""
