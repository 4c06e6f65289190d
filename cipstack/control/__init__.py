"""The ways in to a running emulator: the local control socket (``cipstack drive``), the HTTP API
(``http``), scenarios (``scenario``) and a fleet's relay (``http_relay``); all are shells over one
command service (``service``), whose operations are declared once (``operations``)."""

from .local_socket import (
    MAX_LINE,
    ControlAddress,
    ControlDenied,
    ControlError,
    ControlNotFound,
    ControlRefused,
    ControlServer,
    ControlTaken,
    ControlUnreachable,
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

__all__ = ["MAX_LINE", "ControlAddress", "ControlDenied", "ControlError", "ControlNotFound", "ControlRefused",
           "ControlServer", "ControlTaken", "ControlUnreachable", "Handler", "control_request", "default_control_path",
           "describe", "holder", "is_abstract", "peer_credentials", "trusted_uid", "user_text"]
