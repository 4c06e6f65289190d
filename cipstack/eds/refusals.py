"""What a class 1 connection of an EDS file that the live device did not open says: judged here
once, for ``eds check --against`` and for ``conform --eds`` (group eds), so that one finding has one
severity and one wording in both (``conform`` reports a note as n/a: it neither fails nor warns).

* A Forward_Open refused for its path (0x012A invalid consuming path, 0x012B invalid producing
  path, 0x012F inconsistent path combination) although the device has the connection's assemblies
  is the device's present configuration when it opened another connection of the same kind of the
  file: the ACG-ET2 connects the one pair of assemblies its parameters CM.24 and CM.23 select
  (ACG-ET2 manual, "CIP Input Instance (CM.23)", "CIP Output Instance (CM.24)"), and its file
  declares every pair. A note: the file matches the device. With no connection of that kind
  opened, the device offers none of them, which is worth a warning.
* A listen-only connection needs a connection that produces its input by multicast (CIP Vol. 1,
  Connection Manager: 0x0119 non-listen-only connection not opened); when no connection of the file
  that does so could be opened, the listener is not tried: a note, since each owner's refusal is a
  finding of its own.
* Any other refusal is the device refusing what the file declares: an error.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from ..cip.status import ExtendedStatus, describe_status
from .checker import ERROR, INFO, WARNING
from .generator import LISTEN_ONLY_KIND
from .interpret import ConnectionInfo

#: Forward_Open refusals of a connection path: the device does not offer these points (now).
PATH_REFUSALS = frozenset({ExtendedStatus.INVALID_CONSUMING_PATH, ExtendedStatus.INVALID_PRODUCING_PATH,
                           ExtendedStatus.INCONSISTENT_PATH_COMBINATION})


@dataclass(frozen=True)
class ConnectionVerdict:
    """A severity of ``eds.checker`` (error, warning, info) and what to say, without the connection's
    name (each tool names it its way)."""

    severity: str
    message: str


def data_points(connection: ConnectionInfo) -> set[int]:
    """The connection points that carry data (assemblies the device should have): the output unless
    the O->T is a heartbeat, the input unless the T->O is one."""
    points = set()
    if not connection.heartbeat:
        points.add(connection.o_t_point)
    if not connection.t_o_heartbeat:
        points.add(connection.t_o_point)
    return points


def _named(connection: ConnectionInfo) -> str:
    return f"Connection{connection.number} ({connection.name})"


def refused(connection: ConnectionInfo, general: int, extended: Sequence[int], *, assemblies_exist: bool,
            opened: Iterable[ConnectionInfo]) -> ConnectionVerdict:
    """The device refused ``connection``'s Forward_Open with ``general`` and ``extended`` status;
    ``assemblies_exist``: it has every assembly of ``data_points(connection)``; ``opened``: the
    connections of the same file it opened."""
    status = describe_status(general, extended)
    if not (extended and extended[0] in PATH_REFUSALS and assemblies_exist):
        return ConnectionVerdict(ERROR, f"Forward_Open refused by the device ({status})")
    points = ", ".join(str(p) for p in sorted(data_points(connection)))
    alike = [c for c in opened if c.kind == connection.kind and c.number != connection.number]
    if alike:
        return ConnectionVerdict(INFO, f"not accepted in the device's present configuration, which accepts "
                                       f"{_named(alike[0])}: Forward_Open refused ({status}), assemblies {points} "
                                       "present")
    return ConnectionVerdict(WARNING, f"Forward_Open refused by the device ({status}); the device has assemblies "
                                      f"{points} but does not offer this path now")


def owners_of(listener: ConnectionInfo, connections: Iterable[ConnectionInfo]) -> list[ConnectionInfo]:
    """The connections of the file that produce ``listener``'s input by multicast: what a listen-only
    connection listens to, opened first."""
    return [c for c in connections if c.kind != LISTEN_ONLY_KIND and c.t_o_point == listener.t_o_point
            and c.t_o_multicast]


def unheard(connection: ConnectionInfo, owners: Iterable[tuple[ConnectionInfo, int, Sequence[int]]]
            ) -> ConnectionVerdict:
    """A listen-only ``connection`` that nothing of the file produces by multicast for: ``owners``,
    the connections of the file that produce its input, each with the status that refused it."""
    why = "; ".join(f"Connection{owner.number}: {describe_status(general, extended)}"
                    for owner, general, extended in owners) or "no connection of the file produces it by multicast"
    return ConnectionVerdict(INFO, f"listen only, and nothing produces input {connection.t_o_point} by multicast "
                                   f"for it to listen to ({why}): not opened")


__all__ = ["PATH_REFUSALS", "ConnectionVerdict", "data_points", "owners_of", "refused", "unheard"]
