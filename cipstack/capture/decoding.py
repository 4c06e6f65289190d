"""Names and values of what a capture carries, by the project's own declarations.

A target's declarations come from the profile its identity matches (a ListIdentity reply or an
Identity Get_Attributes_All in the capture), from ``--profile/--model``, or from EDS files
(parameters by their link path, assemblies by instance). The codecs are the project's: message
router request/response, EPATH, Forward_Open/Close, Unconnected_Send.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from ..catalog import Catalog
from ..cip.epath import LogicalSegment, LogicalType, PortSegment, decode_path, parse_application_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ..cip.status import CipError, describe_status
from ..cip.units import scaled_text
from ..componet.gateway import COMPONET_PORT
from ..eip.wire.cm_messages import UnconnectedSendRequest

CONNECTION_MANAGER = 0x06
IDENTITY = 0x01


def service_name(code: int) -> str:
    try:
        return "_".join(word.capitalize() for word in Service(code).name.split("_"))
    except ValueError:
        return f"Service 0x{code:02X}"


@dataclass
class Declarations:
    """What names and scales a target's attributes and assemblies."""

    catalog: Catalog = field(default_factory=Catalog)
    #: EDS parameters by link path (class, instance, attribute).
    eds_params: dict[tuple[int, int, int], Any] = field(default_factory=dict)
    #: EDS assembly schemas by instance.
    eds_schemas: dict[int, Any] = field(default_factory=dict)
    #: Where the declarations come from ("profile acg", "EDS x.eds", "standard objects").
    source: str = "standard objects"

    def class_name(self, class_id: int) -> str | None:
        spec = self.catalog.classes.get(class_id)
        return spec.name if spec is not None else None

    def attribute(self, class_id: int, instance: int | None, attribute: int | None) -> tuple[str | None, Any]:
        """(name, declaration) of an attribute: an EDS parameter by link path first, then the catalog."""
        if instance is None or attribute is None:
            return None, None
        param = self.eds_params.get((class_id, instance, attribute))
        if param is not None:
            return param.name, param
        spec = self.catalog.attribute(class_id, instance, attribute)
        return (spec.name, spec) if spec is not None else (None, None)

    def schema(self, instance: int | None) -> Any:
        if instance is None:
            return None
        return self.eds_schemas.get(instance) or self.catalog.assemblies.get(instance)


def decode_value(declaration: Any, data: bytes) -> dict[str, Any]:
    """The value of an attribute's bytes by its declaration: raw, scaled and as text."""
    if declaration is None or not data:
        return {"raw": data.hex()} if data else {}
    try:
        value = declaration.type.decode(data)
    except Exception as exc:  # any codec failure is a finding about the frame, not a crash
        return {"raw": data.hex(), "decode_error": str(exc)}
    out: dict[str, Any] = {"value": value if isinstance(value, (int, float, str, bool)) else repr(value)}
    describe = getattr(declaration, "describe", None)
    if describe is not None:
        out["text"] = describe(value)
    else:
        enum = getattr(declaration, "enum", None)
        unit, scale = getattr(declaration, "unit", ""), getattr(declaration, "scale", 1.0)
        if enum and value in enum:
            out["text"] = f"{value} ({enum[value]})"
        elif isinstance(value, int) and not isinstance(value, bool):
            out["text"] = scaled_text(value, unit, scale)  # the raw word in its declared unit, scaled
        else:
            out["text"] = f"{value} {unit}".strip()
    scale = getattr(declaration, "scale", 1.0)
    if scale != 1.0 and isinstance(value, int):
        out["scaled"] = value * scale
    return out


def describe_path(path: bytes, decl: Declarations) -> dict[str, Any]:
    """class/instance/attribute with their names; a path that is not one is shown as segments."""
    try:
        app = parse_application_path(path)
    except CipError as exc:
        return {"path": path.hex(), "path_error": str(exc)}
    out: dict[str, Any] = {"class": app.class_id, "instance": app.instance, "attribute": app.attribute}
    name = decl.class_name(app.class_id)
    if name:
        out["class_name"] = name
    attr_name, _ = decl.attribute(app.class_id, app.instance, app.attribute)
    if attr_name:
        out["attribute_name"] = attr_name
    return out


def path_text(info: dict[str, Any]) -> str:
    if "class" not in info:
        return f"path {info.get('path', '')}"
    text = f"{info.get('class_name') or 'class'} 0x{info['class']:02X}"
    if info.get("instance") is not None:
        text += f"/{info['instance']}"
    if info.get("attribute") is not None:
        text += f"/{info['attribute']}"
        if info.get("attribute_name"):
            text += f" {info['attribute_name']}"
    return text


def describe_route(route: bytes) -> dict[str, Any]:
    try:
        segments = decode_path(route)
    except CipError as exc:
        return {"route": route.hex(), "route_error": str(exc)}
    hops = []
    for segment in segments:
        if isinstance(segment, PortSegment):
            link = segment.link[0] if len(segment.link) == 1 else segment.link.hex()
            hop = {"port": segment.port, "link": link}
            if segment.port == COMPONET_PORT:
                hop["network"] = "CompoNet"  # the gateway's second port (componet/gateway.py)
            hops.append(hop)
    return {"route": hops}


def decode_request(raw: bytes, decl: Declarations) -> dict[str, Any]:
    """A message-router request with its names; an Unconnected_Send shows the request it carries."""
    request = MessageRouterRequest.decode(raw)
    out: dict[str, Any] = {"service": request.service, "service_name": service_name(request.service)}
    out.update(describe_path(request.path, decl))
    if request.service == Service.UNCONNECTED_SEND and out.get("class") == CONNECTION_MANAGER:
        send = UnconnectedSendRequest.decode(request.data)
        out.update(describe_route(send.route_path))
        out["embedded"] = decode_request(send.message, decl)
        return out
    if request.service in (Service.SET_ATTRIBUTE_SINGLE,) and request.data:
        _, declaration = decl.attribute(out.get("class", -1), out.get("instance"), out.get("attribute"))
        out["data"] = decode_value(declaration, request.data)
    elif request.data and request.service not in (Service.FORWARD_OPEN, Service.LARGE_FORWARD_OPEN,
                                                    Service.FORWARD_CLOSE):
        out["data"] = {"raw": request.data.hex()}
    return out


def decode_reply(raw: bytes, request: dict[str, Any] | None, decl: Declarations) -> dict[str, Any]:
    reply = MessageRouterResponse.decode(raw)
    out: dict[str, Any] = {"service": reply.service, "status": reply.general_status,
                           "extended_status": list(reply.extended_status),
                           "status_name": describe_status(reply.general_status, reply.extended_status)}
    target = request.get("embedded", request) if request else None
    if reply.ok and reply.data and target is not None and target.get("service") == Service.GET_ATTRIBUTE_SINGLE:
        _, declaration = decl.attribute(target.get("class", -1), target.get("instance"), target.get("attribute"))
        out["data"] = decode_value(declaration, reply.data)
    elif reply.data and not (target and target.get("service") in (Service.FORWARD_OPEN, Service.LARGE_FORWARD_OPEN,
                                                                    Service.FORWARD_CLOSE)):
        out["data"] = {"raw": reply.data.hex()}
    return out


def connection_points(path: bytes) -> tuple[int | None, int | None, int | None]:
    """(configuration instance, O->T point, T->O point) of a Forward_Open connection path:
    ``20 04 24 cfg 2C o->t 2C t->o`` (consumed then produced; wire.md), or instances only."""
    try:
        segments = decode_path(path)
    except CipError:
        return None, None, None
    instances = [s.value for s in segments if isinstance(s, LogicalSegment) and s.kind == LogicalType.INSTANCE_ID]
    points = [s.value for s in segments
              if isinstance(s, LogicalSegment) and s.kind == LogicalType.CONNECTION_POINT]
    config = instances[0] if instances else None
    if len(points) < 2:
        points = instances[1:] + points
    o_t = points[0] if points else None
    t_o = points[1] if len(points) > 1 else None
    return config, o_t, t_o


def field_changes(old: dict[str, Any], new: dict[str, Any]) -> dict[str, list[Any]]:
    return {name: [old.get(name), value] for name, value in new.items() if old.get(name) != value}


def merge_declarations(parts: Iterable[Declarations]) -> Declarations:
    out = Declarations()
    for part in parts:
        out.catalog.classes.update(part.catalog.classes)
        out.catalog.assemblies.update(part.catalog.assemblies)
        out.eds_params.update(part.eds_params)
        out.eds_schemas.update(part.eds_schemas)
    return out
