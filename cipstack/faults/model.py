"""The fault model: every fault the emulator can inject, its options, and how a request names one.

One table (``FAULTS``) declares each fault: its name, what it acts on, the options it takes and
whether it lasts (until cleared or for ``--for DURATION``) or happens once. The command line, the
control socket and the Python API all parse and check a request against this table, so a fault
and its options are written down once.

A request is a name and options, as the command line gives them (``drop --share 0.1 --for 2s``)
or as a mapping (``{"share": 0.1, "for": 2.0}``); ``parse_arguments`` and ``FaultRequest.build``
return the same ``FaultRequest``. Anything unknown raises ``FaultError`` whose message is one line
listing what is valid.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from . import class1, device, explicit, security
from .effect import EffectFactory
from .errors import FaultError, FaultStateError, NoSuchConnection  # noqa: F401 (their import path of old)
from .options import FaultOptions

#: The longest duration any option takes (``--for``, ``--by``, a scenario's ``at``): a day. A test rig's
#: typo (``--for 1e9``) is refused rather than a fault that outlives the rig.
MAX_DURATION_S = 86400.0


def shown(value: object, limit: int = 40) -> str:
    """``value`` as a message quotes it, cut short: a 400-digit number is not worth echoing whole (and an
    int of more than 4,300 digits cannot even be turned into text)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"a number of about {int(value.bit_length() * 0.30103)} digits"
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def parse_duration(value: object) -> float:
    """``2``, ``2.5``, ``500ms``, ``2s``, ``1.5`` (seconds), or a number; at most ``MAX_DURATION_S``."""
    if isinstance(value, bool):
        raise FaultError(f"{shown(value)} is not a duration (e.g. 2s, 500ms)")
    if isinstance(value, (int, float)):
        try:
            seconds = float(value)
        except OverflowError:
            seconds = math.inf
    else:
        text = str(value).strip().lower()
        scale = 1.0
        if text.endswith("ms"):
            text, scale = text[:-2], 0.001
        elif text.endswith("us"):
            text, scale = text[:-2], 1e-6
        elif text.endswith("s"):
            text = text[:-1]
        try:
            seconds = float(text) * scale
        except ValueError:
            raise FaultError(f"{shown(value)} is not a duration (e.g. 2s, 500ms)") from None
    if not math.isfinite(seconds) or seconds < 0:
        raise FaultError(f"duration {shown(value)} is not a finite time of 0 or more")
    if seconds > MAX_DURATION_S:
        raise FaultError(f"duration {shown(value)} is longer than {MAX_DURATION_S:g}s (a day), the longest taken")
    return seconds


def parse_integer(value: object, low: int = 0, high: int = 0xFFFFFFFF) -> int:
    """A whole number, decimal or 0x hex, within ``low..high``."""
    if isinstance(value, bool):
        raise FaultError(f"{shown(value)} is not a number")
    if isinstance(value, int):
        number = value
    else:
        text = str(value).strip()
        try:
            number = int(text, 0) if len(text) <= 40 else high + 1
        except ValueError:
            raise FaultError(f"{shown(value)} is not a number (decimal or 0x hex)") from None
    if not low <= number <= high:
        raise FaultError(f"{shown(value)} is out of range {low}..{high}")
    return number


def parse_share(value: object) -> float:
    """A share of packets: more than 0, at most 1 (``0.1``, or ``10%``)."""
    text = str(value).strip()
    try:
        share = float(text[:-1]) / 100 if text.endswith("%") else float(text)
    except ValueError:
        raise FaultError(f"{shown(value)} is not a share (e.g. 0.1 or 10%)") from None
    if not 0 < share <= 1:
        raise FaultError(f"share {shown(value)} is not in (0, 1]")
    return share


def parse_status(value: object) -> tuple[int, tuple[int, ...]]:
    """A CIP status: ``GENERAL`` or ``GENERAL/EXTENDED`` (``0x08``, ``0x01/0x0100``)."""
    text = str(value).strip()
    general_text, _, extended_text = text.partition("/")
    general = parse_integer(general_text, 1, 0xFF)
    extended = (parse_integer(extended_text, 0, 0xFFFF),) if extended_text else ()
    return general, extended


def parse_host(value: object) -> str:
    text = str(value).strip()
    parts = text.split(".")
    if len(parts) != 4 or not all(p.isdigit() and int(p) <= 255 for p in parts):
        raise FaultError(f"originator {value!r} is not an IPv4 address")
    return text


@dataclass(frozen=True)
class Option:
    name: str
    parse: Callable[[object], Any]
    help: str
    metavar: str = "VALUE"
    #: Its attribute in the typed record (``FaultOptions``) where that is not its name.
    attribute: str = ""

    @property
    def field(self) -> str:
        return self.attribute or self.name


CONNECTION = Option("connection", lambda v: parse_integer(v), "one class 1 connection (its O->T or T->O id)", "ID")
ORIGINATOR = Option("originator", parse_host, "the class 1 connections of one originator address", "HOST")
FOR = Option("for", parse_duration, "clear the fault after this long", "DURATION", "duration")
SHARE = Option("share", parse_share, "a random share of the packets (0.1 or 10%)", "SHARE")
EVERY = Option("every", lambda v: parse_integer(v, 1, 1_000_000), "every Nth packet", "N")
BY = Option("by", parse_duration, "how long (default 10ms)", "DURATION")
JITTER = Option("jitter", parse_duration, "plus or minus up to this much, at random", "DURATION")
SIZE = Option("size", lambda v: parse_integer(v, 0, 65000), "data bytes sent (default: one fewer)", "N")
COUNT = Option("count", lambda v: parse_integer(v, 1, 1_000_000), "how many times (then it clears itself)", "N")
STATUS = Option("status", parse_status, "general status, or general/extended (0x08, 0x01/0x0100)", "STATUS")
SERVICE = Option("service", lambda v: parse_integer(v, 0, 0x7F), "only this service code", "CODE")
CLASS = Option("class", lambda v: parse_integer(v, 0, 0xFFFF), "only requests to this class", "ID", "class_id")
INSTANCE = Option("instance", lambda v: parse_integer(v, 0, 0xFFFFFFFF), "only this instance", "ID")
ATTRIBUTE = Option("attribute", lambda v: parse_integer(v, 0, 0xFFFF), "only this attribute", "ID")
#: The longest a power-cycle's power stays off: a test rig's typo (``--off 3600000``) must not leave a
#: device off for weeks; clearing the fault ends the off period early anyway.
MAX_OFF_S = 3600.0


def parse_off(value: object) -> float:
    seconds = parse_duration(value)
    if seconds > MAX_OFF_S:
        raise FaultError(f"{value!r} is longer than the {MAX_OFF_S:g}s the power may stay off")
    return seconds


OFF = Option("off", parse_off, "how long the power stays off (default 0, at most 3600s; clearing the fault "
             "ends it early)", "DURATION")
#: The longest name a suite is given by (IANA's are at most 50 characters).
MAX_SUITE_NAME = 64


def parse_suite(value: object) -> str:
    """A TLS suite as a user names it: IANA's name, OpenSSL's, or its 16-bit id (``0xC02B``). Whether the
    device accepts it is the device's to say when the fault is applied."""
    text = str(value).strip()
    if not text or len(text) > MAX_SUITE_NAME or not all(c.isalnum() or c in "_-" for c in text):
        raise FaultError(f"{shown(value)} is no cipher suite name (TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256, "
                         "ECDHE-ECDSA-AES128-GCM-SHA256 or 0xC02B)")
    return text


def parse_direction(value: object) -> str:
    text = str(value).strip().lower()
    if text not in ("in", "out", "both"):
        raise FaultError(f"direction {shown(value)} is in, out or both")
    return text


SUITE = Option("suite", parse_suite, "a TLS 1.2 suite by IANA name, OpenSSL name or id "
               "(TLS_ECDHE_ECDSA_WITH_AES_128_GCM_SHA256, ECDHE-ECDSA-AES128-GCM-SHA256, 0xC02B)", "SUITE")
DIRECTION = Option("direction", parse_direction, "records the device receives (in), sends (out) or both "
                   "(default)", "in|out|both")
DTLS_PEER = Option("originator", parse_host, "the DTLS sessions of one originator address", "HOST")
EXTENDED = Option("status", lambda v: parse_integer(v, 0, 0xFFFF),
                  "the Connection Manager's extended status (0x0100, 0x0106, 0x0113, 0x0315, ...)", "STATUS",
                  "extended_status")

#: Where a fault acts: on class 1 datagrams, on explicit requests and the encapsulation, on the device,
#: on CIP Security's listeners (TLS and DTLS: their handshakes, DTLS records, the lab CA's CRL).
CLASS1, EXPLICIT, DEVICE, SECURITY = "class 1", "explicit", "device", "security"


@dataclass(frozen=True)
class FaultKind:
    name: str
    where: str
    summary: str
    #: What the fault does, made when it is applied (a filter in the seam of its layer, or an action).
    effect: EffectFactory
    options: tuple[Option, ...] = ()
    #: A positional argument (its option): ``refuse-forward-open 0x0113``.
    positional: Option | None = None
    #: Happens once (an action), rather than lasting until cleared.
    once: bool = False
    #: Options the fault needs (one of each group).
    requires: tuple[tuple[str, ...], ...] = ()
    #: The option that is its duration instead of ``--for`` (a power-cycle lasts its ``--off``).
    lasts: str | None = None
    #: Applying it ends the active faults of this name, and is refused when there is none (plug ends unplug).
    ends: str | None = None
    #: Why it is refused when there is nothing to end.
    refusal: str = ""
    #: One at a time: applying it replaces the one in force.
    exclusive: bool = False

    @property
    def replaces(self) -> tuple[str, ...]:
        """The names of the active faults applying it ends: the one it ``ends``, and itself when it is
        ``exclusive`` (the relations between faults, declared on each)."""
        return tuple(n for n in (self.ends, self.name if self.exclusive else None) if n is not None)

    @property
    def lasting(self) -> bool:
        """Kept as active until it ends (rather than happening once)."""
        return not self.once or self.lasts is not None

    @property
    def option_names(self) -> tuple[str, ...]:
        names = [o.name for o in self.options]
        if not self.once:
            names.append("for")
        return tuple(names)

    def json_usage(self) -> str:
        """The fault as a JSON body: ``{"name": "drop", "options": {"share" | "every", ...}}``."""
        keys = [o.name for o in self.options]
        if self.positional is not None:
            keys.insert(0, self.positional.name)
        if not self.once:
            keys.append("for")
        return f'{{"name": "{self.name}", "options": {{...}}}} with options {", ".join(keys) or "none"}'

    def usage(self) -> str:
        parts = [self.name]
        if self.positional is not None:
            parts.append(self.positional.metavar)
        parts += [f"[--{o.name} {o.metavar}]" for o in self.options]
        if not self.once:
            parts.append("[--for DURATION]")
        return " ".join(parts)


_SELECT = (CONNECTION, ORIGINATOR)
#: Options no request gives together: one connection or one originator's; a share or every Nth.
EXCLUSIVE_OPTIONS: tuple[tuple[str, str], ...] = (("connection", "originator"), ("share", "every"))

FAULTS: dict[str, FaultKind] = {kind.name: kind for kind in (
    FaultKind("stop-producing", CLASS1, "no T->O data: the originator's connection times out",
              class1.StopProducing, _SELECT),
    FaultKind("drop", CLASS1, "drop a share or every Nth T->O packet", class1.Drop, (*_SELECT, SHARE, EVERY),
              requires=(("share", "every"),)),
    FaultKind("duplicate", CLASS1, "send every (or every Nth) T->O packet twice", class1.Duplicate,
              (*_SELECT, EVERY)),
    FaultKind("reorder", CLASS1, "swap each two consecutive T->O packets", class1.Reorder, _SELECT),
    FaultKind("delay", CLASS1, "delay T->O packets", class1.Delay, (*_SELECT, BY, JITTER)),
    FaultKind("freeze-sequence", CLASS1, "T->O packets keep one CIP sequence count (no new data)",
              class1.FreezeSequence, _SELECT),
    FaultKind("wrong-size", CLASS1, "T->O data of the wrong size", class1.WrongSize, (*_SELECT, SIZE)),
    FaultKind("ignore-output", CLASS1, "O->T data not given to the device (it keeps its last command)",
              class1.IgnoreOutput, _SELECT),
    FaultKind("idle", CLASS1, "O->T run/idle header handed to the device as idle", class1.Idle, _SELECT),
    FaultKind("delay-replies", EXPLICIT, "delay every explicit reply (TCP)", explicit.DelayReplies, (BY, JITTER),
              exclusive=True),
    FaultKind("error-status", EXPLICIT, "answer matching requests with a chosen status", explicit.ErrorStatus,
              (STATUS, SERVICE, CLASS, INSTANCE, ATTRIBUTE, COUNT), requires=(("status",),)),
    FaultKind("refuse-forward-open", EXPLICIT, "refuse the next Forward_Opens with a Connection Manager status",
              explicit.RefuseForwardOpen, (COUNT,), positional=EXTENDED),
    FaultKind("close-tcp", EXPLICIT, "close every TCP connection (sessions and class 3 go with them)",
              explicit.CloseTcp, once=True),
    FaultKind("drop-sessions", EXPLICIT, "forget every session (their TCP connections stay open)",
              explicit.DropSessions, once=True),
    FaultKind("unplug", DEVICE, "link lost: every Ethernet port closed, connections time out; RS-485 goes on "
              "(until plug)", device.Unplug),
    FaultKind("plug", DEVICE, "end an unplug", device.Plug, once=True, ends="unplug",
              refusal="the device is not unplugged"),
    FaultKind("power-cycle", DEVICE, "power loss: every port closed and RS-485 silent, connections gone, the run "
              "stopped, unsaved parameters lost; power back after --off (or when cleared)", device.PowerCycle,
              (OFF,), once=True, lasts="off"),
    FaultKind("expire-certificate", SECURITY, "new TLS and DTLS handshakes present the device's certificate "
              "re-issued by the lab CA with its validity ended", security.ExpireCertificate),
    FaultKind("revoke-certificate", SECURITY, "the lab CA revokes the device's certificate: crl.pem in the "
              "security folder lists it, and originators that read the folder refuse the device",
              security.RevokeCertificate),
    FaultKind("refuse-cipher-suite", SECURITY, "new TLS and DTLS handshakes no longer accept a TLS 1.2 suite",
              security.RefuseCipherSuite, positional=SUITE),
    FaultKind("drop-dtls-records", SECURITY, "drop a share or every Nth whole DTLS record the device receives "
              "or sends, before decryption", security.DropDtlsRecords, (DTLS_PEER, SHARE, EVERY, DIRECTION),
              requires=(("share", "every"),)),
)}


def valid_faults() -> str:
    return ", ".join(FAULTS)


def kind_of(name: str) -> FaultKind:
    kind = FAULTS.get(name)
    if kind is None:
        raise FaultError(f"unknown fault {name!r}; valid: {valid_faults()}")
    return kind


@dataclass(frozen=True)
class Spelling:
    """How a surface names a fault's options in its messages: the command line's ``--share``, or the
    JSON key ``"share"`` (the HTTP API, the control socket, scenarios)."""

    option: Callable[[str], str]
    usage: Callable[[FaultKind], str]


CLI_SPELLING = Spelling(lambda name: f"--{name}", lambda kind: kind.usage())
JSON_SPELLING = Spelling(lambda name: f'"{name}"', lambda kind: kind.json_usage())


@dataclass(frozen=True)
class FaultRequest:
    """A fault by name with its checked options (``for``: the duration, None: until cleared): by their
    names as given (``options``: what a record, an event and ``describe`` show) and as the typed record
    the effect reads (``settings``), both made once by ``build``."""

    name: str
    options: Mapping[str, Any] = field(default_factory=dict)
    settings: FaultOptions = field(default_factory=FaultOptions)

    def __post_init__(self) -> None:
        # A request made with its checked options alone (``FaultRequest(name, options)``) has its record
        # made here, so that its effect reads what the options say.
        if self.options and self.settings == FaultOptions():
            object.__setattr__(self, "settings", typed_options(self.kind, self.options))

    @property
    def kind(self) -> FaultKind:
        return FAULTS[self.name]

    @property
    def duration(self) -> float | None:
        kind = self.kind
        if kind.lasts is None:
            return self.settings.duration
        value = getattr(self.settings, kind.lasts)
        return 0.0 if value is None else float(value)

    @classmethod
    def build(cls, name: str, options: Mapping[str, object] | None = None,
              spelling: Spelling = CLI_SPELLING) -> FaultRequest:
        """Check ``options`` (raw values: text or numbers) against the fault ``name``; the messages name
        the options as ``spelling`` does."""
        said, usage = spelling.option, spelling.usage
        if not isinstance(name, str):
            raise FaultError(f"a fault is named by text; valid: {valid_faults()}")
        kind = kind_of(name)
        options = dict(options or {})
        checked: dict[str, Any] = {}
        typed: dict[str, Any] = {}
        allowed = {o.name: o for o in kind.options}
        if kind.positional is not None:
            allowed[kind.positional.name] = kind.positional
        if not kind.once:
            allowed["for"] = FOR
        for key, value in options.items():
            key = str(key).replace("_", "-")
            option = allowed.get(key)
            if option is None:
                valid = ", ".join(said(n) for n in allowed) or "none"
                raise FaultError(f"unknown option {said(key)} for {name}; valid: {valid}")
            if value is None:
                continue
            try:
                checked[key] = typed[option.field] = option.parse(value)
            except FaultError as exc:
                raise FaultError(f"{name} {said(key)}: {exc}") from None
        if kind.positional is not None and kind.positional.name not in checked:
            raise FaultError(f"{name} needs its {kind.positional.metavar}: {usage(kind)}")
        for group in kind.requires:
            if not any(g in checked for g in group):
                raise FaultError(f"{name} needs {' or '.join(said(g) for g in group)}: {usage(kind)}")
        for one, other in EXCLUSIVE_OPTIONS:
            if one in checked and other in checked:
                raise FaultError(f"{name}: {said(one)} or {said(other)}, not both")
        return cls(name, checked, FaultOptions(**typed))

    def describe(self) -> str:
        parts = [self.name]
        for key, value in self.options.items():
            parts.append(f"--{key} {format_value(key, value)}")
        return " ".join(parts)

    def as_json(self) -> dict[str, Any]:
        """Options as plain JSON values (a status as ``0x01/0x0100``)."""
        return {key: (format_value(key, value) if key == "status" else value) for key, value in self.options.items()}


def typed_options(kind: FaultKind, checked: Mapping[str, Any]) -> FaultOptions:
    """The typed record of options already checked against ``kind``, by their option names."""
    options = {o.name: o for o in (*kind.options, FOR, *((kind.positional,) if kind.positional else ()))}
    return FaultOptions(**{options[name].field: value for name, value in checked.items()})


def format_value(key: str, value: Any) -> str:
    if key == "status" and isinstance(value, tuple):
        general, extended = value
        return f"0x{general:02X}" + "".join(f"/0x{e:04X}" for e in extended)
    if key == "status" and isinstance(value, int):
        return f"0x{value:04X}"
    if key == "connection" and isinstance(value, int):
        return f"0x{value:08X}"
    if isinstance(value, float) and key in ("for", "by", "jitter", "off"):
        return f"{value:g}s"
    return str(value)


def parse_arguments(name: str, arguments: Sequence[str]) -> FaultRequest:
    """A fault as the command line gives it: ``NAME [POSITIONAL] [--option VALUE]...`` (also
    ``--option=VALUE``)."""
    kind = kind_of(name)
    options: dict[str, object] = {}
    tokens = list(arguments)
    index = 0
    while index < len(tokens):
        token = tokens[index]
        index += 1
        if token.startswith("--"):
            key, equals, value = token[2:].partition("=")
            if not equals:
                if index >= len(tokens):
                    raise FaultError(f"{name} --{key} needs a value: {kind.usage()}")
                value = tokens[index]
                index += 1
            options[key] = value
        elif kind.positional is not None and kind.positional.name not in options:
            options[kind.positional.name] = token
        else:
            raise FaultError(f"{name}: unexpected argument {token!r}: {kind.usage()}")
    return FaultRequest.build(name, options)
