"""The command line's grammar: every command and option, with its help and default."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .. import __version__
from ..eip.wire.encapsulation import DEFAULT_FRAME_TIMEOUT, DEFAULT_IO_PORT, DEFAULT_PORT, SECURE_PORT
from .common import (
    UsageError,
    parse_duration,
    parse_number,
)
from .help_texts import COMMANDS, PROGRAM


# -- parser ------------------------------------------------------------------------------------------
class _Formatter(argparse.RawDescriptionHelpFormatter):
    """The one formatter of every command: descriptions and examples as written (``help_texts``
    wraps them), options wrapped to the terminal."""


class _SubParsers(argparse._SubParsersAction):  # type: ignore[type-arg]  # generic in typeshed, not at run time
    """Names each command's parser after its path and gives it its text from ``help_texts``."""

    #: With the descriptions and examples ``--help`` prints (``_BriefSubParsers``: the help line alone).
    texts = True

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        path = (*getattr(self, "_prog_prefix", "cipstack").split()[1:], name)
        text = COMMANDS.get(path)
        if text is not None:
            kwargs["help"] = text.help
            if self.texts:
                kwargs.update(description=text.description_text(), epilog=text.epilog())
        kwargs.setdefault("formatter_class", _Formatter)
        parser: argparse.ArgumentParser = super().add_parser(name, **kwargs)
        return parser


class _BriefSubParsers(_SubParsers):
    """The commands of a line that asks for no help: wrapping their texts is most of the work."""

    texts = False


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _Formatter)
        super().__init__(*args, **kwargs)
        self.register("action", "parsers", _SubParsers)

    def error(self, message: str) -> Any:
        """A bad command line: the parser's usage and ``PROG: error: MESSAGE``, exit 2 (printed by
        ``main``, which owns the exit)."""
        raise UsageError(message, prog=self.prog, usage=self.format_usage())

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        try:
            return super().parse_known_args(args, namespace)
        except UsageError as exc:
            if exc.prog is None:  # raised by an argument's type (a bad number): this parser's error
                self.error(str(exc))
            raise


#: A path argument, for shell completion (shtab's names; shtab is needed only to print the script).
_FILE = {"bash": "_shtab_compgen_files", "zsh": "_files", "tcsh": "f"}
_DIRECTORY = {"bash": "_shtab_compgen_dirs", "zsh": "_files -/", "tcsh": "d"}


#: ``--security`` of the commands that send explicit requests (``get``, ``set``, ``identity``, ``params``...).
EXPLICIT_OVER_TLS = ("CIP Security: send the requests over TLS (TCP 2221 unless TARGET names a port) with the CA, "
                     "client certificate and key of DIR (`cipstack security init DIR`)")


def _complete(action: argparse.Action, kind: dict[str, str]) -> argparse.Action:
    action.complete = kind  # type: ignore[attr-defined]  # shtab reads it; argparse declares no such attribute
    return action


def arguments(parser: argparse.ArgumentParser) -> tuple[argparse.Action, ...]:
    """Every argument ``parser`` takes, in the order they were added: its positionals, its options
    (``--help`` included) and its choice of command, for a tool that walks the command line (a
    reference, a completion script, a check of the grammar). argparse offers no public list of them:
    this is the one place that reads its own."""
    return tuple(parser._actions)


def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The commands ``parser`` takes next, by name, in the order ``--help`` lists them: the commands
    of ``cipstack`` for ``build_parser(None)``, its subcommands for a command's own parser (``drive``:
    ``trip``...), none for a command that has no subcommand."""
    found: dict[str, argparse.ArgumentParser] = {}
    for action in arguments(parser):
        if isinstance(action, argparse._SubParsersAction):
            found.update(action.choices)
    return found


def command_word(argv: list[str]) -> str | None:
    """The command a command line names (``get`` in ``--log-level DEBUG get HOST 1/1/7``), or None."""
    words = iter(argv)
    for word in words:
        if word == "--log-level":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def build_parser(command: str | None = None, texts: bool = True) -> argparse.ArgumentParser:
    """The whole command line, or given the ``command`` it will parse, that command alone (a one-shot
    ``get`` builds no other command's options and imports no other command's module).
    A default a help text names is argparse's own (``%(default)s``), so the two cannot disagree.
    ``texts``: the descriptions and examples ``--help`` prints (wrapping them is most of the work of
    building a command: a line that asks for no help goes without)."""
    parser = _Parser(prog="cipstack", description=PROGRAM.description_text() if texts else None,
                     epilog=PROGRAM.epilog() if texts else None)
    parser.add_argument("--version", action="version", version=f"cipstack {__version__}")
    levels = ["DEBUG", "INFO", "WARNING", "ERROR"]
    parser.add_argument("--log-level", default="INFO", choices=levels, type=str.upper,
                        help="log level on stderr (default %(default)s)")
    # Also accepted after the command name (``cipstack adapter --log-level WARNING``).
    logging_options = _Parser(add_help=False)
    logging_options.add_argument("--log-level", default=argparse.SUPPRESS, choices=levels, type=str.upper,
                                 help=f"log level on stderr (default {parser.get_default('log_level')})")
    # Not required here: without a command ``main`` prints the list of commands.
    if not texts:
        parser.register("action", "parsers", _BriefSubParsers)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands", parser_class=_Parser)
    _add_parser = sub.add_parser

    def add_parser(name: str, **kwargs: Any) -> argparse.ArgumentParser:
        return _add_parser(name, parents=[logging_options], **kwargs)

    # argparse has no option for parents every subparser shares; typeshed's add_parser names every keyword.
    sub.add_parser = add_parser  # type: ignore[method-assign, assignment]

    if (command,) not in COMMANDS:
        command = None  # no command, or one that is not: every command, for the list and the error

    def wanted(name: str) -> bool:
        """Whether to build the command ``name``: every command for the full help, else only the one
        the line names (``cipstack get`` builds and imports no other command)."""
        return command is None or command == name

    def number(what: str) -> Any:
        return lambda text: parse_number(text, what)

    def common(p: argparse.ArgumentParser, target: bool = True, timeout: float = 5.0, secured: bool = False) -> None:
        if target:
            p.add_argument("target", metavar="HOST[:PORT]", help=f"target address (default port {DEFAULT_PORT})")
        p.add_argument("--timeout", type=parse_duration, default=timeout, metavar="DURATION",
                       help="reply timeout: 2, 500ms, 1.5s (default %(default)s s)")
        p.add_argument("--json", action="store_true", help="one JSON object per line")
        if secured:
            _complete(p.add_argument("--security", type=Path, metavar="DIR", help=EXPLICIT_OVER_TLS), _DIRECTORY)

    if wanted("adapter"):
        from .emulators import cmd_adapter

        p = sub.add_parser("adapter")
        p.add_argument("--host", default="127.0.0.1", help="address to listen on (default %(default)s)")
        p.add_argument("--port", type=number("port"), default=DEFAULT_PORT,
                       help="EtherNet/IP port, TCP and UDP (default %(default)s)")
        device = p.add_mutually_exclusive_group()
        device.add_argument("--profile", help="device family: acg (default), mx2, rx, or one another package "
                                                 "brings (`cipstack models` lists them)")
        _complete(device.add_argument("--eds", metavar="FILE",
                                      help="emulate the generic device an EDS file describes (identity, parameters "
                                           "as attributes, assemblies, connections)"), _FILE)
        p.add_argument("--model", help="model of a family with models, e.g. the mx2/rx profiles' MX2-A2015-E, "
                                       "RX-A4055-E (`cipstack models` lists them)")
        p.add_argument("--max-sessions", type=number("max sessions"), default=32, metavar="N",
                       help="encapsulation sessions at once; one more is refused with 0x0002 (default %(default)s)")
        p.add_argument("--max-sessions-per-host", type=number("max sessions per host"), metavar="N",
                       help="sessions one originator address may hold (default: half of --max-sessions)")
        p.add_argument("--max-connections", type=number("max connections"), default=32, metavar="N",
                       help="class 3 (connected explicit) connections (default %(default)s)")
        p.add_argument("--max-io-connections", type=number("max io connections"), metavar="N",
                       help="class 1 (I/O) connections (default: the device's, 64 for the ACG-ET2)")
        p.add_argument("--max-tcp-connections", type=number("max tcp connections"), default=256, metavar="N",
                       help="open TCP connections to the encapsulation port; more are closed at accept "
                            "(default %(default)s)")
        p.add_argument("--max-tcp-connections-per-host", type=number("max tcp connections per host"), metavar="N",
                       help="open TCP connections from one address (default: half of --max-tcp-connections)")
        p.add_argument("--frame-timeout", type=parse_duration, default=DEFAULT_FRAME_TIMEOUT, metavar="SECONDS",
                       help="time a TCP frame, once begun, has to arrive whole; a slower one closes its connection "
                            "(default %(default)s s)")
        p.add_argument("--io-port", type=number("io port"), default=DEFAULT_IO_PORT, metavar="N",
                       help="UDP port of class 1 I/O (default %(default)s; 0 picks a free one)")
        p.add_argument("--io-gather", type=parse_duration, metavar="DURATION",
                       help="while the next class 1 production is this near (e.g. 12.5ms), O->T datagrams do not "
                            "wake the emulator: the production reads them first (less CPU per packet; "
                            "default 0: off)")
        _complete(p.add_argument("--control", type=Path, metavar="PATH",
                                 help="control socket for `cipstack drive` (default: per address and port)"), _FILE)
        _complete(p.add_argument("--state", type=Path, metavar="FILE",
                                 help="state file of saved parameters (default: in the user's data directory, "
                                      "per profile)"), _FILE)
        p.add_argument("--factory", action="store_true",
                       help="start from factory settings without reading or writing the state file: a save lasts "
                            "until the emulator stops (for examples and tests that change parameters)")
        p.add_argument("--modbus-port", type=number("modbus port"), metavar="N",
                       help="also serve Modbus TCP on this port (ACG)")
        p.add_argument("--rtu", metavar="DEVICE",
                       help="also answer Modbus-RTU on the drive's RS-485 port (ACG): a serial device such as "
                            "/dev/ttyUSB0 (needs pyserial: the rtu extra), or pty for a new pseudo-terminal whose "
                            "path is printed; line settings from CM.1, CM.3, CM.4, CM.5")
        p.add_argument("--param", action="append", metavar="CODE=VALUE",
                       help="enter a keypad parameter at start by its code, in the keypad's unit: kept at a "
                            "power-cycle, as the drive keeps a keypad entry; repeatable: the ACG's keypad codes "
                            "(drv=4 Frq=8: run from the network; ACC=2.5), an MX2/RX Digital Operator function "
                            "code (A004=60 is 60.0 Hz, A001=2, P044=1.5)")
        p.add_argument("--param-unsaved", action="store_true",
                       help="write the --param values as over communication instead: not saved, so a "
                            "power-cycle loses them")
        p.add_argument("--quiet", action="store_true", help="no status line on stdout")
        _complete(p.add_argument("--security", type=Path, metavar="DIR",
                                 help="CIP Security: also serve EtherNet/IP over TLS (TCP) and DTLS (UDP, with "
                                      "secured class 1), with the CA, device certificate and key of DIR (`cipstack "
                                      "security init DIR`); client certificates are verified against the CA"),
                  _DIRECTORY)
        p.add_argument("--security-port", type=number("security port"), metavar="N",
                       help="TCP and UDP port of EtherNet/IP over TLS and DTLS, with --security or once "
                            "configured over the network (default 2221; 0 picks a free one)")
        p.add_argument("--secure-only", action="store_true",
                       help="once configured, refuse explicit requests on plain TCP with CIP status 0x0F "
                            "(privilege violation); ListIdentity and sessions still answer")
        p.add_argument("--security-config-timeout", type=float, metavar="SECONDS",
                       help="seconds a configuration session lasts without Kick_Timer (default 60)")
        p.add_argument("--no-security-objects", action="store_true",
                       help="serve no CIP Security objects (0x5D-0x5F): the device cannot be configured over the "
                            "network")
        _add_http_arguments(p)
        _complete(p.add_argument("--scenario", type=Path, metavar="FILE.toml",
                                 help="run this timeline of faults and actions (docs/scenarios.md), then exit: 0 when "
                                      "every step fired, 1 when one did not"), _FILE)
        p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
        p.set_defaults(func=cmd_adapter)

    if wanted("fleet"):
        from .fleet import DEFAULT_WORKERS, cmd_fleet

        p = sub.add_parser("fleet")
        p.add_argument("--addresses", metavar="RANGE[,...]",
                       help="the addresses the devices take in order: 127.0.0.10-127.0.0.73, or a list "
                            "(127.0.0.10,127.0.0.12-127.0.0.20); any 127.x works on Linux's loopback")
        p.add_argument("--device", action="append", metavar="PROFILE[:MODEL][*COUNT][@FIRST]",
                       help="a group of devices: acg*32, mx2:MX2-A2015-E*16, rx*2@127.0.0.90 (from that address "
                            "on); repeatable")
        _complete(p.add_argument("--spec", type=Path, metavar="FILE",
                                 help="the fleet in a TOML file (devices, addresses, ports, workers)"), _FILE)
        # No argparse defaults below: a value given here overrides the --spec file's, which overrides these.
        p.add_argument("--port", type=number("port"), metavar="N",
                       help=f"EtherNet/IP port of every device, TCP and UDP (default {DEFAULT_PORT})")
        p.add_argument("--io-port", type=number("io port"), metavar="N",
                       help=f"UDP port of class 1 I/O of every device (default {DEFAULT_IO_PORT})")
        _complete(p.add_argument("--state-dir", type=Path, metavar="DIR",
                                 help="where each device keeps its state file, ADDRESS-PROFILE[-MODEL].json "
                                      "(default: fleet/ in the user's data directory)"), _DIRECTORY)
        p.add_argument("--factory", action="store_true",
                       help="every device starts from factory settings; no state file is read or written")
        p.add_argument("--param", action="append", metavar="CODE=VALUE",
                       help="set an ACG keypad parameter at start on every ACG device; repeatable")
        _add_http_arguments(p)
        _complete(p.add_argument("--security", type=Path, metavar="DIR",
                                 help="CIP Security: every device also serves EtherNet/IP over TLS (TCP) and DTLS "
                                      "(UDP, with secured class 1) at its address, with the CA, device certificate "
                                      "and key of DIR (`cipstack security init DIR`), as `cipstack adapter "
                                      "--security` does; client certificates are verified against the CA"),
                  _DIRECTORY)
        p.add_argument("--security-port", type=number("security port"), metavar="N",
                       help=f"TCP and UDP port of EtherNet/IP over TLS and DTLS at every device, with --security "
                            f"(default {SECURE_PORT})")
        p.add_argument("--workers", type=number("workers"), metavar="N",
                       help=f"spread the devices over N processes, one event loop each (default {DEFAULT_WORKERS})")
        p.add_argument("--rtu", metavar="DEVICE",
                       help="put the ACG drives (up to 16) on one RS-485 Modbus-RTU line: pty (a new pseudo-terminal, "
                            "its path printed) or a serial device; station IDs 1, 2, ... in address order")
        p.add_argument("--shard", metavar="INDEX/COUNT",
                       help="serve one of COUNT contiguous shares of the plant's devices (in address order), INDEX "
                            "from 0: 0/3 is the first of three; each machine or pod runs one, from the same spec")
        p.add_argument("--max-devices", type=number("max devices"), metavar="N",
                       help="serve up to N devices (default 1024): more where the machine's open-file limit allows "
                            "(about 12 descriptors a device in each worker)")
        p.add_argument("--list-addresses", action="store_true",
                       help="print the addresses of the devices this fleet (or shard) serves, one a line, and exit")
        p.set_defaults(func=cmd_fleet)

    if wanted("plant"):
        from .fleet import cmd_plant

        p = sub.add_parser("plant")
        p.add_argument("--fleet", action="append", required=True, metavar="NAME:PORT",
                       help="the fleets' HTTP APIs: a DNS name whose A records are every fleet (a Kubernetes "
                            "headless Service), or an address; repeatable")
        p.add_argument("--refresh", type=parse_duration, default=5.0, metavar="DURATION",
                       help="how often to look for fleets and ask each for its devices (default %(default)s s)")
        _add_http_arguments(p)
        p.set_defaults(func=cmd_plant)

    if wanted("models"):
        from ..devices.profiles import PROFILES
        from .emulators import cmd_models

        p = sub.add_parser("models")
        p.add_argument("--profile", choices=list(PROFILES), help="one family only (default: every family)")
        p.add_argument("--json", action="store_true", help="one JSON object per line")
        p.set_defaults(func=cmd_models)

    if wanted("componet"):
        from .emulators import cmd_componet

        p = sub.add_parser("componet")
        p.add_argument("--nodes", required=True, metavar="PROFILE:MODEL@NODE,...",
                       help="slaves, e.g. mx2:MX2-A2015-E@3,rx:RX-A4055-E@5 (node addresses 0-63)")
        p.add_argument("--host", default="127.0.0.1", help="address to listen on (default %(default)s)")
        p.add_argument("--port", type=number("port"), default=DEFAULT_PORT,
                       help="EtherNet/IP port, TCP and UDP (default %(default)s)")
        p.add_argument("--io-port", type=number("io port"), default=DEFAULT_IO_PORT, metavar="N",
                       help="UDP port of class 1 I/O (default %(default)s; 0 picks a free one)")
        _complete(p.add_argument("--control", type=Path, metavar="PATH",
                                 help="control socket (default: per address and port)"), _FILE)
        p.add_argument("--quiet", action="store_true", help="no status line on stdout")
        p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
        p.set_defaults(func=cmd_componet)

    if wanted("discover"):
        from .explicit import cmd_discover

        p = sub.add_parser("discover")
        p.add_argument("--broadcast", metavar="ADDRESS",
                       help="broadcast or unicast address (default: 255.255.255.255 and every interface's broadcast "
                            "address, loopback's 127.255.255.255 included); with --security the devices' own "
                            "addresses, HOST[:PORT][,HOST[:PORT]...]")
        p.add_argument("--port", type=number("port"),
                       help=f"UDP port to ask (default {DEFAULT_PORT}; with --security {SECURE_PORT})")
        common(p, target=False, timeout=2.0)
        _complete(p.add_argument("--security", type=Path, metavar="DIR",
                                 help="CIP Security: ask each device of --broadcast in a DTLS session of its own "
                                      "(UDP 2221 unless --port or HOST:PORT) with the CA, client certificate and key "
                                      "of DIR (`cipstack security init DIR`); a broadcast cannot be secured"),
                  _DIRECTORY)
        p.set_defaults(func=cmd_discover)

    if wanted("identity"):
        from .explicit import cmd_identity

        p = sub.add_parser("identity")
        common(p, secured=True)
        p.set_defaults(func=cmd_identity)

    if wanted("get"):
        from .explicit import cmd_get

        p = sub.add_parser("get")
        common(p, secured=True)
        p.add_argument("path", metavar="CLASS/INSTANCE[/ATTRIBUTE]|CODE",
                       help="decimal or 0x hex numbers: 1/1/7, 0x2A/1/102; or a parameter's code: ACC, CM.24, A004, "
                            "an EDS ParamN or its name")
        p.add_argument("--type", help="CIP type to decode the value (UINT, SHORT_STRING, ...)")
        p.add_argument("--connected", action="store_true", help="use a class 3 connection")
        p.add_argument("--route", metavar="PORT/LINK[,...]",
                       help="route through the target (Unconnected_Send), e.g. 1/0 or 2/3 (CompoNet node 3)")
        p.add_argument("--eds", metavar="FILE",
                       help="decode by this EDS file's parameters (link paths, units, scaling) instead of the "
                            "device's profile")
        p.set_defaults(func=cmd_get)

    if wanted("params"):
        from .params import add_arguments as add_params_arguments

        add_params_arguments(sub, _Parser, common)

    if wanted("set"):
        from .explicit import cmd_set

        p = sub.add_parser("set")
        common(p, secured=True)
        p.add_argument("path", metavar="CLASS/INSTANCE/ATTRIBUTE|CODE",
                       help="decimal or 0x hex numbers: 0xF5/1/13; or a parameter's code: ACC, CM.24, A004, an EDS "
                            "ParamN or its name")
        p.add_argument("value", metavar="VALUE",
                       help="by path, the raw value, as on the wire (50 for 5.0 s at 0.1 s per step); BOOL also "
                            "true/false/on/off. By code, the value in the parameter's unit (2.5 for 2.5 s), as the "
                            "keypad takes it")
        p.add_argument("--type", help="CIP type of the value (UINT, INT, REAL, SHORT_STRING, ...); "
                                      "default: the attribute's declaration")
        p.add_argument("--scaled", action="store_true",
                       help="VALUE is the engineering value (5.0 for 5.0 s), turned into raw steps by the declaration")
        p.add_argument("--connected", action="store_true", help="use a class 3 connection")
        p.add_argument("--route", metavar="PORT/LINK[,...]", help="route through the target (Unconnected_Send)")
        p.add_argument("--eds", metavar="FILE",
                       help="decode by this EDS file's parameters (link paths, units, scaling) instead of the "
                            "device's profile")
        p.set_defaults(func=cmd_set)

    if wanted("io"):
        from .io import PRINT_MODES, cmd_io

        p = sub.add_parser("io")
        common(p)
        _complete(p.add_argument("--security", type=Path, metavar="DIR",
                                 help="CIP Security: open the connection over DTLS (UDP 2221 unless TARGET names "
                                      "a port) with the CA, client certificate and key of DIR (`cipstack security "
                                      "init DIR`); its data flows in the DTLS session"), _DIRECTORY)
        p.add_argument("--output", type=number("output"), metavar="N", help="output (O->T) assembly instance")
        p.add_argument("--input", type=number("input"), metavar="N", help="input assembly instance")
        p.add_argument("--heartbeat", type=number("heartbeat"), metavar="N",
                       help="O->T heartbeat point instead of an output (input only: e.g. 198, listen only: 199)")
        p.add_argument("--rpi", metavar="DURATION",
                       help="requested packet interval with its unit: 10ms, 500us, 0.5s (default: the EDS's with "
                            "--eds, else 10ms)")
        _complete(p.add_argument("--eds", metavar="FILE", help="open a connection this EDS file describes "
                                                                "(with --connection), or take only field names from "
                                                                "it (with --output/--input)"), _FILE)
        p.add_argument("--connection", metavar="N",
                       help="the ConnectionN of --eds to open, by number N or by name")
        p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                       help="output field to set, a raw value in the field's unit (see --list-fields), or "
                            "raw=HEX; repeatable")
        p.add_argument("--duration", type=parse_duration, default=5.0, metavar="DURATION",
                       help="how long to run (default %(default)s s)")
        p.add_argument("--idle", action="store_true", help="send idle instead of run in the run/idle header")
        p.add_argument("--io-port", type=number("io port"), default=0, metavar="N",
                       help="local UDP port for T->O data (default %(default)s: any free port, announced to the "
                            "target)")
        p.add_argument("--target-io-port", type=number("target io port"), metavar="N",
                       help="the target's class 1 UDP port (default: the port its Forward_Open reply names, else "
                            f"{DEFAULT_IO_PORT})")
        p.add_argument("--multicast", action="store_true",
                       help="ask T->O multicast (a listen-only connection needs an owner opened so); with --eds: "
                            "the file's transport, and multicast when it allows both and the target refuses "
                            "point-to-point (0x0108)")
        p.add_argument("--config", type=number("config"), metavar="N",
                       help="configuration assembly instance of the connection path (default 1)")
        p.add_argument("--config-data", metavar="HEX", help="configuration data sent in the Forward_Open (hex bytes)")
        p.add_argument("--ot-format", choices=["run-idle", "heartbeat", "modeless"],
                       help="O->T real-time format: run-idle header (default), heartbeat (sequence count only, "
                            "size 2), modeless (no header); with --eds: the file's")
        p.add_argument("--list-fields", action="store_true",
                       help="list the output and input fields of the connection (names for --set and the input, "
                            "and the unit of a raw value) and exit")
        p.add_argument("--timeout-multiplier", type=number("timeout multiplier"), choices=range(8),
                       metavar="0..7", help="connection timeout = RPI x 4 x 2^N, each way (default 2: 16 ms at a "
                                            "1 ms RPI; 3 or more at RPIs under 2 ms on a busy host)")
        p.add_argument("--print", default="changes", metavar="|".join(PRINT_MODES),
                       help="which input lines to print: " + "; ".join(f"{mode}: {what}" for mode, what in
                                                                       PRINT_MODES.items())
                            + " (default %(default)s)")
        p.set_defaults(func=cmd_io)

    if wanted("drive"):
        from .drive import add_drive_commands

        p = sub.add_parser("drive")
        drive = p.add_subparsers(dest="drive_command", metavar="COMMAND", title="commands", required=True,
                                 parser_class=_Parser)

        def where_the_emulator_is(q: argparse.ArgumentParser) -> None:
            q.add_argument("--host", default="127.0.0.1",
                           help="the emulator's address (its --host), which with --port finds its control socket "
                                "(default %(default)s)")
            q.add_argument("--port", type=number("port"), default=DEFAULT_PORT,
                           help="the emulator's EtherNet/IP port, which finds its control socket (default %(default)s)")
            _complete(q.add_argument("--control", type=Path, metavar="PATH", help="the emulator's control socket"),
                      _FILE)
            q.add_argument("--timeout", type=parse_duration, default=5.0, metavar="DURATION",
                           help="reply timeout (default %(default)s s)")
            q.add_argument("--json", action="store_true", help="one JSON object per line")

        add_drive_commands(drive, where_the_emulator_is)

    if wanted("eds"):
        _add_eds_commands(sub)
    if wanted("security"):
        from .security import cmd_security_configure, cmd_security_init

        p = sub.add_parser("security")
        security = p.add_subparsers(dest="security_command", metavar="COMMAND", title="commands", required=True,
                                    parser_class=_Parser)
        q = security.add_parser("init")
        _complete(q.add_argument("folder", type=Path, metavar="DIR", help="the folder to write (made if missing)"),
                  _DIRECTORY)
        q.add_argument("--psk", action="store_true", help="also write a pre-shared key, psk.txt (IDENTITY:HEX)")
        q.add_argument("--psk-only", action="store_true", help="write the pre-shared key and no certificate")
        q.add_argument("--days", type=number("days"), default=825, metavar="N",
                       help="validity of the device's and client's certificates (default %(default)s)")
        q.add_argument("--force", action="store_true", help="replace files already there")
        q.add_argument("--json", action="store_true", help="one JSON object per line")
        q.set_defaults(func=cmd_security_init)
        q = security.add_parser("configure")
        q.add_argument("host", metavar="HOST[:PORT]", help="the device, in factory-default state, on plain EtherNet/IP")
        _complete(q.add_argument("--security", type=Path, metavar="DIR", required=True,
                                 help="the folder of `cipstack security init`: its CA signs the device's request"),
                  _DIRECTORY)
        q.add_argument("--common-name", metavar="NAME", help="the device certificate's common name (default: the "
                                                              "device's product name)")
        q.add_argument("--security-port", type=number("security port"), default=2221, metavar="N",
                       help="TCP port where the device then serves TLS (default %(default)s)")
        q.add_argument("--check-expiration", action="store_true",
                       help="set Check Expiration (0x5E/11): the device refuses expired client certificates")
        q.add_argument("--send-chain", action="store_true",
                       help="set Send Certificate Chain (0x5E/10): the device sends the CA certificate too")
        q.add_argument("--dtls-timeout", type=number("DTLS timeout"), metavar="SECONDS",
                       help="set DTLS Timeout (0x5E/15): the DTLS port's idle timeout (the device's default 12)")
        q.add_argument("--timeout", type=float, default=10.0, metavar="SECONDS",
                       help="per request (default %(default)s)")
        q.add_argument("--json", action="store_true", help="one JSON object")
        q.set_defaults(func=cmd_security_configure)
    if wanted("capture"):
        from ..capture.command import add_arguments as add_capture_arguments

        add_capture_arguments(sub)
    if wanted("completion"):
        from .completion import cmd_completion

        p = sub.add_parser("completion")
        p.add_argument("shell", choices=["bash", "zsh"], help="the shell")
        p.set_defaults(func=cmd_completion)
    if wanted("conform"):
        from .conform import add_arguments as add_conform_arguments

        p = sub.add_parser("conform")
        add_conform_arguments(p)
        for action in p._actions:
            if action.dest in ("eds", "junit", "html"):
                _complete(action, _FILE)
    return parser


def _add_http_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--http", metavar="HOST:PORT",
                   help="also serve the HTTP control API (docs/http.md) on this loopback address and port")
    p.add_argument("--http-token", metavar="TOKEN",
                   help="every HTTP request must carry Authorization: Bearer TOKEN (visible to every local user "
                        "in the process list: prefer --http-token-file or CIPSTACK_HTTP_TOKEN)")
    _complete(p.add_argument("--http-token-file", type=Path, metavar="FILE",
                             help="read the HTTP token from the first line of FILE (keep it mode 0600)"), _FILE)
    p.add_argument("--http-allow-remote", action="store_true",
                   help="let the HTTP API listen on and serve other than loopback (needs a token of 32 characters or "
                        "more that nobody can guess: openssl rand -hex 32)")
    p.add_argument("--http-allow-host", action="append", default=[], metavar="NAME",
                   help="a host name the HTTP API answers to besides its address and localhost (a request "
                        "naming another is refused: DNS rebinding); repeatable")


def _add_eds_commands(sub: Any) -> None:
    from ..eds.commands import add_check_arguments, add_show_arguments
    from ..eds.commands_generate import add_generate_arguments
    from .eds import cmd_eds_check, cmd_eds_fetch, cmd_eds_generate, cmd_eds_show

    p = sub.add_parser("eds")
    eds = p.add_subparsers(dest="eds_command", metavar="COMMAND", title="commands", required=True,
                           parser_class=_Parser)
    q = eds.add_parser("check")
    add_check_arguments(q)
    q.add_argument("--against", metavar="HOST[:PORT]",
                   help="also compare the file with a live device: [Device] with its Identity, every linked ParamN "
                        "with its attribute, every AssemN with its size, every class 1 ConnectionN opened and closed")
    q.add_argument("--timeout", type=parse_duration, default=5.0, metavar="DURATION",
                   help="reply timeout with --against (default %(default)s s)")
    q.add_argument("--target-io-port", type=lambda t: parse_number(t, "target io port"), metavar="N",
                   help="with --against: the device's class 1 UDP port (default: the port its Forward_Open reply "
                        "names, else 2222)")
    q.add_argument("--no-connections", action="store_true",
                   help="with --against: open no class 1 connection (read only)")
    _complete(q.add_argument("--security", type=Path, metavar="DIR",
                             help="with --against, CIP Security: read over TLS (TCP 2221 unless HOST names a port) "
                                  "and open each class 1 connection over DTLS (UDP, the same port), with the CA, "
                                  "client certificate and key of DIR (`cipstack security init DIR`)"), _DIRECTORY)
    q.set_defaults(func=cmd_eds_check)
    q = eds.add_parser("generate")
    add_generate_arguments(q)
    q.set_defaults(func=cmd_eds_generate)
    q = eds.add_parser("show")
    add_show_arguments(q)
    q.set_defaults(func=cmd_eds_show)
    q = eds.add_parser("fetch")
    q.add_argument("host", metavar="HOST[:PORT]", help="the device (default port 44818)")
    q.add_argument("-o", "--output", metavar="FILE", required=True, help="where to write the file (- for stdout)")
    q.add_argument("--timeout", type=parse_duration, default=5.0, metavar="DURATION",
                   help="reply timeout (default %(default)s s)")
    _complete(q.add_argument("--security", type=Path, metavar="DIR", help=EXPLICIT_OVER_TLS), _DIRECTORY)
    q.set_defaults(func=cmd_eds_fetch)
