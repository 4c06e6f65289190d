"""Ports for the emulators and peers a test starts: chosen by the OS, free for TCP and UDP alike."""

from __future__ import annotations

import socket


def free_port(*hosts: str) -> int:
    """A port number free for both TCP and UDP on every one of ``hosts`` (default 127.0.0.1): an
    adapter listens on both, and two loopback addresses may each need the same number."""
    hosts = hosts or ("127.0.0.1",)
    for _ in range(100):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((hosts[0], 0))
            port = int(probe.getsockname()[1])
        sockets: list[socket.socket] = []
        try:
            for host in hosts:
                for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
                    sockets.append(socket.socket(socket.AF_INET, kind))
                    sockets[-1].bind((host, port))
        except OSError:
            continue
        finally:
            for sock in sockets:
                sock.close()
        return port
    raise RuntimeError(f"no port free for TCP and UDP on {', '.join(hosts)}")
