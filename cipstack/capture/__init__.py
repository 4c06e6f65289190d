"""Reading captures: TCP reassembly, per-connection timing, decoding by the same declarations
the emulator serves (``cipstack capture analyze``), and scapy layers for EtherNet/IP and CIP.

``from cipstack.capture import ENIP, CPF, CIP, ENIP_IO`` imports scapy (the layers are bound to
TCP/UDP 44818 and UDP 2222 on import); the analyzer itself does not need it.
"""

from __future__ import annotations

from typing import Any

from .analyzer import Analyzer, Connection, Direction, Totals
from .decoding import Declarations
from .reader import CaptureFormatError, Record, decode_segment, read_records

_LAYERS = ("ENIP", "CPF", "CPFItem", "CIP", "CIPConnected", "ENIP_IO", "bind_layers_to_ports")


def __getattr__(name: str) -> Any:
    if name in _LAYERS:
        from . import layers

        return getattr(layers, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["Analyzer", "CaptureFormatError", "Connection", "Declarations", "Direction", "Record", "Totals",
           "decode_segment", "read_records", *_LAYERS]
