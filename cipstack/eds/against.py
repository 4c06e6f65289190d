"""``eds check --against HOST``: an EDS file compared with the live device it describes.

What is compared, each through the services the device has:

* ``[Device]`` with the Identity object: Get_Attributes_All of instance 1; where the device refuses
  it (0x08, as the MX2 and RX do), Get_Attribute_Single of attributes 1-4 and 7; where that is
  refused too, the ListIdentity reply (which carries the same attributes).
* every ``ParamN`` with a link path (a class attribute, instance 0, too): Get_Attribute_Single of that
  attribute; the size of the reply
  against the parameter's data type and size (fields 5 and 6), its value against the minimum and
  maximum (fields 10 and 11).
* every ``AssemN`` the file places at an instance: its size against Assembly attribute 4 (where
  attribute 4 is not served, the length of attribute 3, the data); one it places at no instance
  (no path, and no connection names it) is noted, since nothing says which instance to read.
* every class 1 ``ConnectionN``: opened as the file describes it (``Scanner.io_connection_from_eds``)
  and closed at once; a listen-only connection while a connection of the file that produces the
  same input by multicast is open. A refusal says who refused: the device (its status), or the
  file, whose connection cannot be opened as it declares it (never sent). A refusal by the device is
  judged once every connection was tried, by ``refusals`` (as ``conform --eds`` judges it): a path
  the device refuses while it has the assemblies and opened another connection of the file of the
  same kind is its configuration (a note), with none of that kind opened a warning.

A difference is an error finding of the checker's kind (a rule, a line of the file, a message);
what the device refuses without saying the file is wrong (a service it does not serve, a state
conflict) is an ``info`` finding, so the check goes on with what the device does serve.
"""

from __future__ import annotations

import asyncio
import re
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from ..cip.status import CipError, GeneralStatus, describe_status
from ..cip.types import SHORT_STRING, UINT, USINT, CipType, IntegerType, RealType
from . import refusals
from .checker import ERROR, INFO, WARNING, Finding
from .interpret import ConnectionInfo, ParamInfo, read_view
from .model import EdsDocument

if TYPE_CHECKING:
    from contextlib import AbstractAsyncContextManager

    from ..cip.values import Value
    from ..eip.wire.identity_items import IdentityRecord


class _Reply(Protocol):
    @property
    def data(self) -> bytes: ...


class LiveDevice(Protocol):
    """What the comparison asks of the device: a connected ``cipstack.Scanner`` is one. Named here, the
    EDS checker lies below the scanner and never imports it."""

    async def get_attributes_all(self, class_id: int, instance: int) -> tuple[bytes, dict[str, Any] | None]: ...

    async def get_attribute_single(self, class_id: int, instance: int, attribute: int) -> _Reply: ...

    async def read(self, class_id: int, instance: int, attribute: int, cip_type: CipType | None = None) -> Value: ...

    async def list_identity(self) -> list[IdentityRecord]: ...

    def io_connection_from_eds(self, doc: EdsDocument, connection: int,
                               **options: Any) -> AbstractAsyncContextManager[Any]: ...

T = TypeVar("T")

#: What the file's reading says of a ConnectionN it skipped (see ``interpret._connection``).
_DECLARED_NOT_OPENABLE = re.compile(r"Connection[0-9]+\b.*: skipped$")

#: Statuses that say the attribute or instance is not there: the file names something the device lacks.
_ABSENT = frozenset({GeneralStatus.PATH_DESTINATION_UNKNOWN, GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
                     GeneralStatus.OBJECT_DOES_NOT_EXIST, GeneralStatus.PATH_SEGMENT_ERROR})
#: Identity attributes ``[Device]`` mirrors (eds.md: "must equal Identity attributes 1-4 and 7").
_IDENTITY_ATTRIBUTES = ((1, "vendor_id", UINT), (2, "device_type", UINT), (3, "product_code", UINT),
                        (7, "product_name", SHORT_STRING))


@dataclass
class LiveReport:
    """What comparing one file with the device found, and what was compared."""

    identity: dict[str, Any] | None = None
    #: How the identity was read: "Get_Attributes_All", "Get_Attribute_Single" or "ListIdentity".
    identity_by: str = ""
    findings: list[Finding] = field(default_factory=list)
    parameters: int = 0
    assemblies: int = 0
    connections: int = 0
    opened: int = 0
    #: The Assembly instances the device has (their size was read).
    sized: set[int] = field(default_factory=set)

    def summary(self, host: str) -> str:
        return (f"against {host}: identity by {self.identity_by or 'nothing (refused)'}, "
                f"{self.parameters} parameters read, {self.assemblies} assemblies sized, "
                f"{self.opened} of {self.connections} class 1 connections opened and closed")


def _status(exc: CipError) -> str:
    return describe_status(exc.general, exc.extended)


def _find(report: LiveReport, rule: str, line: int, message: str, severity: str = ERROR) -> None:
    report.findings.append(Finding(rule, severity, line, message))


async def _identity(scanner: LiveDevice, report: LiveReport) -> None:
    try:
        _, values = await scanner.get_attributes_all(0x01, 1)
    except CipError as exc:
        _find(report, "live-refused", 0, f"Identity Get_Attributes_All refused ({_status(exc)}): read "
                                         "attribute by attribute", INFO)
    else:
        if values is not None:
            report.identity_by = "Get_Attributes_All"
            report.identity = {"vendor_id": values["Vendor ID"], "device_type": values["Device Type"],
                               "product_code": values["Product Code"],
                               "revision": (values["Revision"]["major"], values["Revision"]["minor"]),
                               "product_name": values["Product Name"]}
            return
    identity: dict[str, Any] = {}
    try:
        for attribute, key, cip_type in _IDENTITY_ATTRIBUTES:
            identity[key] = await scanner.read(0x01, 1, attribute, cip_type)
        raw = (await scanner.get_attribute_single(0x01, 1, 4)).data
        identity["revision"] = (USINT.decode(raw[:1]), USINT.decode(raw[1:2]))
    except (CipError, ValueError) as exc:
        why = _status(exc) if isinstance(exc, CipError) else str(exc)
        _find(report, "live-refused", 0, f"Identity Get_Attribute_Single refused ({why}): ListIdentity read", INFO)
    else:
        report.identity_by, report.identity = "Get_Attribute_Single", identity
        return
    records = await scanner.list_identity()
    if records:
        record = records[0]
        report.identity_by = "ListIdentity"
        report.identity = {"vendor_id": record.vendor_id, "device_type": record.device_type,
                           "product_code": record.product_code, "revision": record.revision,
                           "product_name": record.product_name}


async def _parameter(scanner: LiveDevice, param: ParamInfo, report: LiveReport) -> None:
    assert param.link is not None
    class_id, instance, attribute = param.link
    where = f"{param.keyword} ({param.name}) at 0x{class_id:02X}/{instance}/{attribute}"
    try:
        raw = (await scanner.get_attribute_single(class_id, instance, attribute)).data
    except CipError as exc:
        if exc.general in _ABSENT:
            _find(report, "live-parameter", param.line, f"{where}: the device has no such attribute ({_status(exc)})")
        else:
            _find(report, "live-refused", param.line, f"{where}: read refused ({_status(exc)})", INFO)
        return
    report.parameters += 1
    cip_type = param.type
    if not isinstance(cip_type, (IntegerType, RealType)):
        try:
            cip_type.decode(raw)
        except (CipError, ValueError, IndexError) as exc:
            _find(report, "live-parameter", param.line, f"{where}: the device's {len(raw)} bytes are no "
                                                        f"{cip_type.name} ({exc})")
        return
    if isinstance(cip_type, (IntegerType, RealType)):
        if len(raw) != param.size or cip_type.size != param.size:
            _find(report, "live-parameter", param.line,
                  f"{where}: the device answers {len(raw)} bytes; the file says a {cip_type.name} of {param.size}")
            return
        value = cip_type.decode(raw)
        low, high = param.minimum, param.maximum
        numbers = [bound for bound in (low, high) if isinstance(bound, (int, float)) and not isinstance(bound, bool)]
        if len(numbers) == 2 and not low <= value <= high:
            _find(report, "live-parameter", param.line,
                  f"{where}: the device holds {value}, outside the file's {low}..{high}", WARNING)


async def _assembly(scanner: LiveDevice, keyword: str, instance: int, size: int, line: int, report: LiveReport) -> None:
    where = f"{keyword} (Assembly instance {instance})"
    try:
        served = int(await scanner.read(0x04, instance, 4, UINT))
    except CipError as exc:
        if exc.general in (GeneralStatus.PATH_DESTINATION_UNKNOWN, GeneralStatus.OBJECT_DOES_NOT_EXIST):
            _find(report, "live-assembly", line, f"{where}: the device has no such instance ({_status(exc)})")
            return
        try:   # attribute 4 is optional: the data itself gives the size
            served = len((await scanner.get_attribute_single(0x04, instance, 3)).data)
        except CipError as again:
            _find(report, "live-refused", line, f"{where}: attributes 4 and 3 refused ({_status(exc)}; "
                                                f"{_status(again)})", INFO)
            return
    report.assemblies += 1
    report.sized.add(instance)
    if served != size:
        _find(report, "live-assembly", line, f"{where} is {size} bytes in the file, {served} on the device")


@dataclass
class _Attempt:
    """How opening one connection of the file went: opened, refused by the device (its status), or
    a listen-only connection whose owners were all refused (each with its status)."""

    connection: ConnectionInfo
    opened: bool = False
    refusal: CipError | None = None
    owners_refused: list[tuple[ConnectionInfo, CipError]] = field(default_factory=list)


async def _connection(scanner: LiveDevice, doc: EdsDocument, connection: ConnectionInfo, owners: list[ConnectionInfo],
                      options: dict[str, Any], report: LiveReport) -> _Attempt | None:
    """Open and close ``connection``; None when the attempt is a finding already (no answer, or the
    file's declaration cannot be sent)."""
    where = f"Connection{connection.number} ({connection.name})"
    attempt = _Attempt(connection)

    async def opened(number: int, multicast: bool | None, then: Callable[[], Awaitable[None]] | None) -> None:
        extra = dict(options)
        if multicast is not None:
            extra["multicast"] = multicast
        async with scanner.io_connection_from_eds(doc, number, **extra) as io:
            for note in io.notes:
                _find(report, "live-connection", connection.line, f"{where}: {note}")
            if then is not None:
                await then()

    try:
        if connection.kind == "listen only":
            candidates = refusals.owners_of(connection, owners)
            listened: list[bool] = []

            async def listen() -> None:
                listened.append(True)
                await opened(connection.number, True, None)

            for owner in candidates:
                try:
                    await opened(owner.number, True, listen)
                except CipError as exc:
                    if listened:
                        raise   # the owner opened: the listener was refused
                    attempt.owners_refused.append((owner, exc))
                    continue
                break
            else:
                return attempt   # nothing to listen to: judged with the rest
        else:
            await opened(connection.number, None, None)
    except CipError as exc:
        attempt.refusal = exc
        return attempt
    except (OSError, asyncio.TimeoutError) as exc:
        _find(report, "live-connection", connection.line, f"{where}: no answer from the device ({type(exc).__name__}: "
                                                          f"{exc})")
        return None
    except (ValueError, KeyError, TypeError) as exc:
        # Raised before anything is sent: the file's declaration is what cannot be opened.
        _find(report, "live-connection", connection.line, f"{where}: cannot be opened as the file declares it "
                                                          f"({exc}): not sent")
        return None
    report.opened += 1
    attempt.opened = True
    return attempt


def _judge(attempts: list[_Attempt], report: LiveReport) -> None:
    """A finding for each connection not opened, judged once the whole file was tried (whether
    another of its connections opened tells a configuration from a refusal: ``refusals``)."""
    opened = [a.connection for a in attempts if a.opened]
    for attempt in attempts:
        connection = attempt.connection
        where = f"Connection{connection.number} ({connection.name})"
        if attempt.refusal is not None:
            exc = attempt.refusal
            verdict = refusals.refused(connection, exc.general, exc.extended,
                                       assemblies_exist=refusals.data_points(connection) <= report.sized,
                                       opened=opened)
        elif not attempt.opened:
            verdict = refusals.unheard(connection, [(owner, exc.general, exc.extended)
                                                    for owner, exc in attempt.owners_refused])
        else:
            continue
        _find(report, "live-connection", connection.line, f"{where}: {verdict.message}", verdict.severity)


async def _guarded(step: Awaitable[T], report: LiveReport, what: str) -> T | None:
    """A step that a broken reply must not turn into a traceback: it becomes a finding."""
    try:
        return await step
    except CipError as exc:
        _find(report, "live-refused", 0, f"{what}: {_status(exc)}", INFO)
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        _find(report, "live-refused", 0, f"{what}: the reply does not decode ({exc})", INFO)
    return None


async def compare_with_device(doc: EdsDocument, scanner: LiveDevice, *, target_io_port: int | None = None,
                              connections: bool = True) -> LiveReport:
    """Everything the module docstring lists, for one document."""
    report = LiveReport()
    await _guarded(_identity(scanner, report), report, "Identity")
    view = read_view(doc)
    for param in view.params.values():
        if param.link is not None:
            await _guarded(_parameter(scanner, param, report), report, param.keyword)
    members = {m.reference for a in view.assemblies.values() for m in a.members if m.reference}
    for info in view.assemblies.values():
        if info.instance is not None and info.size:
            await _guarded(_assembly(scanner, info.keyword, info.instance, info.size, info.line, report), report,
                           info.keyword)
        elif info.instance is None and info.keyword not in members:
            _find(report, "live-assembly", info.line, f"{info.keyword}: not sized: it has no path and no connection "
                                                      "names it, so nothing says which instance of the device it is",
                  INFO)
    if connections:
        for issue in view.issues:
            # A class 1 connection the file declares but does not describe so that it can be opened.
            if _DECLARED_NOT_OPENABLE.match(issue.message) and "is not class 1" not in issue.message:
                _find(report, "live-connection", issue.line, f"{issue.message.removesuffix(': skipped')}: cannot be "
                                                             "opened as the file declares it: not sent", WARNING)
    if connections:
        options: dict[str, Any] = {"target_io_port": target_io_port, "timeout_multiplier": 4}
        owners = [c for c in view.connections if c.kind != "listen only"]
        report.connections = len(view.connections)
        attempts = [await _connection(scanner, doc, connection, owners, options, report)
                    for connection in view.connections]
        _judge([a for a in attempts if a is not None], report)
    report.findings.sort(key=lambda finding: finding.line)
    return report


__all__ = ["LiveReport", "compare_with_device"]
