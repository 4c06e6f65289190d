"""The ways in to a running emulator: the local control socket (``cipstack drive``); all are shells
over the adapter's in-process API (``Adapter.control``, ``Adapter.faults``)."""

from .local_socket import (
    MAX_LINE,
    ControlAddress,
    ControlDenied,
    ControlError,
    ControlRefused,
    ControlServer,
    Handler,
    control_request,
    default_control_path,
    describe,
    is_abstract,
)

__all__ = ["MAX_LINE", "ControlAddress", "ControlDenied", "ControlError", "ControlRefused", "ControlServer",
           "Handler", "control_request", "default_control_path", "describe", "is_abstract"]
