"""The emulator's faults: what can go wrong on the wire and in the device, on demand.

``FAULTS`` declares every fault, its options and its effect (``model``); ``FaultController`` applies
them to a running device's runtime (``cipstack.runtime.DeviceRuntime``), between the wire and the
device, in the seam of each fault's layer."""

from .controller import Fault, FaultController, NoActiveFault
from .errors import FaultError, FaultStateError, NoSuchConnection
from .model import FAULTS, FaultKind, FaultRequest, parse_arguments

__all__ = ["FAULTS", "Fault", "FaultController", "FaultError", "FaultKind", "FaultRequest", "FaultStateError",
           "NoActiveFault", "NoSuchConnection", "parse_arguments"]
