"""The emulator commands: adapter (a profile or an EDS), componet, models."""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import sys
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from ..errors import BadRequest, NotFound
from .common import (
    EXIT_FAILURE,
    EXIT_OK,
    EXIT_USAGE,
    UsageError,
    _emit,
)


# -- adapter -----------------------------------------------------------------------------------------
def cmd_adapter(args: argparse.Namespace) -> int:
    from ..adapter import Adapter, AdapterSettings
    from ..devices.profiles import DEFAULT_PROFILE, PROFILES, check_model
    from ..devices.state import StateFileError, default_state_path
    from ..eds.served import profile_eds_files

    if args.eds is not None:
        return _adapter_from_eds(args)
    if args.profile is None:
        args.profile = _profile_of_model(args.model) if args.model else DEFAULT_PROFILE
    if args.profile not in PROFILES:
        raise UsageError(f"unknown profile {args.profile!r} (known: {', '.join(sorted(PROFILES))})")
    try:
        check_model(PROFILES[args.profile], args.model)
    except BadRequest as exc:
        raise UsageError(str(exc)) from None
    if not 0 <= args.port < 65536:
        raise UsageError(f"port {args.port} out of range")
    default_state = default_state_path(f"{args.profile}-{args.model}" if args.model else args.profile)
    if args.factory and args.state is not None:
        raise UsageError("--factory reads and writes no state file: drop --state FILE")
    if args.state is None and not args.factory:
        # One file per profile and model: another model's saved parameters are not this one's.
        args.state = default_state
    settings = AdapterSettings(host=args.host, port=args.port, profile=args.profile, model=args.model,
                               max_sessions=args.max_sessions, max_connections=args.max_connections,
                               io_port=args.io_port, control_path=args.control,
                               status_lines=not args.quiet, state_path=args.state, modbus_port=args.modbus_port,
                               rtu=args.rtu, files=profile_eds_files(args.profile, args.model),
                               **_limit_settings(args), **_http_settings(args), **_security_settings(args))
    try:
        adapter = Adapter(settings)
    except (StateFileError, ValueError, KeyError) as exc:
        raise UsageError(str(exc)) from None
    log = logging.getLogger("cipstack.adapter")

    def started() -> None:
        # Said once it serves (after any one-line refusal of a bad argument, never before one).
        if args.factory:   # the user's saved drive stays as it is: this run's saves live in memory
            log.info("factory settings: saves last until the emulator stops; %s is not read or written", default_state)
        else:
            log.info("saved parameters in %s (--factory starts without them)", args.state)

    if args.param_unsaved and not args.param:
        raise UsageError("--param-unsaved goes with --param CODE=VALUE")
    if args.param:
        _apply_keypad_parameters(adapter, args.param, kept=not args.param_unsaved)
    return _serve(adapter, args, "adapter", started)


def _apply_keypad_parameters(adapter: Any, assignments: list[str], kept: bool = True) -> None:
    """``--param CODE=VALUE``: keypad parameters set before the network connects (the device's keypad):
    keypad entries a power-cycle keeps, or with ``--param-unsaved`` written as over communication."""
    try:
        applied = adapter.apply_keypad_parameters(assignments, kept)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for line in applied:
        logging.getLogger("cipstack.adapter").info("keypad parameter %s", line)


def _profile_of_model(name: str) -> str:
    """The profile of ``--model`` given without ``--profile``: the family the model belongs to."""
    from ..devices.profiles import profile_of_model

    try:
        return profile_of_model(name).name
    except NotFound as exc:
        raise UsageError(f"--model: {exc}") from None


def _security_settings(args: argparse.Namespace) -> dict[str, Any]:
    """CIP Security: ``--security DIR`` serves EtherNet/IP over TLS too, on ``--security-port``; without
    it the device starts in factory default and serves TLS there once configured over the network."""
    settings: dict[str, Any] = {"security_objects": not getattr(args, "no_security_objects", False)}
    timeout = getattr(args, "security_config_timeout", None)
    if timeout is not None:
        if timeout <= 0:
            raise UsageError(f"--security-config-timeout {timeout:g}: must be more than 0")
        settings["security_config_timeout"] = timeout
    if getattr(args, "secure_only", False):
        settings["secure_only"] = True
    if args.security_port is not None:
        if not 0 <= args.security_port < 65536:
            raise UsageError(f"--security-port {args.security_port} out of range")
        settings["security_port"] = args.security_port
    if args.security is not None:
        settings["security"] = args.security
    return settings


def _limit_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The adapter's limits beyond sessions and class 3 connections, checked with those two (a
    connection limit may be 0: that transport class refused; every other at least 1)."""
    limits = {"max_sessions_per_host": args.max_sessions_per_host, "max_io_connections": args.max_io_connections,
              "max_tcp_connections": args.max_tcp_connections,
              "max_tcp_connections_per_host": args.max_tcp_connections_per_host}
    frame_timeout = getattr(args, "frame_timeout", None)
    if frame_timeout is not None:
        if frame_timeout <= 0:
            raise UsageError(f"--frame-timeout {frame_timeout:g}: must be more than 0")
        limits["frame_timeout"] = frame_timeout
    checked = (("max_sessions", args.max_sessions), ("max_connections", args.max_connections), *limits.items())
    for name, value in checked:
        minimum = 0 if name in ("max_connections", "max_io_connections") else 1
        if value is not None and value < minimum:
            raise UsageError(f"--{name.replace('_', '-')} {value}: must be at least {minimum}")
    io_gather = getattr(args, "io_gather", None)   # a duration, checked by its parser (not negative)
    if io_gather is not None:
        limits["io_gather"] = io_gather
    return limits


#: Where the HTTP token may come from besides the command line, which every local user can read (ps).
TOKEN_VARIABLE = "CIPSTACK_HTTP_TOKEN"


def _http_token(args: argparse.Namespace) -> tuple[str | None, str]:
    """The HTTP token and where it came from: ``--http-token``, else the first line of
    ``--http-token-file``, else the environment's ``CIPSTACK_HTTP_TOKEN``; one of them only. A file
    that cannot be read, or an empty token, is a usage error naming it."""
    given = [name for name, value in (("--http-token", args.http_token), ("--http-token-file", args.http_token_file))
             if value is not None]
    if len(given) > 1:
        raise UsageError("--http-token or --http-token-file, not both")
    if args.http_token is not None:
        token: str | None = args.http_token
        where = "--http-token"
    elif args.http_token_file is not None:
        try:
            token = args.http_token_file.read_text(encoding="utf-8").splitlines()[0].strip() \
                if args.http_token_file.stat().st_size else ""
        except (OSError, UnicodeDecodeError, IndexError) as exc:
            raise UsageError(f"--http-token-file {args.http_token_file}: {getattr(exc, 'strerror', None) or exc}") \
                from None
        where = f"--http-token-file {args.http_token_file}"
    else:
        token = os.environ.get(TOKEN_VARIABLE)
        where = TOKEN_VARIABLE
    if token is not None and not token.strip():
        raise UsageError(f"{where}: the token is empty")
    return token, where


def _http_settings(args: argparse.Namespace) -> dict[str, Any]:
    """``--http HOST:PORT`` (with its token, ``--http-allow-remote``, ``--http-allow-host``), checked
    before anything listens."""
    if args.http is None:
        if args.http_token is not None or args.http_token_file is not None or args.http_allow_remote \
                or args.http_allow_host:
            raise UsageError("--http-token, --http-token-file, --http-allow-remote and --http-allow-host go with "
                             "--http HOST:PORT")
        return {}
    args.http_token, where = _http_token(args)
    if args.http_allow_remote and args.http_token is not None:
        # Refused before anything listens, naming where the token came from (a Secret's file, say).
        from ..control.tokens import weak_token_reason

        reason = weak_token_reason(args.http_token)
        if reason is not None:
            raise UsageError(f"{where}: {reason}")
    try:
        from ..control.http import HttpApiError, check_settings
    except ImportError:
        raise UsageError("--http needs aiohttp: python3 -m pip install 'cipstack[http]'") from None
    try:
        check_settings(args.http, args.http_token, args.http_allow_remote)
    except HttpApiError as exc:
        raise UsageError(str(exc)) from None
    return {"http": args.http, "http_token": args.http_token, "http_allow_remote": args.http_allow_remote,
            "http_hosts": tuple(args.http_allow_host)}


def _serve(adapter: Any, args: argparse.Namespace, command: str, started: Callable[[], None] | None = None) -> int:
    """Run an emulator until SIGINT/SIGTERM; a port it cannot listen on (taken, or not an address of
    this machine) is one line naming the port and its option, and exit 2. ``started`` runs once it
    serves (after its ``emulating`` line)."""
    from ..eip.io_server import run_precise
    from ..listening import ListenError
    from ..modbus.rtu_line import RtuPortError

    scenario = getattr(args, "scenario", None)
    run_scenario: Callable[[Any], Awaitable[Any]] | None = None
    if scenario is not None:
        from ..control import scenario as scenarios

        try:
            loaded = scenarios.load(scenario)
            loaded.check(adapter.service)
        except scenarios.ScenarioError as exc:
            raise UsageError(str(exc)) from None

        def run_scenario(running: Any) -> Awaitable[Any]:
            return scenarios.run(running.service, loaded, lambda line: print(line, flush=True))

    async def serving(running: Any) -> Any:
        if started is not None:
            started()
        if run_scenario is not None:
            return await run_scenario(running)
        await asyncio.Event().wait()   # no scenario: serve until a signal (this is then cancelled)
        return None

    until = serving if started is not None or run_scenario is not None else None
    try:
        fired = run_precise(adapter.serve_forever(until) if until is not None else adapter.serve_forever())
    except RtuPortError as exc:
        print(f"cipstack {command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ListenError as exc:
        print(f"cipstack {command}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"cipstack {command}: cannot listen on {args.host}:{args.port}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    if scenario is not None and fired is not True:
        return EXIT_FAILURE  # a step did not fire, or a signal ended the scenario first
    return EXIT_OK


def _read_eds_file(path: str) -> Any:
    """The EDS document of ``path``; an unreadable file is a usage error (one line, exit 2)."""
    from ..eds.reader import EdsSyntaxError, read_eds

    try:
        doc = read_eds(path)
    except EdsSyntaxError as exc:
        raise UsageError(f"{path}:{exc.line}: not a readable EDS: {exc.message}") from None
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror or exc}") from None
    for line, what in doc.reader_notes:   # read, but not as the specification writes it
        print(f"{path}:{line}: warning: {what}", file=sys.stderr)
    return doc


def _adapter_from_eds(args: argparse.Namespace) -> int:
    """``cipstack adapter --eds FILE``: the generic device the file describes; each construct it
    cannot serve is one warning line on stderr."""
    from ..adapter import Adapter, AdapterSettings, network_interface
    from ..devices.base import DeviceLimits
    from ..devices.profiles import DEFAULT_MAC
    from ..eds.emulated_device import EdsDeviceError, build_eds_device

    if (args.model is not None or args.state is not None or args.modbus_port is not None or args.param
            or args.param_unsaved or args.rtu is not None):
        raise UsageError("--model, --state, --modbus-port, --rtu and --param belong to --profile, not --eds")
    if not 0 <= args.port < 65536:
        raise UsageError(f"port {args.port} out of range")
    doc = _read_eds_file(args.eds)
    try:
        device = build_eds_device(doc, network_interface(args.host, DEFAULT_MAC),
                                  DeviceLimits(args.max_sessions, args.max_connections),
                                  served=Path(args.eds).read_bytes())
    except EdsDeviceError as exc:
        raise UsageError(f"{args.eds}: {exc}") from None
    for issue in device.issues:
        print(f"cipstack adapter: {args.eds}:{issue.line}: warning: {issue.message}", file=sys.stderr, flush=True)
    settings = AdapterSettings(host=args.host, port=args.port, max_sessions=args.max_sessions,
                               max_connections=args.max_connections, io_port=args.io_port,
                               control_path=args.control, status_lines=not args.quiet, **_limit_settings(args),
                               **_http_settings(args), **_security_settings(args))
    adapter = Adapter(settings, device=device)
    return _serve(adapter, args, "adapter")




def cmd_models(args: argparse.Namespace) -> int:
    """Every model of every family installed, with the distribution that brought it (a family of one model
    is one line); a family whose plug-in cannot be used is a line on stderr and exit status 1."""
    from ..devices.profiles import PROFILES

    for name, profile in PROFILES.items():
        if args.profile and name != args.profile:
            continue
        distribution = PROFILES.distribution(name)
        models = profile.model_info()
        if not models:
            _emit(args, {"profile": name, "model": None, "description": profile.description,
                         "distribution": distribution}, f"{name:3}  {'-':14}  {profile.description}  {distribution}")
        for m in models:
            _emit(args, {"profile": name, "model": m.name, "product_code": m.product_code,
                         "product_name": m.product_name, "eds_file": m.eds_file, "distribution": distribution},
                  f"{name:3}  {m.name:14}  product code {m.product_code:5}  {m.product_name:32}  "
                  f"{m.eds_file or '-':36}  {distribution}")
    problems = PROFILES.problems
    for problem in problems.values():
        print(f"cipstack models: {problem}", file=sys.stderr)
    return EXIT_FAILURE if problems else EXIT_OK


def cmd_componet(args: argparse.Namespace) -> int:
    from ..adapter import Adapter, AdapterSettings, network_interface
    from ..devices.profiles import DEFAULT_MAC, componet_gateway, parse_nodes

    try:
        gateway = componet_gateway(parse_nodes(args.nodes), network_interface(args.host, DEFAULT_MAC))
    except (ValueError, KeyError) as exc:
        raise UsageError(str(exc)) from None
    settings = AdapterSettings(host=args.host, port=args.port, io_port=args.io_port, control_path=args.control,
                               status_lines=not args.quiet)
    adapter = Adapter(settings, device=gateway)
    return _serve(adapter, args, "componet")
