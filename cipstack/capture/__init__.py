"""Reading captures: TCP reassembly, per-connection timing, decoding by the same declarations
the emulator serves (``cipstack capture analyze``), and scapy layers for EtherNet/IP and CIP.

``from cipstack.capture import ENIP, CPF, CPFItem, CIP, ENIP_IO`` imports scapy (the layers are
bound to TCP/UDP 44818 and UDP 2222 on import). Names load on first use, so the ``cipstack``
command does not pay for this package unless it runs ``capture``.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_WHERE = {
    "Analyzer": "analyzer", "Connection": "analyzer", "Direction": "analyzer", "Totals": "analyzer",
    "Declarations": "decoding",
    "CaptureFormatError": "reader", "Record": "reader", "decode_segment": "reader", "read_records": "reader",
    "ENIP": "layers", "CPF": "layers", "CPFItem": "layers", "CIP": "layers", "CIPConnected": "layers",
    "ENIP_IO": "layers", "bind_layers_to_ports": "layers",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(import_module(f"{__name__}.{module}"), name)


__all__ = sorted(_WHERE)
