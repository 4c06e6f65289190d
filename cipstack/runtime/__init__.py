"""A running device: its ports, the one power/link state that opens and closes them, the seams where
faults act, and the observers that watch it.

``DeviceRuntime`` is the narrow interface the fault controller (``cipstack.faults``), the event stream
and the command service (``cipstack.control``) work through; none of them knows the ``Adapter`` that
composes it."""

from .observer import RuntimeObserver
from .ports import Class1Port, Medium, Port, Rs485Port, ServerPort
from .power import PowerLink
from .runtime import DeviceRuntime

__all__ = ["Class1Port", "DeviceRuntime", "Medium", "Port", "PowerLink", "Rs485Port", "RuntimeObserver",
           "ServerPort"]
