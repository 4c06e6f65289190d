"""Where the battery finds the target's class 1 connection points when no EDS is given, and which
source it used. In order, the first that gives a point-to-point exclusive owner wins:

1. ``--connection-points O,T[,C]``: named outright.
2. The device's own EDS file, read from its File object (class 0x37, instance 0xC8), as EtherNet/IP
   devices that carry their EDS serve it. It also enables group ``eds``, whatever its connections.
3. An EDS file of ``--eds-dir DIR`` whose ``[Device]`` names the target's vendor, product code and
   major revision (the minor revision too, when a file matches it).
4. The AC drive profile (Identity device type 2, or 0x13 for a DC drive): the output assemblies
   21, 20, 23, 22 with the inputs 71, 70, 73, 72, the extended forms first.
5. Probing the Assembly object: the class's highest instance and instance count (class attributes
   2 and 3), the sizes (attribute 4) of instances ``PROBED_INSTANCES`` up to that highest one (until
   as many as the class counts are found), then Forward_Opens of output/input candidates with each
   configuration instance the device may have (``configuration_candidates``: 1, the instance after
   the output, the others); at most ``MAX_PROBE_OPENS``.

Probing stays within these bounds: a few hundred Get_Attribute_Single requests and a few dozen
Forward_Opens, each opened connection closed at once.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..cip.epath import request_path
from ..eip.io_core import SEQUENCE_COUNT_SIZE
from ..errors import BadRequest
from .connections import Endpoint, Plan, forward_open_request, plans_of_eds, send_forward_open
from .registry import Context
from .wire import Probe

if TYPE_CHECKING:
    from ..eds.model import EdsDocument

#: Assembly instances probed for a size: the profile's, and the vendor-specific range 100-199.
PROBED_INSTANCES = (*range(1, 9), 20, 21, 22, 23, 70, 71, 72, 73, *range(100, 200))
#: At most this many Forward_Opens while probing pairs of assemblies.
MAX_PROBE_OPENS = 24
#: The AC drive profile's output and input assemblies, the extended forms first.
PROFILE_OUTPUTS = (21, 20, 23, 22)
PROFILE_INPUTS = (71, 70, 73, 72)
DRIVE_DEVICE_TYPES = (0x02, 0x13)
CONFIG_INSTANCE = 1
RPI_US = 10_000
#: The largest EDS file read from a device.
MAX_EDS_BYTES = 4 * 1024 * 1024


@dataclass
class Found:
    """What the discovery found: the source in words, the plans, and an EDS to check the device with."""

    source: str
    plans: list[Plan] = field(default_factory=list)
    eds: EdsDocument | None = None
    eds_source: str = ""
    tried: list[str] = field(default_factory=list)


def _plan(name: str, output: int, input: int, output_size: int, input_size: int, config: int = CONFIG_INSTANCE
          ) -> Plan:
    """An exclusive owner with a run/idle header O->T and modeless T->O, as the profile and most devices do."""
    return Plan(name, config, output, input, SEQUENCE_COUNT_SIZE + 4 + output_size, SEQUENCE_COUNT_SIZE + input_size,
                RPI_US, None, False, True, True)


def assembly_size(probe: Probe, instance: int) -> int | None:
    """An Assembly instance's data size: attribute 4, else the length of attribute 3; None if it is not there."""
    reply = probe.request(0x0E, request_path(0x04, instance, 4))
    if reply.status == 0 and len(reply.data) == 2:
        return int(struct.unpack("<H", reply.data)[0])
    if reply.status in (0x05, 0x16):
        return None
    data = probe.request(0x0E, request_path(0x04, instance, 3))
    return len(data.data) if data.status == 0 else None


def parse_points(text: str) -> tuple[int, int, int]:
    """``O,T[,C]`` (decimal or 0x hex) -> (output, input, configuration); ``ValueError`` names the problem."""
    parts = [p.strip() for p in text.split(",")]
    if len(parts) not in (2, 3) or not all(parts):
        raise BadRequest(f"{text!r}: give O,T or O,T,C (output point, input point, configuration instance)")
    try:
        numbers = [int(p, 0) for p in parts]
    except ValueError:
        raise BadRequest(f"{text!r}: the points are numbers (decimal or 0x hex)") from None
    if not all(1 <= n <= 0xFFFF for n in numbers):
        raise BadRequest(f"{text!r}: a connection point is 1-65535")
    return numbers[0], numbers[1], numbers[2] if len(numbers) == 3 else CONFIG_INSTANCE


def _named(ctx: Context, probe: Probe, points: tuple[int, int, int]) -> Found:
    output, input, config = points
    sizes = (assembly_size(probe, output), assembly_size(probe, input))
    found = Found(f"--connection-points {output},{input},{config}")
    if None not in sizes:
        found.plans = [_plan(f"points {output}/{input}", output, input, sizes[0] or 0, sizes[1] or 0, config)]
    else:
        found.tried.append(f"--connection-points: assembly {output if sizes[0] is None else input} has no size")
    return found


def _device_eds(ctx: Context, probe: Probe) -> tuple[EdsDocument | None, str]:
    from ..eds.reader import EdsSyntaxError, decode_eds, parse_eds
    from ..objects.file import CLASS_ID, EDS_INSTANCE, FileTransferError, read_file

    def request(service: int, data: bytes) -> tuple[int, bytes]:
        reply = probe.request(service, request_path(CLASS_ID, EDS_INSTANCE), data)
        return (0x100 if reply.status is None else reply.status), reply.data

    try:
        return parse_eds(decode_eds(read_file(request))), ""
    except (FileTransferError, EdsSyntaxError) as exc:
        return None, str(exc)


def _matching_eds(directory: str | os.PathLike[str], identity: dict[str, object] | None
                  ) -> tuple[EdsDocument | None, str]:
    """The EDS of ``directory`` for the target's vendor, product code and major revision (its minor
    revision preferred)."""
    from ..eds.reader import EdsSyntaxError, read_eds

    if not identity:
        return None, "no identity to match"
    revision = identity.get("revision") or {}
    wanted = (identity.get("vendor_id"), identity.get("product_code"),
              revision.get("major") if isinstance(revision, dict) else None)
    minor = revision.get("minor") if isinstance(revision, dict) else None
    best: tuple[int, Path, EdsDocument] | None = None
    for path in sorted(Path(directory).glob("*.[eE][dD][sS]")):
        try:
            doc = read_eds(path)
        except (OSError, EdsSyntaxError, UnicodeError):
            continue
        values = [doc.entry("Device", key) for key in ("VendCode", "ProdCode", "MajRev", "MinRev")]
        numbers = [v.value() if v is not None else None for v in values]
        if tuple(numbers[:3]) != wanted:
            continue
        score = 1 if numbers[3] == minor else 0
        if best is None or score > best[0]:
            best = (score, path, doc)
    if best is None:
        return None, f"no file of {directory} names vendor {wanted[0]}, product code {wanted[1]}, revision {wanted[2]}"
    return best[2], str(best[1])


def _open_closes(ctx: Context, probe: Probe, endpoint: Endpoint, plan: Plan) -> tuple[bool, int | None]:
    """Whether the target accepts ``plan`` (closed at once), and the extended status when it refuses."""
    reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is not None:
        opened.close()
        return True, None
    return False, reply.extended if reply.status == 0x01 else None


def profile_pair(ctx: Context, probe: Probe, endpoint: Endpoint, outputs: tuple[int, ...] = PROFILE_OUTPUTS,
                 inputs: tuple[int, ...] = PROFILE_INPUTS) -> list[Plan]:
    """The first pair of ``outputs`` x ``inputs`` (in order) that opens as an exclusive owner (closed at once)."""
    sizes = {i: assembly_size(probe, i) for i in (*outputs, *inputs)}
    for output in outputs:
        for input in inputs:
            out_size, in_size = sizes[output], sizes[input]
            if out_size is None or in_size is None:
                continue
            plan = _plan(f"profile {output}/{input}", output, input, out_size, in_size)
            if _open_closes(ctx, probe, endpoint, plan)[0]:
                return [plan]
    return []


def assembly_class(probe: Probe) -> tuple[int | None, int | None]:
    """The Assembly class's highest instance and number of instances (class attributes 2 and 3, CIP
    Vol. 1 §4-4.1): by Get_Attributes_All of instance 0, else Get_Attribute_Single of each; None
    where the device does not say."""
    every = probe.request(0x01, request_path(0x04, 0))
    if every.status == 0 and len(every.data) >= 6:
        _, highest, count = struct.unpack_from("<3H", every.data)
        return highest, count
    values: list[int | None] = []
    for attribute in (2, 3):
        reply = probe.request(0x0E, request_path(0x04, 0, attribute))
        values.append(int(struct.unpack("<H", reply.data)[0]) if reply.status == 0 and len(reply.data) == 2
                      else None)
    return values[0], values[1]


def assembly_sizes(probe: Probe) -> tuple[dict[int, int], str]:
    """Every Assembly instance found and its data size (0: a data-less instance, such as a heartbeat
    or a configuration point without data), and what was probed, in words."""
    highest, count = assembly_class(probe)
    instances = [i for i in PROBED_INSTANCES if highest is None or i <= highest]
    if highest is not None and highest not in instances:
        instances.append(highest)  # the highest instance exists, wherever it is
    sizes: dict[int, int] = {}
    for instance in instances:
        size = assembly_size(probe, instance)
        if size is not None:
            sizes[instance] = size
        if count is not None and len(sizes) >= count:
            break  # the class says there are no more
    said = "" if highest is None else f", up to the class's highest, {highest}"
    return sizes, f"instances 1-8, 20-23, 70-73, 100-199{said}: {len(sizes)} found"


def configuration_candidates(sizes: dict[int, int], output: int) -> list[int]:
    """The configuration instances to try with ``output``, in order: 1, the one most devices take;
    the instance right after the output, where OpENer's sample application and the layouts that
    follow it put it (output 150, configuration 151); then the other instances the device has, those
    with data first (a configuration assembly carries the configuration), then the data-less ones
    (a configuration point without data)."""
    others = sorted((i for i in sizes if i not in (CONFIG_INSTANCE, output + 1)), key=lambda i: (sizes[i] == 0, i))
    return [CONFIG_INSTANCE, *([output + 1] if output + 1 in sizes else []), *others]


#: Refusals that say the configuration instance is wrong whatever the points (CIP Vol. 1 Table
#: 3-5.33): invalid segment in the connection path (OpENer's answer for a configuration instance it
#: lacks), invalid configuration application path.
CONFIG_REFUSED = (0x0315, 0x0129)
#: Refusals another configuration instance may answer otherwise: an inconsistent application path
#: combination (OpENer's for points it has but does not configure together), an invalid configuration
#: size.
CONFIG_SUSPECT = (0x012F, 0x0126)


def _probed(ctx: Context, probe: Probe, endpoint: Endpoint, sizes: dict[int, int]) -> list[Plan]:
    inputs = [i for i, size in sizes.items() if size]
    # The outputs followed by an instance (their configuration, by the convention above) first.
    outputs = sorted(inputs, key=lambda i: (i + 1 not in sizes, i))
    ruled_out: set[int] = set()  # configuration instances refused whatever the points
    opens = 0
    for output in list(outputs):
        for input in list(inputs):
            if output == input or output not in outputs:
                continue
            for config in configuration_candidates(sizes, output):
                if config in (output, input) or config in ruled_out:
                    continue
                if opens >= MAX_PROBE_OPENS:
                    return []
                opens += 1
                plan = _plan(f"probed {output}/{input}/{config}", output, input, sizes[output], sizes[input], config)
                ok, extended = _open_closes(ctx, probe, endpoint, plan)
                if ok:
                    return [plan]
                # The refusal says which part is wrong: no more Forward_Opens for it.
                if extended in CONFIG_REFUSED:
                    ruled_out.add(config)
                    continue
                if extended in (0x012A, 0x0127):
                    outputs.remove(output)
                    break
                if extended in (0x012B, 0x0128):
                    if input in inputs:
                        inputs.remove(input)
                    break
                if extended not in CONFIG_SUSPECT:
                    break  # not about the configuration: the next pair
            if output not in outputs:
                break
    return []


def discover(ctx: Context, points: tuple[int, int, int] | None = None,
             eds_dir: str | os.PathLike[str] | None = None) -> Found:
    """Find the target's connection points from the sources in order (module docstring)."""
    from ..eds.interpret import read_view

    probe = ctx.probe()
    if points is not None:
        return _named(ctx, probe, points)
    found = Found("none")
    doc, why = _device_eds(ctx, probe)
    if doc is not None:
        found.eds, found.eds_source = doc, "the device's own EDS file (File object 0x37, instance 0xC8)"
        found.plans = plans_of_eds(doc, read_view(doc))
        if any(p.exclusive_owner and not p.multicast for p in found.plans):
            found.source = found.eds_source
            return found
        found.tried.append("the device's EDS file declares no point-to-point exclusive owner")
    else:
        found.tried.append(f"no EDS file from the device ({why})")
    if eds_dir is not None:
        matched, where = _matching_eds(eds_dir, ctx.identity)
        if matched is not None:
            candidates = plans_of_eds(matched, read_view(matched))
            if any(p.exclusive_owner and not p.multicast for p in candidates):
                found.source, found.plans = f"{where} (--eds-dir)", candidates
                if found.eds is None:
                    found.eds, found.eds_source = matched, found.source
                return found
            found.tried.append(f"{where} declares no point-to-point exclusive owner")
        else:
            found.tried.append(where)
    endpoint = Endpoint(ctx, probe)
    device_type = (ctx.identity or {}).get("device_type")
    if device_type in DRIVE_DEVICE_TYPES:
        profile = profile_pair(ctx, probe, endpoint)
        if profile:
            found.source, found.plans = "the AC drive profile (assemblies 20-23 and 70-73)", profile
            return found
        found.tried.append("no profile assembly pair opens")
    sizes, probed_what = assembly_sizes(probe)
    probed = _probed(ctx, probe, endpoint, sizes)
    if probed:
        plan = probed[0]
        found.source, found.plans = (f"probing the Assembly object ({probed_what}; {plan.ot_point}/{plan.to_point}, "
                                     f"configuration {plan.config} opens)"), probed
        return found
    found.tried.append(f"no probed assembly pair opens ({probed_what})")
    found.plans = []
    return found
