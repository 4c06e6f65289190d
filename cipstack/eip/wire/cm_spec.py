"""The Connection Manager's declaration (class 0x06): attributes and services. The object itself
(Forward_Open, Unconnected_Send, class 3 connections) is ``connection_manager``; what only names
the object (the catalog a scanner reads names from) needs no more than this, nor the messages'
codecs that module loads."""

from __future__ import annotations

from ...cip.messages import Service
from ...cip.model import AttributeSpec, ClassSpec
from ...cip.types import UINT

CLASS_ID = 0x06
#: Backplane port of a device: a route path "port 1, link 0" addresses the device itself.
BACKPLANE_PORT = 1

SPEC = ClassSpec(
    CLASS_ID, "Connection Manager", revision=1,
    instance_attributes=(
        AttributeSpec(1, "Open Requests", UINT, default=0),
        AttributeSpec(2, "Open Format Rejects", UINT, default=0),
        AttributeSpec(3, "Open Resource Rejects", UINT, default=0),
        AttributeSpec(4, "Open Other Rejects", UINT, default=0),
        AttributeSpec(5, "Close Requests", UINT, default=0),
        AttributeSpec(6, "Close Format Requests", UINT, default=0),
        AttributeSpec(7, "Close Other Requests", UINT, default=0),
        AttributeSpec(8, "Connection Timeouts", UINT, default=0),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=frozenset({
        Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTES_ALL, Service.FORWARD_OPEN,
        Service.LARGE_FORWARD_OPEN, Service.FORWARD_CLOSE, Service.UNCONNECTED_SEND,
    }),
)
