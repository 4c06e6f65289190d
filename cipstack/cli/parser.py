"""The command line's grammar: every command and option, with its help and default."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .. import __version__
from ..eip.encapsulation import DEFAULT_PORT
from .common import (
    UsageError,
    parse_duration,
    parse_number,
)
from .drive import _trip_code, cmd_drive_status, cmd_drive_trip
from .eds import cmd_eds_check, cmd_eds_generate, cmd_eds_show
from .emulators import cmd_adapter, cmd_componet, cmd_models
from .explicit import cmd_discover, cmd_get, cmd_identity, cmd_set
from .fleet import cmd_fleet
from .io import cmd_io


# -- parser ------------------------------------------------------------------------------------------
class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> Any:  # one line, exit 2, no usage dump
        raise UsageError(message)


# The eds and capture commands take their arguments from modules that take tens of milliseconds
# to import: the parser names them with these lines, and adds their arguments only when the
# command line is theirs (see ``build_parser``).
_EDS_HELP = "EDS files: generate, check, show"
_CAPTURE_HELP = "analyse a pcap/pcapng capture of EtherNet/IP and CIP traffic"


def command_word(argv: list[str]) -> str | None:
    """The command a command line names (``get`` in ``--log-level DEBUG get HOST 1/1/7``), or None."""
    words = iter(argv)
    for word in words:
        if word == "--log-level":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole command line; given the ``command`` it will parse, the ``eds`` and ``capture``
    commands are only named unless it is theirs (a one-shot ``get`` does not import the EDS tool)."""
    parser = _Parser(prog="cipstack", description="CIP for AC drives over EtherNet/IP and CompoNet")
    parser.add_argument("--version", action="version", version=f"cipstack {__version__}")
    levels = ["DEBUG", "INFO", "WARNING", "ERROR"]
    parser.add_argument("--log-level", default="INFO", choices=levels, type=str.upper,
                        help="log level on stderr (default INFO)")
    # Also accepted after the command name (``cipstack adapter --log-level WARNING``).
    logging_options = _Parser(add_help=False)
    logging_options.add_argument("--log-level", default=argparse.SUPPRESS, choices=levels, type=str.upper,
                                 help="log level on stderr (default INFO)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    _add_parser = sub.add_parser

    def add_parser(name: str, **kwargs: Any) -> argparse.ArgumentParser:
        return _add_parser(name, parents=[logging_options], **kwargs)

    sub.add_parser = add_parser  # type: ignore[method-assign]

    def common(p: argparse.ArgumentParser, target: bool = True) -> None:
        if target:
            p.add_argument("target", metavar="HOST[:PORT]", help=f"target address (default port {DEFAULT_PORT})")
        p.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout (default 5 s)")
        p.add_argument("--json", action="store_true", help="one JSON object per line")

    p = sub.add_parser("adapter", help="run the adapter emulator")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"EtherNet/IP port, TCP and UDP (default {DEFAULT_PORT})")
    device = p.add_mutually_exclusive_group()
    device.add_argument("--profile", help="device profile: acg (default), mx2, rx")
    device.add_argument("--eds", metavar="FILE",
                        help="emulate the generic device an EDS file describes (identity, parameters as "
                             "attributes, assemblies, connections)")
    p.add_argument("--model", help="model of the mx2/rx profiles (e.g. MX2-A2015-E, RX-A4055-E)")
    p.add_argument("--max-sessions", type=lambda t: parse_number(t, "max sessions"), default=32,
                   help="encapsulation sessions at once; one more is refused with 0x0002 (default 32)")
    p.add_argument("--max-sessions-per-host", type=lambda t: parse_number(t, "max sessions per host"),
                   help="sessions one originator address may hold (default: half of --max-sessions)")
    p.add_argument("--max-connections", type=lambda t: parse_number(t, "max connections"), default=32,
                   help="class 3 (connected explicit) connections (default 32)")
    p.add_argument("--max-io-connections", type=lambda t: parse_number(t, "max io connections"),
                   help="class 1 (I/O) connections (default: the device's, 64 for the ACG-ET2)")
    p.add_argument("--max-tcp-connections", type=lambda t: parse_number(t, "max tcp connections"), default=256,
                   help="open TCP connections to the encapsulation port; more are closed at accept (default 256)")
    p.add_argument("--max-tcp-connections-per-host", type=lambda t: parse_number(t, "max tcp connections per host"),
                   help="open TCP connections from one address (default: half of --max-tcp-connections)")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=2222,
                   help="UDP port of class 1 I/O (default 2222; 0 picks a free one)")
    p.add_argument("--control", type=Path, help="control socket for `cipstack drive` (default: per port)")
    p.add_argument("--state", type=Path,
                   help="state file of saved parameters (default: in the user's data directory, per profile)")
    p.add_argument("--modbus-port", type=lambda t: parse_number(t, "modbus port"),
                   help="also serve Modbus TCP on this port (ACG)")
    p.add_argument("--param", action="append", metavar="CODE=VALUE",
                   help="set an ACG keypad parameter at start, in the keypad's unit; repeatable "
                        "(drv=4 Frq=8: run from the network)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_adapter)

    p = sub.add_parser("fleet", help="emulate many devices at once, each on its own address")
    p.add_argument("--addresses", metavar="RANGE[,...]",
                   help="the addresses the devices take in order: 127.0.0.10-127.0.0.73, or a list "
                        "(127.0.0.10,127.0.0.12-127.0.0.20); any 127.x works on Linux's loopback")
    p.add_argument("--device", action="append", metavar="PROFILE[:MODEL][*COUNT][@FIRST]",
                   help="a group of devices: acg*32, mx2:MX2-A2015-E*16, rx*2@127.0.0.90 (from that address "
                        "on); repeatable")
    p.add_argument("--spec", type=Path, metavar="FILE", help="the fleet in a TOML file (see the README)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"),
                   help=f"EtherNet/IP port of every device, TCP and UDP (default {DEFAULT_PORT})")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"),
                   help="UDP port of class 1 I/O of every device (default 2222)")
    p.add_argument("--state-dir", type=Path, metavar="DIR",
                   help="where each device keeps its state file, ADDRESS-PROFILE[-MODEL].json (default: "
                        "fleet/ in the user's data directory)")
    p.add_argument("--param", action="append", metavar="CODE=VALUE",
                   help="set an ACG keypad parameter at start on every ACG device; repeatable")
    p.add_argument("--workers", type=lambda t: parse_number(t, "workers"),
                   help="spread the devices over N processes, one event loop each (default 1)")
    p.set_defaults(func=cmd_fleet)

    p = sub.add_parser("models", help="the MX2/RX models the mx2/rx profiles emulate (Tables 2/3)")
    p.add_argument("--profile", choices=["mx2", "rx"], help="one family only (default: both)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=cmd_models)

    p = sub.add_parser("componet", help="run a CompoNet network of MX2/RX slaves behind an EtherNet/IP gateway")
    p.add_argument("--nodes", required=True, metavar="PROFILE:MODEL@NODE,...",
                   help="slaves, e.g. mx2:MX2-A2015-E@3,rx:RX-A4055-E@5 (node addresses 0-63)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"EtherNet/IP port, TCP and UDP (default {DEFAULT_PORT})")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=2222,
                   help="UDP port of class 1 I/O (default 2222; 0 picks a free one)")
    p.add_argument("--control", type=Path, help="control socket (default: per port)")
    p.add_argument("--quiet", action="store_true", help="no status line on stdout")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=cmd_componet)

    p = sub.add_parser("discover", help="ListIdentity over UDP")
    p.add_argument("--broadcast", metavar="ADDRESS",
                   help="broadcast or unicast address (default: 255.255.255.255 and every interface's broadcast "
                        "address, loopback's 127.255.255.255 included)")
    p.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                   help=f"UDP port to ask (default {DEFAULT_PORT})")
    common(p, target=False)
    p.set_defaults(func=cmd_discover, timeout=2.0)

    p = sub.add_parser("identity", help="ListIdentity over TCP")
    common(p)
    p.set_defaults(func=cmd_identity)

    p = sub.add_parser("get", help="Get_Attribute_Single (or Get_Attributes_All without an attribute)")
    common(p)
    p.add_argument("path", metavar="CLASS/INSTANCE[/ATTRIBUTE]")
    p.add_argument("--type", help="CIP type to decode the value (UINT, SHORT_STRING, ...)")
    p.add_argument("--connected", action="store_true", help="use a class 3 connection")
    p.add_argument("--route", metavar="PORT/LINK[,...]",
                   help="route through the target (Unconnected_Send), e.g. 1/0 or 2/3 (CompoNet node 3)")
    p.set_defaults(func=cmd_get)

    p = sub.add_parser("io", help="open a class 1 connection, print input changes by field name")
    common(p)
    p.add_argument("--output", type=lambda t: parse_number(t, "output"), help="output (O->T) assembly instance")
    p.add_argument("--input", type=lambda t: parse_number(t, "input"), help="input assembly instance")
    p.add_argument("--heartbeat", type=lambda t: parse_number(t, "heartbeat"),
                   help="O->T heartbeat point instead of an output (input only: e.g. 198, listen only: 199)")
    p.add_argument("--rpi", metavar="DURATION",
                   help="requested packet interval with its unit: 10ms, 500us, 0.5s (default: the EDS's with "
                        "--eds, else 10ms)")
    p.add_argument("--eds", metavar="FILE", help="open a connection this EDS file describes (with --connection)")
    p.add_argument("--connection", metavar="N",
                   help="the ConnectionN of --eds to open, by number N or by name")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                   help="output field to set (or raw=HEX); repeatable")
    p.add_argument("--duration", type=parse_duration, default=5.0, help="how long to run (default 5s)")
    p.add_argument("--idle", action="store_true", help="send idle instead of run in the run/idle header")
    p.add_argument("--io-port", type=lambda t: parse_number(t, "io port"), default=0,
                   help="local UDP port for T->O data (default: any free port, announced to the target)")
    p.add_argument("--target-io-port", type=lambda t: parse_number(t, "target io port"), default=None,
                   help="the target's class 1 UDP port (default: the port its Forward_Open reply names, else 2222)")
    p.add_argument("--config", type=lambda t: parse_number(t, "config"), metavar="N",
                   help="configuration assembly instance of the connection path (default 1)")
    p.add_argument("--config-data", metavar="HEX", help="configuration data sent in the Forward_Open (hex bytes)")
    p.add_argument("--ot-format", choices=["run-idle", "heartbeat", "modeless"],
                   help="O->T real-time format: run-idle header (default), heartbeat (sequence count only, "
                        "size 2), modeless (no header); with --eds: the file's")
    p.add_argument("--list-fields", action="store_true",
                   help="list the output and input fields of the connection (names for --set and the input) and exit")
    p.add_argument("--timeout-multiplier", type=lambda t: parse_number(t, "timeout multiplier"), choices=range(8),
                   metavar="0..7", help="connection timeout = RPI x 4 x 2^N, each way (default 2: 16 ms at a 1 ms RPI; "
                                        "3 or more at RPIs under 2 ms on a busy host)")
    p.add_argument("--print", default="changes", metavar="changes|summary|every:DURATION",
                   help="input lines: every change (default), none (statistics only), or the latest at most "
                        "once per DURATION (every:1s)")
    p.set_defaults(func=cmd_io)

    p = sub.add_parser("drive", help="control a running emulator: inject a trip, read its status")
    drive = p.add_subparsers(dest="drive_command", required=True, parser_class=_Parser)
    for name, func, text in (("trip", cmd_drive_trip, "trip the emulated drive with a fault code"),
                             ("status", cmd_drive_status, "the emulated drive's status line")):
        q = drive.add_parser(name, help=text)
        if name == "trip":
            q.add_argument("code", type=_trip_code,
                           help="fault code of the drive's manual (decimal or 0x hex: 0x4200 on the ACG, 5 on "
                                "the MX2/RX) or its name (OverHeat, E05)")
        q.add_argument("--host", default="127.0.0.1",
                       help="the emulator's address (its --host), which with --port finds its control socket "
                            "(default 127.0.0.1)")
        q.add_argument("--port", type=lambda t: parse_number(t, "port"), default=DEFAULT_PORT,
                       help=f"the emulator's EtherNet/IP port, which finds its control socket (default {DEFAULT_PORT})")
        q.add_argument("--control", type=Path, help="the emulator's control socket")
        q.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout (default 5 s)")
        q.add_argument("--json", action="store_true", help="one JSON object per line")
        q.set_defaults(func=func)

    if command in (None, "eds"):
        _add_eds_commands(sub)
    else:
        sub.add_parser("eds", help=_EDS_HELP)
    if command in (None, "capture"):
        from ..capture.command import add_arguments as add_capture_arguments

        add_capture_arguments(sub, _CAPTURE_HELP)
    else:
        sub.add_parser("capture", help=_CAPTURE_HELP)

    p = sub.add_parser("set", help="Set_Attribute_Single")
    common(p)
    p.add_argument("path", metavar="CLASS/INSTANCE/ATTRIBUTE")
    p.add_argument("value")
    p.add_argument("--type", required=True, help="CIP type of the value (UINT, INT, REAL, SHORT_STRING, ...)")
    p.add_argument("--connected", action="store_true", help="use a class 3 connection")
    p.add_argument("--route", metavar="PORT/LINK[,...]", help="route through the target (Unconnected_Send)")
    p.set_defaults(func=cmd_set)
    return parser


def _add_eds_commands(sub: Any) -> None:
    from ..eds.commands import add_check_arguments, add_show_arguments
    from ..eds.commands_generate import add_generate_arguments

    p = sub.add_parser("eds", help=_EDS_HELP)
    eds = p.add_subparsers(dest="eds_command", required=True, parser_class=_Parser)
    q = eds.add_parser("check", help="check EDS files against the rules a configuration tool relies on")
    add_check_arguments(q)
    q.add_argument("--against", metavar="HOST[:PORT]", help="also compare [Device] with a live device's Identity")
    q.add_argument("--timeout", type=parse_duration, default=5.0, help="reply timeout with --against (default 5 s)")
    q.set_defaults(func=cmd_eds_check)
    q = eds.add_parser("generate", help="write the EDS files of emulated models")
    add_generate_arguments(q)
    q.set_defaults(func=cmd_eds_generate)
    q = eds.add_parser("show", help="a readable summary: identity, assemblies, connections")
    add_show_arguments(q)
    q.set_defaults(func=cmd_eds_show)
