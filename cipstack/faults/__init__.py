"""The emulator's faults: what can go wrong on the wire and in the device, on demand.

``FAULTS`` declares every fault and its options (``model``); ``FaultController`` applies them to a
running ``Adapter`` (``adapter.faults``), between the wire and the device."""

from .controller import Fault, FaultController, FaultStateError
from .model import FAULTS, FaultError, FaultKind, FaultRequest, NoSuchConnection, parse_arguments

__all__ = ["FAULTS", "Fault", "FaultController", "FaultError", "FaultKind", "FaultRequest", "FaultStateError",
           "NoSuchConnection", "parse_arguments"]
