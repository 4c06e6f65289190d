"""What a fleet is: which device at which address, read from the command line or a TOML file.

A fleet spec names an address pool (``127.0.0.10-127.0.0.73``, or a list of addresses and ranges)
and groups of devices (``acg*32``, ``mx2:MX2-A2015-E*16``, ``acg*4@127.0.0.90``). A group with a
first address takes that many consecutive addresses from it; a group without one takes the next
unused addresses of the pool, in order. Every device gets its own state file in the state
directory, named after its address and its profile (and model), so that a device keeps its saved
parameters across restarts and no two devices share one.

With ``--rtu DEVICE`` (``rtu = "pty"`` in a file) the fleet's drives whose family has an RS-485 port
(the ACG's) also share one line, the Multi-drop Link System of the ACG RS-485 manual: up to 16 drives,
each at its own station ID (CM.1, 1-250). A group may give its first station ID (``station = 10`` in a
file); the others take the lowest free IDs from 1, in address order.

Everything here is checked before anything listens: a bad spec is one ``SpecError`` line.
"""

from __future__ import annotations

import ipaddress
import re
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import BadRequest, NotFound

if TYPE_CHECKING:
    from ..devices.profiles import SerialLink

#: Devices in one fleet unless ``--max-devices`` (``max_devices`` in a file) says more: a default, so
#: that a typo (127.0.0.0-127.255.255.255) is one line rather than a machine's every descriptor. What a
#: machine can really hold is its open-file limit's (``cipstack.fleet.serve.check_open_files``).
MAX_DEVICES = 1024

_GROUP = re.compile(r"^(?P<kind>[^*@]+?)(?:\*(?P<count>[^@]*))?(?:@(?P<first>.*))?$")


class SpecError(BadRequest):
    """A fleet spec that cannot be served as written; the message is one line naming the problem."""


@dataclass(frozen=True)
class DeviceGroup:
    """``count`` devices of one profile (and model), from ``first`` or from the pool."""

    profile: str
    model: str | None = None
    count: int = 1
    first: ipaddress.IPv4Address | None = None
    params: tuple[str, ...] = ()
    #: How the user wrote it, for error messages.
    text: str = ""
    #: First RS-485 station ID of the group's drives on the fleet's RTU line (None: the next free).
    station: int | None = None

    @property
    def label(self) -> str:
        return f"{self.profile}-{self.model}" if self.model else self.profile


@dataclass(frozen=True)
class FleetDevice:
    """One device of a fleet: what ``cipstack adapter --host ADDRESS --profile ... --state ...`` runs."""

    address: str
    profile: str
    model: str | None = None
    params: tuple[str, ...] = ()
    state_path: Path | None = None
    #: Its station ID on the fleet's RS-485 line (None: not on it).
    station: int | None = None


@dataclass(frozen=True)
class FleetSecurity:
    """CIP Security of every device of a fleet: what ``cipstack adapter --security FOLDER
    --security-port PORT`` serves, at each device's own address: TLS on TCP ``port`` and DTLS on
    UDP ``port``, with the certificate and key of ``folder`` (one certificate for every device: an
    originator checks the chain, not a host name)."""

    folder: Path
    port: int = 2221


@dataclass
class FleetSpec:
    devices: list[FleetDevice]
    port: int
    io_port: int
    workers: int = 1
    state_dir: Path | None = None
    #: The RS-485 line the ACG drives share: "pty" or a serial device (None: none).
    rtu: str | None = None
    #: Which shard of the plant this fleet serves (``--shard INDEX/COUNT``), or None: all of it.
    shard: Shard | None = None
    #: TLS and DTLS at every device (``--security DIR``), or None: plain EtherNet/IP only.
    security: FleetSecurity | None = None


# -- addresses ------------------------------------------------------------------------------------------
def _address(text: str, where: str) -> ipaddress.IPv4Address:
    try:
        return ipaddress.IPv4Address(text.strip())
    except ValueError:
        raise SpecError(f"{where}: {text.strip()!r} is not an IPv4 address") from None


def parse_addresses(text: str | Sequence[str], where: str = "--addresses",
                    limit: int = MAX_DEVICES) -> list[ipaddress.IPv4Address]:
    """``127.0.0.10-127.0.0.73``, ``127.0.0.10,127.0.0.12``, or a mix; in the order given, each once;
    more than ``limit`` is refused."""
    items = [text] if isinstance(text, str) else list(text)
    found: list[ipaddress.IPv4Address] = []
    seen: set[ipaddress.IPv4Address] = set()
    for item in items:
        if not isinstance(item, str):
            raise SpecError(f"{where}: {item!r} is not an address or a range (text)")
        for part in item.split(","):
            if not part.strip():
                raise SpecError(f"{where}: an empty item in {item!r}")
            low_text, dash, high_text = part.partition("-")
            low = _address(low_text, where)
            high = _address(high_text, where) if dash else low
            if high < low:
                raise SpecError(f"{where}: the range {part.strip()} ends before it starts")
            if int(high) - int(low) + 1 + len(found) > limit:
                raise SpecError(f"{where}: more than {limit} addresses (a fleet serves at most {limit} devices; "
                                f"--max-devices N for more)")
            for number in range(int(low), int(high) + 1):
                address = ipaddress.IPv4Address(number)
                if address in seen:
                    raise SpecError(f"{where}: {address} is given twice")
                seen.add(address)
                found.append(address)
    return found


def describe_addresses(addresses: Iterable[str | ipaddress.IPv4Address]) -> str:
    """Addresses as ranges where they run on: ``127.0.0.10-127.0.0.41,127.0.0.50``."""
    numbers = [int(ipaddress.IPv4Address(a)) for a in addresses]
    runs: list[list[int]] = []
    for number in numbers:
        if runs and number == runs[-1][1] + 1:
            runs[-1][1] = number
        else:
            runs.append([number, number])
    v4 = ipaddress.IPv4Address
    return ",".join(str(v4(a)) if a == b else f"{v4(a)}-{v4(b)}" for a, b in runs)


# -- device groups --------------------------------------------------------------------------------------
def _count(value: Any, where: str, limit: int) -> int:
    if isinstance(value, str):
        try:
            value = int(value.strip(), 0)
        except ValueError:
            raise SpecError(f"{where}: the count {value!r} is not a number") from None
    if isinstance(value, bool) or not isinstance(value, int):
        raise SpecError(f"{where}: the count {value!r} is not a number")
    if not 1 <= value <= limit:
        raise SpecError(f"{where}: the count {value} is not in 1..{limit} (--max-devices N for more)")
    return value


def make_group(profile: str | None, model: str | None, count: Any, first: str | None, params: Sequence[str],
               where: str, station: Any = None, limit: int = MAX_DEVICES) -> DeviceGroup:
    """A group checked against the profiles and models this cipstack emulates."""
    from ..devices.profiles import PROFILES, profile_of_model

    if profile is None and model is None:
        raise SpecError(f"{where}: no profile")
    if profile is not None and profile not in PROFILES:
        raise SpecError(f"{where}: unknown profile {profile!r} (known: {', '.join(sorted(PROFILES))})")
    if profile is not None and model is not None and PROFILES[profile].find_model is None:
        raise SpecError(f"{where}: profile {profile} has one model; give no model")
    if model is not None:
        try:
            family = profile_of_model(model).name
        except NotFound:
            raise SpecError(f"{where}: unknown model {model!r} (`cipstack models` lists them)") from None
        if profile is not None and profile != family:
            raise SpecError(f"{where}: {model} is an {family} model, not {profile}")
        profile = family
    assert profile is not None
    chosen = PROFILES[profile]
    link = chosen.serial_link
    if params:
        if chosen.keypad is None:
            raise SpecError(f"{where}: parameters (--param, params) are a keypad's, and profile {profile} has none")
        codes = chosen.keypad()
        for text in params:
            try:
                register, _ = codes.parse(text)
            except (ValueError, LookupError) as exc:
                raise SpecError(f"{where}: {exc}") from None
            if link is not None and register.code == link.station_code:
                raise SpecError(f"{where}: {link.station_code} (the station ID) is given by the fleet's RTU line: "
                                "use station = N")
    if station is not None:
        if link is None:
            on_a_line = [p for p in PROFILES.values() if p.serial_link is not None]
            raise SpecError(f"{where}: a station ID is " + " or ".join(
                f"{p.serial_link.port} (profile {p.name})" for p in on_a_line if p.serial_link is not None))
        if isinstance(station, bool) or not isinstance(station, int) or not 1 <= station <= link.max_station:
            raise SpecError(f"{where}: station {station!r} is not a station ID (1..{link.max_station}, "
                            f"{link.station_code})")
    return DeviceGroup(profile, model, _count(count, where, limit), _address(first, where) if first else None,
                       tuple(params), where, station)


def parse_group(text: str, limit: int = MAX_DEVICES) -> DeviceGroup:
    """``--device PROFILE[:MODEL][*COUNT][@FIRST]``, or ``MODEL[*COUNT][@FIRST]``."""
    from ..devices.profiles import PROFILES, profile_of_model

    where = f"--device {text}"
    match = _GROUP.match(text.strip())
    if match is None:
        raise SpecError(f"{where}: not PROFILE[:MODEL][*COUNT][@FIRST] (e.g. acg*32, mx2:MX2-A2015-E*16)")
    kind, count, first = match.group("kind"), match.group("count"), match.group("first")
    profile, colon, model = kind.partition(":")
    if not colon and profile not in PROFILES:
        try:
            profile_of_model(profile)       # whichever family has it (its declaration's find_model)
        except NotFound:
            raise SpecError(f"{where}: unknown profile {profile!r} (known: {', '.join(sorted(PROFILES))}; "
                            f"or a model `cipstack models` lists)") from None
        profile, model = "", profile          # a model alone names its family
    if (colon and not model) or (count is not None and not count.strip()) or (first is not None and not first.strip()):
        raise SpecError(f"{where}: not PROFILE[:MODEL][*COUNT][@FIRST] (e.g. acg*32, mx2:MX2-A2015-E*16)")
    return make_group(profile or None, model or None, count if count is not None else 1, first, (), where,
                      limit=limit)


# -- assigning addresses ---------------------------------------------------------------------------------
def state_file(state_dir: Path, address: str, group: DeviceGroup) -> Path:
    """The state file of the device at ``address``: one per address, profile and model."""
    return state_dir / f"{address}-{group.label}.json"


def assign(groups: Sequence[DeviceGroup], pool: Sequence[ipaddress.IPv4Address] | None,
           state_dir: Path | None, limit: int = MAX_DEVICES) -> list[FleetDevice]:
    """The devices of ``groups``, each at its address, in address order: the groups with a first
    address take theirs, then the others the pool's unused addresses in order."""
    if not groups:
        raise SpecError("no device: give --device PROFILE*COUNT (e.g. acg*16) or a spec file")
    taken: dict[ipaddress.IPv4Address, DeviceGroup] = {}
    for group in groups:
        if group.first is None:
            continue
        if int(group.first) + group.count - 1 > int(ipaddress.IPv4Address("255.255.255.255")):
            raise SpecError(f"{group.text}: {group.count} addresses from {group.first} run past 255.255.255.255")
        for address in (group.first + n for n in range(group.count)):
            if address in taken:
                raise SpecError(f"{group.text}: {address} is already given to {taken[address].text}")
            taken[address] = group
    free = iter([a for a in (pool or []) if a not in taken])
    for group in groups:
        if group.first is not None:
            continue
        if pool is None:
            raise SpecError(f"{group.text}: no address: give --addresses (e.g. 127.0.0.10-127.0.0.73) or a "
                            f"first address (acg*16@127.0.0.10)")
        mine = [a for _, a in zip(range(group.count), free, strict=False)]
        if len(mine) < group.count:
            raise SpecError(f"{group.text}: {group.count} devices, but the addresses {describe_addresses(pool)} "
                            f"have {len(mine)} left for them")
        taken.update((a, group) for a in mine)
    if len(taken) > limit:
        raise SpecError(f"{len(taken)} devices: a fleet serves at most {limit} (--max-devices N for more)")
    devices = []
    placed: dict[int, int] = {}    # id(group) -> its devices so far
    for address, group in sorted(taken.items()):
        index = placed.get(id(group), 0)
        placed[id(group)] = index + 1
        station = None if group.station is None else group.station + index
        link = _serial_link(group.profile)
        if station is not None and link is not None and station > link.max_station:
            raise SpecError(f"{group.text}: {group.count} station IDs from {group.station} run past "
                            f"{link.max_station}")
        devices.append(FleetDevice(str(address), group.profile, group.model, group.params,
                                   state_file(state_dir, str(address), group) if state_dir else None, station))
    return devices


def _serial_link(profile: str) -> SerialLink | None:
    from ..devices.profiles import PROFILES

    return PROFILES[profile].serial_link


def assign_stations(devices: Sequence[FleetDevice], workers: int, where: str = "--rtu") -> list[FleetDevice]:
    """The devices whose family has an RS-485 port (``Profile.serial_link``: the ACG's) on one line, each
    at its station ID (CM.1 on the ACG, set at start): a group's drives from its ``station`` on
    (``assign``), the others at the lowest free IDs from 1, in address order."""
    from ..devices.profiles import PROFILES

    links = {d.address: link for d in devices if (link := _serial_link(d.profile)) is not None}
    if not links:
        ports = [f"{p.serial_link.port}: profile {p.name}" for p in PROFILES.values() if p.serial_link is not None]
        raise SpecError(f"{where}: the fleet has no device with an RS-485 port (" + "; ".join(ports) + ")")
    drives = [d for d in devices if d.address in links]
    link = min(links.values(), key=lambda each: each.max_drives)
    if len(drives) > link.max_drives:
        raise SpecError(f"{where}: {len(drives)} {link.drives}, but an RS-485 line takes at most {link.max_drives} "
                        f"({link.source})")
    if workers != 1:
        raise SpecError(f"{where}: one RS-485 line is served by one process: --workers 1")
    owner: dict[int, str] = {}
    for device in drives:
        if device.station is not None:
            if device.station in owner:
                raise SpecError(f"{where}: station {device.station} is given to {owner[device.station]} and "
                                f"{device.address}")
            owner[device.station] = device.address
    free = (n for n in range(1, min(each.max_station for each in links.values()) + 1) if n not in owner)
    result = []
    for device in devices:
        on_line = links.get(device.address)
        if on_line is not None:
            station = device.station if device.station is not None else next(free)
            device = replace(device, params=(*device.params, f"{on_line.station_code}={station}"), station=station)
        result.append(device)
    return result


def check_port(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < 65536:
        raise SpecError(f"{where}: {value!r} is not a port number (0..65535)")
    return value


def check_max_devices(value: Any, where: str = "--max-devices") -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise SpecError(f"{where}: {value!r} is not a number of devices (1 or more)")
    return value


def check_workers(workers: Any, devices: int, where: str = "--workers") -> int:
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise SpecError(f"{where}: {workers!r} is not a number of processes (1 or more)")
    if workers > devices:
        raise SpecError(f"{where} {workers}: more worker processes than the fleet's {devices} device(s)")
    return workers


# -- shards of a plant -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Shard:
    """One of ``count`` parts of a plant spec: ``index`` counts from 0, as a StatefulSet's pod ordinals do."""

    index: int
    count: int

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"


def parse_shard(text: str, where: str = "--shard") -> Shard:
    """``INDEX/COUNT``: ``0/3`` is the first of three shards."""
    index_text, slash, count_text = text.strip().partition("/")
    try:
        index, count = int(index_text), int(count_text)
    except ValueError:
        raise SpecError(f"{where} {text!r}: not INDEX/COUNT (e.g. 0/3, the first of three)") from None
    if not slash or count < 1 or not 0 <= index < count:
        raise SpecError(f"{where} {text!r}: not INDEX/COUNT with 0 <= INDEX < COUNT (e.g. 0/3, the first of three)")
    return Shard(index, count)


def shares(devices: Sequence[FleetDevice], parts: int) -> list[list[FleetDevice]]:
    """``devices`` in ``parts`` contiguous shares whose sizes differ by one at most."""
    size, extra = divmod(len(devices), parts)
    result, start = [], 0
    for index in range(parts):
        end = start + size + (1 if index < extra else 0)
        result.append(list(devices[start:end]))
        start = end
    return result


def select_shard(devices: Sequence[FleetDevice], shard: Shard, where: str = "--shard") -> list[FleetDevice]:
    """The devices of ``shard``: the plant's devices in address order cut as ``shares`` cuts them, so that
    every shard of one spec is the same wherever it is computed, and together they are the plant once."""
    if shard.count > len(devices):
        raise SpecError(f"{where} {shard}: more shards than the plant's {len(devices)} device(s)")
    return shares(devices, shard.count)[shard.index]


# -- the TOML file ---------------------------------------------------------------------------------------
_FILE_KEYS = {"addresses", "port", "io_port", "workers", "state_dir", "device", "rtu", "max_devices", "security",
              "security_port"}
_GROUP_KEYS = {"profile", "model", "count", "first", "params", "station"}


def _load_toml(path: Path) -> dict[str, Any]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10 reads TOML with the tomli package (a dependency there)
        try:
            import tomli as tomllib
        except ImportError:
            raise SpecError(f"{path}: reading a TOML spec on Python 3.10 needs the tomli package") from None
    try:
        with open(path, "rb") as file:
            return tomllib.load(file)
    except OSError as exc:
        raise SpecError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: not valid TOML: {' '.join(str(exc).split())}") from None


def _params(value: Any, where: str) -> list[str]:
    """``params = ["drv=4", "Frq=8"]`` or ``params = {drv = 4, Frq = 8}``."""
    if isinstance(value, dict):
        return [f"{code}={v}" for code, v in value.items()]
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return list(value)
    raise SpecError(f"{where}: params is a list of \"CODE=VALUE\" or a table of CODE = VALUE")


def read_spec_file(path: Path, limit: int | None = None) -> tuple[dict[str, Any], list[DeviceGroup]]:
    """The file's settings (``addresses``, ``port``, ``io_port``, ``workers``, ``state_dir``,
    ``max_devices``, ``security``, ``security_port``) and its ``[[device]]`` groups. A relative
    ``state_dir`` or ``security`` is relative to the file's directory; ``limit`` (``--max-devices``)
    wins over the file's ``max_devices``."""
    document = _load_toml(path)
    if limit is None:
        limit = check_max_devices(document.get("max_devices", MAX_DEVICES), f"{path}: max_devices")
    unknown = sorted(set(document) - _FILE_KEYS)
    if unknown:
        raise SpecError(f"{path}: unknown key {unknown[0]!r} (known: {', '.join(sorted(_FILE_KEYS))})")
    settings = {k: v for k, v in document.items() if k != "device"}
    if "rtu" in settings and not isinstance(settings["rtu"], str):
        raise SpecError(f"{path}: rtu is \"pty\" or a serial device (text)")
    if "state_dir" in settings:
        if not isinstance(settings["state_dir"], str):
            raise SpecError(f"{path}: state_dir is a directory name (text)")
        settings["state_dir"] = path.parent / settings["state_dir"]
    if "security" in settings:
        if not isinstance(settings["security"], str):
            raise SpecError(f"{path}: security is the folder of `cipstack security init` (text)")
        settings["security"] = path.parent / settings["security"]
    entries = document.get("device", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise SpecError(f"{path}: devices are [[device]] tables")
    groups = []
    for index, entry in enumerate(entries, start=1):
        where = f"{path}: device {index}"
        unknown = sorted(set(entry) - _GROUP_KEYS)
        if unknown:
            raise SpecError(f"{where}: unknown key {unknown[0]!r} (known: {', '.join(sorted(_GROUP_KEYS))})")
        for key in ("profile", "model", "first"):
            if key in entry and not isinstance(entry[key], str):
                raise SpecError(f"{where}: {key} is text")
        groups.append(make_group(entry.get("profile"), entry.get("model"), entry.get("count", 1), entry.get("first"),
                                 _params(entry.get("params", []), where), where, entry.get("station"), limit))
    return settings, groups


__all__ = ["MAX_DEVICES", "DeviceGroup", "FleetDevice", "FleetSecurity", "FleetSpec", "Shard", "SpecError",
           "assign", "assign_stations", "check_max_devices", "check_port", "check_workers", "describe_addresses",
           "make_group", "parse_addresses", "parse_group", "parse_shard", "read_spec_file", "select_shard", "shares"]
