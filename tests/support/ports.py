"""ports.py: a free TCP port on loopback, for the servers that tests and benchmarks start."""

import socket


def free_port():
    """A port nothing listens on now (another process may still take it before the caller's
    server binds it; the callers retry or fail clearly)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
