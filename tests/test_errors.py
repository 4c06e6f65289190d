"""One error root: every exception class the package defines derives from ``CipstackError``
(``cipstack/errors.py``), and keeps the builtin base it had before, so a caller's ``except
ConnectionError`` or ``except KeyError`` still catches what it caught."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from types import ModuleType

import pytest

import cipstack
from cipstack.errors import BadRequest, CipstackError, NotFound, PeerUnreachable, ProtocolError, StateRefused

#: Modules not imported: ``python -m cipstack`` runs the command line when imported.
NOT_IMPORTED = frozenset({"cipstack.__main__"})


def _modules() -> tuple[list[ModuleType], set[str]]:
    """Every module of the package, and the names of those left out for want of an optional
    third-party package (an extra that is not installed)."""
    modules: list[ModuleType] = [cipstack]
    missing: set[str] = set()
    for info in pkgutil.walk_packages(cipstack.__path__, "cipstack."):
        if info.name in NOT_IMPORTED:
            continue
        try:
            modules.append(importlib.import_module(info.name))
        except ModuleNotFoundError as exc:
            if exc.name is None or exc.name.split(".")[0] == "cipstack":
                raise
            missing.add(info.name)
    return modules, missing


MODULES, MISSING = _modules()


def _exception_classes() -> dict[str, type[BaseException]]:
    """Qualified name -> class, for every exception class a cipstack module defines (nested ones too)."""
    found: dict[str, type[BaseException]] = {}

    def visit(owner: object, module: str) -> None:
        for value in vars(owner).values():
            if inspect.isclass(value) and value.__module__ == module and value is not owner:
                if issubclass(value, BaseException):
                    found[f"{module}.{value.__qualname__}"] = value
                visit(value, module)

    for module in MODULES:
        visit(module, module.__name__)
    return found


CLASSES = _exception_classes()


def test_the_walk_finds_the_exception_classes() -> None:
    # Without this, a walk that found nothing would pass every test below.
    assert len(MODULES) > 100
    for name in ("cipstack.cip.status.CipError", "cipstack.eip.originator.replies.MalformedReplyError",
                 "cipstack.scanner._Unsplittable", "cipstack.listening.ListenError", "cipstack.errors.NotFound"):
        assert name in CLASSES


def test_every_exception_class_derives_from_cipstack_error() -> None:
    outside = sorted(name for name, cls in CLASSES.items() if not issubclass(cls, CipstackError))
    assert outside == []


@pytest.mark.parametrize(("name", "kind", "builtin"), [
    ("cipstack.cip.status.CipError", ProtocolError, Exception),
    ("cipstack.scanner._Unsplittable", ProtocolError, Exception),
    ("cipstack.eip.originator.replies.MalformedReplyError", ProtocolError, ConnectionError),
    ("cipstack.eip.originator.replies.EncapsulationStatusError", ProtocolError, Exception),
    ("cipstack.eip.wire.encapsulation.EncapsulationError", ProtocolError, Exception),
    ("cipstack.eip.io_core.IoDatagramError", ProtocolError, ValueError),
    ("cipstack.eip.originator.class1.IoTimeoutError", PeerUnreachable, ConnectionError),
    ("cipstack.scanner.UnknownAttributeError", NotFound, TypeError),
    ("cipstack.scanner.ReplyDecodeError", ProtocolError, ValueError),
    ("cipstack.conformance.wire.TargetUnreachable", PeerUnreachable, ConnectionError),
    ("cipstack.componet.network.NoResponse", PeerUnreachable, Exception),
    ("cipstack.componet.explicit.FrameError", ProtocolError, ValueError),
    ("cipstack.devices.omron.models.UnknownModelError", NotFound, KeyError),
    ("cipstack.devices.acg.modbus.MbapLengthError", ProtocolError, ValueError),
    ("cipstack.devices.acg.modbus_core.ModbusException", ProtocolError, Exception),
    ("cipstack.devices.registers.RegisterError", StateRefused, Exception),
    ("cipstack.devices.omron.states.InverterModeError", StateRefused, Exception),
    ("cipstack.devices.state.StateFileError", StateRefused, Exception),
    ("cipstack.devices.omron.flexible.FlexibleMappingError", BadRequest, ValueError),
    ("cipstack.eds.reader.EdsSyntaxError", BadRequest, ValueError),
    ("cipstack.eds.emulated_device.EdsDeviceError", BadRequest, ValueError),
    ("cipstack.eds.commands_generate.GenerateError", BadRequest, Exception),
    ("cipstack.capture.reader.CaptureFormatError", BadRequest, ValueError),
    ("cipstack.capture.command.UsageProblem", BadRequest, Exception),
    ("cipstack.cli.common.UsageError", CipstackError, Exception),
    ("cipstack.fleet.spec.SpecError", BadRequest, ValueError),
    ("cipstack.fleet.workers.FleetFailure", CipstackError, Exception),
    ("cipstack.capture.report.PlotUnavailable", CipstackError, RuntimeError),
    ("cipstack.listening.ListenError", CipstackError, OSError),
    ("cipstack.params.DriveRunningError", StateRefused, RuntimeError),
    ("cipstack.faults.errors.FaultError", BadRequest, ValueError),
    ("cipstack.faults.errors.NoSuchConnection", NotFound, LookupError),
    ("cipstack.faults.errors.FaultStateError", StateRefused, RuntimeError),
    ("cipstack.faults.controller.NoActiveFault", NotFound, LookupError),
    ("cipstack.devices.base.TripRefused", StateRefused, ValueError),
    ("cipstack.devices.keypad.UnknownCode", NotFound, ValueError),
    ("cipstack.devices.keypad.BadValue", BadRequest, ValueError),
    ("cipstack.devices.keypad.WriteRefused", StateRefused, ValueError),
    ("cipstack.devices.keypad.NoKeypad", NotFound, ValueError),
    ("cipstack.control.local_socket.ControlRefused", BadRequest, ValueError),
    ("cipstack.control.local_socket.ControlDenied", StateRefused, Exception),
    ("cipstack.control.local_socket.ControlUnreachable", PeerUnreachable, ConnectionError),
    ("cipstack.control.local_socket.ControlTaken", CipstackError, OSError),
    ("cipstack.control.scenario.ScenarioError", BadRequest, ValueError),
    ("cipstack.control.http.HttpApiError", BadRequest, ValueError),
    ("cipstack.modbus.rtu_line.RtuPortError", CipstackError, Exception),
    ("cipstack.errors.NoReply", PeerUnreachable, TimeoutError),
    ("cipstack.eip.originator.core.NoReplyError", PeerUnreachable, TimeoutError),
    ("cipstack.errors.UnknownKey", NotFound, KeyError),
    ("cipstack.errors.UnknownField", NotFound, AttributeError),
    ("cipstack.errors.ReadOnlyField", BadRequest, AttributeError),
    ("cipstack.errors.WrongType", BadRequest, TypeError),
    ("cipstack.errors.WrongState", StateRefused, RuntimeError),
    ("cipstack.errors.TimedOut", CipstackError, TimeoutError),
    ("cipstack.devices.base.NoDrive", BadRequest, NotImplementedError),
])
def test_each_class_has_its_kind_and_keeps_its_builtin_base(name: str, kind: type, builtin: type) -> None:
    module = name.rsplit(".", 1)[0]
    if module in MISSING:
        pytest.skip(f"{module} needs a package of an extra that is not installed (cipstack.control.http: aiohttp, "
                    "the http extra)")
    cls = CLASSES[name]
    assert issubclass(cls, kind)
    assert issubclass(cls, builtin)


def test_the_builtin_bases_callers_catch_are_kept() -> None:
    from cipstack.devices.omron.models import UnknownModelError
    from cipstack.eip.originator.io_originator import IoTimeoutError
    from cipstack.eip.originator.replies import MalformedReplyError
    from cipstack.listening import ListenError
    from cipstack.params import DriveRunningError
    from cipstack.scanner import ReplyDecodeError, UnknownAttributeError

    assert issubclass(MalformedReplyError, ConnectionError)
    assert issubclass(IoTimeoutError, ConnectionError)
    assert issubclass(UnknownAttributeError, TypeError)
    assert issubclass(ReplyDecodeError, ValueError)
    assert issubclass(UnknownModelError, KeyError)
    assert issubclass(ListenError, OSError)
    assert issubclass(DriveRunningError, RuntimeError)


def test_the_root_and_its_kinds_import_from_the_package() -> None:
    from cipstack import BadRequest as Bad
    from cipstack import CipstackError as Root
    from cipstack import NotFound as Missing
    from cipstack import PeerUnreachable as Unreachable
    from cipstack import ProtocolError as Protocol
    from cipstack import StateRefused as Refused

    assert Root is CipstackError
    for kind in (Bad, Missing, Unreachable, Protocol, Refused):
        assert kind.__module__ == "cipstack.errors"
        assert issubclass(kind, Root)
        assert kind.__name__ in cipstack.__all__


def test_a_cip_error_carries_its_status_as_a_protocol_error() -> None:
    from cipstack.cip.status import CipError, GeneralStatus

    with pytest.raises(ProtocolError) as caught:
        raise CipError(GeneralStatus.PATH_DESTINATION_UNKNOWN, (0x0001,), message="no such object")
    assert (caught.value.general, caught.value.extended) == (0x05, (0x0001,))
    assert str(caught.value) == "no such object: 0x05 (path destination unknown), extended 0x0001"


def test_an_unknown_model_says_its_message_plainly() -> None:
    """KeyError quotes its argument; NotFound, earlier in the MRO, does not."""
    from cipstack.devices.omron.models import model

    with pytest.raises(KeyError) as caught:
        model("MX2-NOPE")
    assert str(caught.value) == ("unknown inverter model 'MX2-NOPE': `cipstack models` lists the 61 models "
                                 "(MX2-AB001-E to RX-B413K-E)")
    assert isinstance(caught.value, NotFound)


def test_a_listen_error_is_still_an_os_error() -> None:
    from cipstack.listening import ListenError

    error = ListenError("TCP 127.0.0.1:44818 (--port)", "address in use")
    assert str(error) == "cannot listen on TCP 127.0.0.1:44818 (--port): address in use"
    with pytest.raises(OSError):
        raise error



def test_a_usage_error_is_no_value_error() -> None:
    """argparse replaces the message of a ValueError raised by a ``type=`` function with its own
    ("invalid <lambda> value"); a UsageError reaches ``main`` with the message it was given."""
    from cipstack.cli.common import UsageError

    assert not issubclass(UsageError, ValueError)


def test_a_missing_key_says_its_message_plainly_and_is_still_a_key_error() -> None:
    from cipstack.devices.acg.assemblies import assembly_size

    with pytest.raises(KeyError) as caught:
        assembly_size(999)
    assert isinstance(caught.value, NotFound)
    assert str(caught.value) == "the ACG-ET2 has no assembly instance 999"


def test_an_unknown_field_keeps_hasattr_and_getattr_working() -> None:
    from cipstack.assemblies.schema import AssemblyField, AssemblySchema
    from cipstack.eip.originator.io_originator import ProcessImage
    from cipstack.errors import ReadOnlyField, UnknownField

    schema = AssemblySchema(71, "status", 2, [AssemblyField("status", 0)])
    image = ProcessImage(bytearray(schema.size), schema, writable=False)
    assert not hasattr(image, "no_such_field")
    assert getattr(image, "no_such_field", "default") == "default"
    with pytest.raises(UnknownField, match="no_such_field"):
        image.no_such_field  # noqa: B018
    with pytest.raises(ReadOnlyField, match="read-only"):
        image.raw = bytes(schema.size)
