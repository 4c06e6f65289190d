"""The ways in to a running emulator: the local control socket (``cipstack drive``), the HTTP API
(``http``) and scenarios (``scenario``); all are shells over the adapter's in-process API
(``Adapter.control``, ``Adapter.faults``, ``Adapter.events``)."""

from .local_socket import (
    MAX_LINE,
    ControlAddress,
    ControlDenied,
    ControlError,
    ControlRefused,
    ControlServer,
    ControlTaken,
    Handler,
    control_request,
    default_control_path,
    describe,
    holder,
    is_abstract,
    peer_credentials,
    trusted_uid,
    user_text,
)

__all__ = ["MAX_LINE", "ControlAddress", "ControlDenied", "ControlError", "ControlRefused", "ControlServer",
           "ControlTaken", "Handler", "control_request", "default_control_path", "describe", "holder",
           "is_abstract", "peer_credentials", "trusted_uid", "user_text"]
