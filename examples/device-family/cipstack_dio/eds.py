"""The EDS description of DIO-4, for ``cipstack eds generate --profile dio`` and the file the block serves
through its File object. The family declares it as ``Profile.eds = "cipstack_dio.eds:description"``: a
reference, which cipstack imports when a file is made, as the EDS tool sits above the devices.

Every value comes from the block as ``build`` makes it (its Identity, its assemblies, its class 1 offer
and the classes its router serves) or from the point classes' declarations: nothing is declared twice."""

from __future__ import annotations

import dataclasses

from cipstack.assemblies.schema import AssemblyField, AssemblySchema
from cipstack.devices.base import DeviceLimits
from cipstack.devices.profiles import DEFAULT_MAC, ProfileOptions
from cipstack.eds.description import (
    EdsCapacity,
    EdsDescription,
    EdsObjectClass,
    EdsParameter,
    EdsPort,
    IoOffer,
    attribute_parameters,
)
from cipstack.eip.wire.cm_spec import BACKPLANE_PORT
from cipstack.objects.tcpip import TCPIP_CLASS_ID, NetworkInterface

from . import DISCRETE_INPUT_POINT, DISCRETE_OUTPUT_POINT, INPUT_ASSEMBLY, OUTPUT_ASSEMBLY, POINTS, PRODUCT_NAME, build

#: Made up with the vendor id: no vendor's name.
VENDOR_NAME = "cipstack example"
#: ``ProdTypeStr`` of device type 7, the General Purpose Discrete I/O profile (CIP Vol 1, chapter 6).
PRODUCT_TYPE_NAME = "General Purpose Discrete I/O"


def _points_schema(instance: int, name: str, class_id: int, what: str) -> AssemblySchema:
    """One byte, bit N-1 the Value of point N (the class's instance N, attribute 3)."""
    return AssemblySchema(instance, name, 1, [
        AssemblyField(f"{what.lower()}_{point}", 0, bits=1, bit=point - 1, link=(class_id, point, 3))
        for point in range(1, POINTS + 1)])


def _point_parameters() -> tuple[EdsParameter, ...]:
    """The Value of every point, a parameter linked to its attribute (outputs settable), named as the
    assembly member that carries it, so that the member and the attribute are one parameter."""
    out: list[EdsParameter] = []
    for spec, what in ((DISCRETE_OUTPUT_POINT, "Output"), (DISCRETE_INPUT_POINT, "Input")):
        for point in range(1, POINTS + 1):
            (value,) = attribute_parameters(spec, point, ids=(3,))
            out.append(dataclasses.replace(value, name=f"{what} {point}"))
    return tuple(out)


def description() -> EdsDescription:
    """DIO-4 as ``build`` makes it (a family of one model: no argument)."""
    device = build(NetworkInterface(mac=DEFAULT_MAC), DeviceLimits(), ProfileOptions())
    offer = device.io_profile()
    io = IoOffer.from_io_profile(offer) if offer is not None else None
    return EdsDescription(
        identity=device.identity_info,
        vendor_name=VENDOR_NAME,
        product_type_name=PRODUCT_TYPE_NAME,
        catalog=PRODUCT_NAME,
        network="EtherNetIP",
        description="DIO-4 digital I/O block, four inputs wired to four outputs",
        parameters=_point_parameters(),
        outputs=(_points_schema(OUTPUT_ASSEMBLY, "outputs", DISCRETE_OUTPUT_POINT.class_id, "Output"),),
        inputs=(_points_schema(INPUT_ASSEMBLY, "inputs", DISCRETE_INPUT_POINT.class_id, "Input"),),
        io=io,
        # Port 1 is the backplane (the block itself); the Ethernet port is the next one.
        ports=(EdsPort("TCP", "EtherNet/IP Port", (TCPIP_CLASS_ID, 1), BACKPLANE_PORT + 1),),
        capacity=EdsCapacity(max_io_connections=io.max_connections if io is not None else 0,
                             max_msg_connections=device.limits.max_connections),
        object_classes=tuple(EdsObjectClass(obj.spec, len(obj.instances))
                             for _, obj in sorted(device.router.objects.items())),
    )
