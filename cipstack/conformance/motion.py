"""Group ``profile``, the drive's motion (only with ``--allow-motion``: these checks run the motor).

For a device of type AC (or DC) drive, over a class 1 exclusive owner of output assembly 21 or 20
and input 71 or 70 (the first pair that opens, extended forms first, as the discovery finds the
profile's points): run forward and see Running1 then AtReference; stop and see it stop; fault reset
on a 0->1 edge only; NetCtl/NetRef hand run/stop and the reference to the network and back; and the
drive does not run on idle data (run/idle header bit 0).

Bounds, all measured from the command on the wire to the first T->O packet showing its effect:

* running and at reference within the drive's acceleration time (AC/DC Drive 0x2A attribute 18
  AccelTime, ms x 2^TimeScale (attribute 28), measured from 0 to the high speed limit, so it bounds
  any lower reference), else ``UNKNOWN_RAMP_S``; plus ``MARGIN_S``;
* stopped (Running1 0) within the deceleration time (attribute 19 DecelTime), likewise;
* a fault forced (Control Supervisor attribute 17 ForceFault) shows, and a FaultRst edge clears it,
  within ``FAULT_S``; a FaultRst held at 1 is watched for ``HOLD_S``; a hand-over of NetCtl/NetRef
  shows within ``HANDOVER_S``; idle data is sent for ``IDLE_S``.

Whatever happens (a check failing, raising, the target stopping to answer) each check ends with the
drive stopped, NetCtl/NetRef and the speed reference as found and its connection closed
(``MotionLink.release``); what cannot be restored is noted for the final self-check.
"""

from __future__ import annotations

import contextlib
import select
import struct
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import TypeVar

from ..cip.epath import request_path
from ..eip.io_core import SEQUENCE_COUNT_SIZE, IoDatagramError, decode_io_datagram
from .connections import Endpoint, Opened, Plan, forward_open_request, send_forward_open
from .discovery import profile_pair
from .model import Behaviour, CheckSpec, Exchange, Outcome, Verdict
from .ot_producer import OutputProducer
from .profile import PROFILE, clear_fault_of_the_run, not_a_drive  # and the static checks register before these
from .registry import GET_ATTRIBUTE_SINGLE, SET_ATTRIBUTE_SINGLE, Context, check, outcome
from .wire import Probe, TargetUnreachable

#: The speed reference the checks run at: 300 rpm on a drive in rpm, 3.00 Hz on one in 0.01 Hz (the MX2
#: and RX without motor poles set, CompoNet manual Table B-1): a low speed on either.
SPEED_REFERENCE = 300
#: Added to every bound the drive gives (its ramp times): the network's and the check's own latency.
MARGIN_S = 1.0
#: The ramp time assumed where the drive has no AccelTime / DecelTime attribute (the ACG serves its
#: times only in vendor attributes, ACG-ET2 manual, AC/DC Drive object).
UNKNOWN_RAMP_S = 30.0
#: Added to twice the deceleration time when a check ends: how long the drive is given to stop before
#: Run1 is cleared by explicit messaging and the run noted as leaving it running.
RELEASE_S = 5.0
FAULT_S = 1.0
HOLD_S = 0.5
HANDOVER_S = 1.0
IDLE_S = 1.0
#: How long a level is sent before the next step (the drive sees it, and a later 0->1 is an edge).
SETTLE_S = 0.3
#: The outputs and inputs tried, extended forms first (20/21/70/71 only: their bits are the profile's).
MOTION_OUTPUTS, MOTION_INPUTS = (21, 20), (71, 70)

# Output 20/21 byte 0 (ACG-ET2 manual, output instances 20/21; CompoNet manual, Tables B-1 to B-4).
RUN_FWD, FAULT_RST, NET_CTL, NET_REF = 0x01, 0x04, 0x20, 0x40
# Input 70/71 byte 0 (ACG-ET2 manual, input instances 70/71; CompoNet manual, Tables B-5 to B-8).
FAULTED, RUNNING1, READY, CTRL_FROM_NET, REF_FROM_NET, AT_REFERENCE = 0x01, 0x04, 0x10, 0x20, 0x40, 0x80
CONTROL_SUPERVISOR, AC_DC_DRIVE = 0x29, 0x2A
#: The attributes input 70 lacks, read by Get_Attribute_Single instead: name -> (class, attribute).
READ_BY_GET = {"ready": (CONTROL_SUPERVISOR, 9), "ctrl_from_net": (CONTROL_SUPERVISOR, 15),
               "ref_from_net": (AC_DC_DRIVE, 29), "at_reference": (AC_DC_DRIVE, 3)}
#: What each check restores, read before it runs: NetCtrl (0x29/5), NetRef (0x2A/4), SpeedRef (0x2A/8).
AS_FOUND = {"NetCtrl": (CONTROL_SUPERVISOR, 5), "NetRef": (AC_DC_DRIVE, 4), "SpeedRef": (AC_DC_DRIVE, 8)}
FORCE_FAULT = (CONTROL_SUPERVISOR, 17)
T = TypeVar("T")

IDLE_REFERENCE = "CIP Vol. 1 §3-6.1 (32-bit run/idle header: the data of an idle packet is not applied)"
MOTION = f"{PROFILE}: Control Supervisor state machine and run/stop event matrix"
CITED = ("ACG-ET2 manual, Control Supervisor object (Drive Run table, Drive Fault Reset) and output instances "
         "20/21; CompoNet manual, Tables B-1 to B-8 and D-4")
RUN_STATES = ("Control Supervisor attributes 6 State and 7 Running1 (Enabled and Run1, or Stopping and still "
              "Running1); ACG-ET2 manual, Control Supervisor object (Drive Run table); CompoNet manual, Tables B-5 to "
              "B-8 and D-4")
FAULT_RESET = ("ACG-ET2 manual, Control Supervisor object, Drive Fault Reset (a reset only when the value changes "
               "from 0 to 1; 1 over 1 does not reset); CompoNet manual, Tables B-1 to B-4 (RST: reset on a 0 to 1 "
               "transition) and Table D-4 (Force Fault 0x11: a fault on the rising edge)")


@dataclass(frozen=True)
class Status:
    """What input 70/71 (and, for 70, the attributes it lacks) says of the drive; None: not known."""

    faulted: bool
    running: bool
    ready: bool | None
    ctrl_from_net: bool | None
    ref_from_net: bool | None
    at_reference: bool | None
    speed: int

    def describe(self) -> str:
        flags = [name for name, value in (("Faulted", self.faulted), ("Running1", self.running),
                                          ("Ready", self.ready), ("CtrlFromNet", self.ctrl_from_net),
                                          ("RefFromNet", self.ref_from_net), ("AtReference", self.at_reference))
                 if value]
        return f"{' '.join(flags) or 'no flag set'}, SpeedActual {self.speed}"


class MotionLink:
    """A class 1 exclusive owner of the drive: O->T sent at the granted API with the data a step asks
    for, T->O read into ``Status``."""

    def __init__(self, ctx: Context, plan: Plan, probe: Probe, endpoint: Endpoint, opened: Opened) -> None:
        self.ctx, self.plan, self.probe, self.endpoint, self.opened = ctx, plan, probe, endpoint, opened
        header = 4 if plan.run_idle else 0
        self.size = plan.ot_size - SEQUENCE_COUNT_SIZE - header
        self.producer = OutputProducer(endpoint.sock, (ctx.host, opened.io_port), opened.reply.ot_connection_id,
                                       max(opened.reply.ot_api_us, 1000) / 1e6, plan.run_idle)
        self.received_example: bytes | None = None
        self.last: Status | None = None
        self._gets: dict[str, bool | None] = {}
        self._got_at = 0.0
        #: The bits of byte 0 this check holds while it is not commanding anything else.
        self.control = NET_CTL | NET_REF if plan.ot_point == 21 else 0
        self.force_fault_used = False
        #: The drive was not faulted when the check began: a fault it has at the end is the check's.
        self.fault_free = False
        self.as_found: dict[str, bytes] = {}

    @property
    def extended(self) -> bool:
        return self.plan.ot_point == 21

    def data(self, bits: int, speed: int) -> bytes:
        if not self.extended:
            bits &= ~(NET_CTL | NET_REF)  # output 20 has no NetCtl/NetRef bits
        return (bytes((bits, 0)) + struct.pack("<h", speed)).ljust(self.size, b"\0")[:self.size]

    def _status(self, payload: bytes) -> Status:
        flags = payload[0] if payload else 0
        speed = struct.unpack_from("<h", payload, 2)[0] if len(payload) >= 4 else 0
        if self.plan.to_point == 71:
            return Status(bool(flags & FAULTED), bool(flags & RUNNING1), bool(flags & READY),
                          bool(flags & CTRL_FROM_NET), bool(flags & REF_FROM_NET), bool(flags & AT_REFERENCE), speed)
        now = time.monotonic()
        if now - self._got_at >= 0.1:  # input 70: the other flags read at most every 100 ms
            self._got_at = now
            self._gets = {name: self.read_flag(*where) for name, where in READ_BY_GET.items()}
        return Status(bool(flags & FAULTED), bool(flags & RUNNING1), self._gets.get("ready"),
                      self._gets.get("ctrl_from_net"), self._gets.get("ref_from_net"), self._gets.get("at_reference"),
                      speed)

    def read(self, class_id: int, attribute: int) -> bytes | None:
        reply = self.probe.request(GET_ATTRIBUTE_SINGLE, request_path(class_id, 1, attribute))
        return reply.data if reply.status == 0 else None

    def read_flag(self, class_id: int, attribute: int) -> bool | None:
        data = self.read(class_id, attribute)
        return None if not data else bool(data[0])

    def write(self, class_id: int, attribute: int, value: bytes) -> str | None:
        """Set_Attribute_Single; the problem in words, or None."""
        reply = self.probe.request(SET_ATTRIBUTE_SINGLE, request_path(class_id, 1, attribute), value)
        return None if reply.status == 0 else f"Set of {class_id:#04x}/1/{attribute}: {reply.describe()}"

    def send(self, bits: int, speed: int, seconds: float, until: Callable[[Status], bool] | None = None,
             run: bool = True) -> tuple[float | None, list[Status]]:
        """Send ``bits``/``speed`` (idle: ``run`` False) for at most ``seconds``; return how long it took
        until a T->O packet showed ``until`` (None: never, or no ``until``) and every status seen."""
        self.producer.command(self.data(bits, speed), run)
        start = time.monotonic()
        end = start + seconds
        seen: list[Status] = []
        sock = self.endpoint.sock
        while (now := time.monotonic()) < end:
            ready, _, _ = select.select([sock], [], [], end - now)
            if not ready:
                continue
            raw = sock.recv(65536)
            try:
                datagram_in = decode_io_datagram(raw)
            except IoDatagramError:
                continue
            if datagram_in.connection_id != self.opened.reply.to_connection_id:
                continue
            self.received_example = self.received_example or raw
            status = self._status(datagram_in.payload)
            seen.append(status)
            self.last = status
            if until is not None and until(status):
                return time.monotonic() - start, seen
        return None, seen

    def hold(self, bits: int, seconds: float, run: bool = True, speed: int = SPEED_REFERENCE) -> list[Status]:
        return self.send(bits, speed, seconds, run=run)[1]

    def ramp_time(self, attribute: int) -> tuple[float, str]:
        """AccelTime (18) or DecelTime (19) in seconds, and where the value came from."""
        name = "AccelTime" if attribute == 18 else "DecelTime"
        data = self.read(AC_DC_DRIVE, attribute)
        if data is None or len(data) != 2:
            return UNKNOWN_RAMP_S, f"no {name} (0x2A/1/{attribute}): {UNKNOWN_RAMP_S:g} s assumed"
        scale_data = self.read(AC_DC_DRIVE, 28)
        scale = struct.unpack("<b", scale_data[:1])[0] if scale_data else 0
        seconds = struct.unpack("<H", data)[0] * 2.0 ** scale / 1000
        return seconds, f"{name} {seconds:g} s (0x2A/1/{attribute})"

    def take_control(self) -> Status | str:
        """Hold the control bits (run command 0, the speed reference set) for ``SETTLE_S``: the drive's
        status, or why the motion cannot be checked from the network."""
        _, seen = self.send(self.control, SPEED_REFERENCE, HANDOVER_S,
                            until=lambda s: s.ctrl_from_net is not False and s.ref_from_net is not False)
        seen += self.hold(self.control, SETTLE_S)
        if not seen:
            return f"no T->O packet from input {self.plan.to_point} in {HANDOVER_S + SETTLE_S:g} s"
        status = seen[-1]
        if status.faulted:
            code = self.read(CONTROL_SUPERVISOR, 13)
            return (f"the drive is faulted (FaultCode {code.hex(' ') if code else 'unreadable'}): clear its fault "
                    "first")
        self.fault_free = True
        if status.running:
            return "the drive is running: the motion checks start from a stopped drive"
        if status.ctrl_from_net is False or status.ref_from_net is False:
            how = "with NetCtl and NetRef 1" if self.extended else "(output 20 has no NetCtl/NetRef bits)"
            return (f"the run command or the reference does not come from the network {how} "
                    f"(CtrlFromNet {int(bool(status.ctrl_from_net))}, RefFromNet {int(bool(status.ref_from_net))}): "
                    "the drive takes them from a local source (the ACG's are set on its keypad, drv = 4 Field Bus "
                    "and Frq = 8 give them to the network; ACG-ET2 manual, output instance 21 note 2)")
        return status

    def exchanges(self) -> list[Exchange]:
        return [*self.probe.exchanges, Exchange(self.producer.first or b"", self.received_example, "udp")]

    def release(self) -> None:
        """Stop the drive, reset a fault this check caused, give NetCtl/NetRef and the speed reference
        back as found, close the connection, and check by explicit messaging; what is left is noted
        for the final self-check."""
        ctx = self.ctx
        found_bits = (NET_CTL if self.as_found.get("NetCtrl", b"\0")[:1] == b"\1" else 0) | (
            NET_REF if self.as_found.get("NetRef", b"\0")[:1] == b"\1" else 0)
        found_speed = struct.unpack("<h", self.as_found["SpeedRef"][:2])[0] if len(
            self.as_found.get("SpeedRef", b"")) >= 2 else 0
        try:
            with contextlib.suppress(OSError, TargetUnreachable):  # the explicit part below notes what is left
                decel, _ = self.ramp_time(19)
                self.send(self.control, SPEED_REFERENCE, 2 * decel + RELEASE_S, until=lambda s: not s.running)
                if self.force_fault_used:
                    self.write(*FORCE_FAULT, b"\0")
                if self.fault_free and self.last is not None and self.last.faulted:
                    self.hold(self.control, SETTLE_S)
                    self.send(self.control | FAULT_RST, SPEED_REFERENCE, FAULT_S, until=lambda s: not s.faulted)
                if self.extended and found_bits != self.control:
                    self.hold(self.control, SETTLE_S)
                    # NetCtl/NetRef handed back: once the input shows both sources as found, the drive has
                    # applied the packet that carries them and the speed reference; a drive whose sources are
                    # set locally shows no change, and is given the whole SETTLE_S.
                    ctrl, ref = bool(found_bits & NET_CTL), bool(found_bits & NET_REF)
                    self.send(found_bits, found_speed, SETTLE_S,
                              until=lambda s: s.ctrl_from_net is ctrl and s.ref_from_net is ref)
                else:
                    # The bits held are the bits found (output 20 has no NetCtl/NetRef): one level, and the
                    # speed reference as found, for SETTLE_S.
                    self.hold(found_bits, SETTLE_S, speed=found_speed)
        finally:
            self.producer.stop()  # whatever went wrong above: nothing is sent once the check is over
        self.opened.close()
        try:
            self._check_by_explicit_messaging()
        except (TargetUnreachable, OSError) as exc:
            ctx.left_behind.append(f"the drive could not be checked after a motion check: {exc}")

    def _check_by_explicit_messaging(self) -> None:
        """After the connection: a drive still running gets Run1 = 0, a source not as found is written back."""
        ctx = self.ctx
        running = self.read_flag(CONTROL_SUPERVISOR, 7)
        if running:
            # The connection could not stop it: Run1 0 by explicit messaging (the event matrix's stop).
            problem = self.write(CONTROL_SUPERVISOR, 3, b"\0")
            ctx.left_behind.append("the drive was still running after a motion check: Run1 (0x29/1/3) set to 0"
                                   + (f", which failed: {problem}" if problem else ""))
        for name, where in AS_FOUND.items():
            found = self.as_found.get(name)
            if found is None:
                continue
            now = self.read(*where)
            if now is not None and now != found:
                problem = self.write(*where, found)
                if problem is not None:
                    ctx.left_behind.append(f"{name} {now.hex(' ')}, found {found.hex(' ')}: {problem}")


def _motion_plan(ctx: Context) -> Plan | None:
    """The first output 21/20 x input 71/70 exclusive owner that opens (found once per run)."""
    if "motion.plan" not in ctx.cache:
        probe = ctx.probe()
        found = profile_pair(ctx, probe, Endpoint(ctx, probe), MOTION_OUTPUTS, MOTION_INPUTS)
        ctx.cache["motion.plan"] = replace(found[0], name=f"output {found[0].ot_point} / input "
                                           f"{found[0].to_point}") if found else None
    plan: Plan | None = ctx.cache["motion.plan"]
    return plan


@contextlib.contextmanager
def motion_link(ctx: Context, spec: CheckSpec) -> Iterator[MotionLink | Outcome]:
    """A ``MotionLink`` with the drive under network control, released whatever happens; or the outcome
    of a check that cannot run (not allowed, not a drive, no connection, no control from the network)."""
    # A device that is no drive (its device type, from the identity the run began with: nothing more is
    # asked of it) has no motor: the check does not apply, with or without the option. For a drive, the
    # option first, as for --allow-writes: without it nothing about the motor is asked of the device.
    skipped = not_a_drive(ctx, spec)
    if skipped is not None:
        yield skipped
        return
    if not ctx.allow_motion:
        yield outcome(spec, Verdict.NOT_RUN, "needs --allow-motion (this check runs the motor)")
        return
    plan = _motion_plan(ctx)
    if plan is None:
        yield outcome(spec, Verdict.NOT_APPLICABLE, "no class 1 exclusive owner of output 21 or 20 and input 71 or "
                      "70 opens")
        return
    probe = ctx.probe()
    # A fault an earlier group caused (a class 1 timeout) is cleared; one the drive had is its own.
    clear_fault_of_the_run(ctx, probe)
    endpoint = Endpoint(ctx, probe)
    as_found = {}
    for name, (class_id, attribute) in AS_FOUND.items():
        read = probe.request(GET_ATTRIBUTE_SINGLE, request_path(class_id, 1, attribute))
        if read.status == 0:
            as_found[name] = read.data
    reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is None:
        yield outcome(spec, False, f"Forward_Open of {plan.name}: {reply.describe()}", probe.exchanges)
        return
    link = MotionLink(ctx, plan, probe, endpoint, opened)
    link.as_found = as_found
    try:
        yield link
    finally:
        link.release()


def _motion(body: Callable[[Context, CheckSpec, MotionLink, Status], T]) -> Callable[[Context, CheckSpec], T | Outcome]:
    """Run ``body`` on a ``motion_link`` whose drive is stopped, not faulted and under network control."""

    def run(ctx: Context, spec: CheckSpec) -> T | Outcome:
        with motion_link(ctx, spec) as link:
            if isinstance(link, Outcome):
                return link
            status = link.take_control()
            if isinstance(status, str):
                return outcome(spec, Verdict.NOT_APPLICABLE, status, link.exchanges())
            return body(ctx, spec, link, status)

    run.__name__ = body.__name__
    run.__doc__ = body.__doc__
    return run


@dataclass
class Cycle:
    """One run forward and stop, judged by two checks."""

    accel: float = 0.0
    accel_source: str = ""
    decel: float = 0.0
    decel_source: str = ""
    running_after: float | None = None
    at_reference_after: float | None = None
    stopped_after: float | None = None
    last: str = ""
    exchanges: list[Exchange] = field(default_factory=list)


def _cycle(ctx: Context, spec: CheckSpec) -> Cycle | Outcome:
    """Run forward at ``SPEED_REFERENCE`` until at reference, then stop (shared by two checks)."""
    if "motion.cycle" not in ctx.cache:
        ctx.cache["motion.cycle"] = _motion(_run_and_stop)(ctx, spec)
    cached = ctx.cache["motion.cycle"]
    if isinstance(cached, Outcome):
        return outcome(spec, cached.verdict, cached.observed, cached.exchanges)
    return cached  # type: ignore[no-any-return]  # the cache holds any check's results; this key, a Cycle


def _run_and_stop(ctx: Context, spec: CheckSpec, link: MotionLink, status: Status) -> Cycle:
    cycle = Cycle()
    cycle.accel, cycle.accel_source = link.ramp_time(18)
    cycle.decel, cycle.decel_source = link.ramp_time(19)
    bound = cycle.accel + MARGIN_S
    start = time.monotonic()
    command = link.control | RUN_FWD
    cycle.running_after, _ = link.send(command, SPEED_REFERENCE, bound, until=lambda s: s.running)
    if cycle.running_after is not None:
        reached, _ = link.send(command, SPEED_REFERENCE, max(0.0, start + bound - time.monotonic()),
                               until=lambda s: bool(s.at_reference))
        cycle.at_reference_after = None if reached is None else time.monotonic() - start
        cycle.stopped_after, _ = link.send(link.control, SPEED_REFERENCE, cycle.decel + MARGIN_S,
                                           until=lambda s: not s.running)
    cycle.last = link.last.describe() if link.last else "no T->O packet"
    cycle.exchanges = link.exchanges()
    return cycle


@check("profile.motion.run_forward", "run forward by the output assembly: Running1, then AtReference",
       "with RunFwd 0->1 and a speed reference of 300 (NetCtl and NetRef 1 on output 21), the input shows Running1 "
       "and then AtReference (input 71 bit 7, else 0x2A/1/3) within the drive's AccelTime (0x2A/1/18, or 30 s where "
       "it has none) + 1 s", f"{MOTION}; {CITED}",
       behaviours=[Behaviour("runs", "Running1 once the run command is taken (Enabled), AtReference once the ramp "
                             "reaches the reference, both within AccelTime + 1 s",
                             f"{RUN_STATES}; AC/DC Drive attribute 3 AtReference (CompoNet manual, Table D-7)")])
def run_forward(ctx: Context, spec: CheckSpec) -> Outcome:
    cycle = _cycle(ctx, spec)
    if isinstance(cycle, Outcome):
        return cycle
    bound = cycle.accel + MARGIN_S
    if cycle.running_after is None:
        return outcome(spec, False, f"no Running1 within {bound:g} s ({cycle.accel_source}); last: {cycle.last}",
                       cycle.exchanges)
    ok = cycle.at_reference_after is not None
    reached = f"AtReference after {cycle.at_reference_after:.2f} s" if ok else f"no AtReference within {bound:g} s"
    return outcome(spec, ok, (f"{spec.permits('runs').name}: " if ok else "") + f"Running1 after "
                   f"{cycle.running_after:.2f} s, {reached} ({cycle.accel_source})", cycle.exchanges)


@check("profile.motion.stop", "stop by the output assembly: Running1 clears",
       "with RunFwd 1->0 the drive stops: Running1 clears within the drive's DecelTime (0x2A/1/19, or 30 s where "
       "it has none) + 1 s (it may stay set while Stopping, as the state machine says)", f"{MOTION}; {CITED}",
       behaviours=[Behaviour("stops", "Running1 stays set while Stopping and clears once stopped (Ready), within "
                             "DecelTime + 1 s", RUN_STATES)])
def stop(ctx: Context, spec: CheckSpec) -> Outcome:
    cycle = _cycle(ctx, spec)
    if isinstance(cycle, Outcome):
        return cycle
    if cycle.running_after is None:
        return outcome(spec, Verdict.NOT_APPLICABLE, "the drive did not run (profile.motion.run_forward)",
                       cycle.exchanges)
    bound = cycle.decel + MARGIN_S
    if cycle.stopped_after is None:
        return outcome(spec, False, f"still Running1 {bound:g} s after the stop ({cycle.decel_source}); last: "
                       f"{cycle.last}", cycle.exchanges)
    return outcome(spec, True, f"{spec.permits('stops').name}: Running1 clear {cycle.stopped_after:.2f} s after "
                   f"RunFwd 1->0 ({cycle.decel_source})", cycle.exchanges)


@check("profile.motion.fault_reset", "FaultRst resets on a 0->1 edge only",
       "where the drive offers ForceFault (0x29/1/17, a rising edge forces a fault): a forced fault shows Faulted "
       "within 1 s, a FaultRst 0->1 clears it within 1 s, and a FaultRst held at 1 does not clear a fault forced "
       "meanwhile (0.5 s watched); else a FaultRst 0->1 with no fault leaves the drive Ready and not Faulted",
       f"{MOTION}; {FAULT_RESET}",
       behaviours=[Behaviour("edge resets", "a fault forced by ForceFault 0->1 shows Faulted; FaultRst 0->1 clears it "
                             "(State out of Faulted); FaultRst held at 1 does not clear the next one", FAULT_RESET),
                   Behaviour("no fault to reset", "no way through CIP to fault the drive (no ForceFault): FaultRst "
                             "0->1, then held at 1, leaves it Ready and not Faulted",
                             "ACG-ET2 manual, Control Supervisor object (no Force Fault attribute; Drive Fault "
                             "Reset)")])
@_motion
def fault_reset(ctx: Context, spec: CheckSpec, link: MotionLink, status: Status) -> Outcome:
    control = link.control
    if link.read(*FORCE_FAULT) is None:
        seen = link.hold(control | FAULT_RST, HOLD_S)
        seen += link.hold(control, SETTLE_S)
        if not seen:
            return outcome(spec, False, "no T->O packet while FaultRst went 0->1 and was held", link.exchanges())
        bad = [s for s in seen if s.faulted or s.ready is False or s.running]
        return outcome(spec, not bad, (f"with no fault, FaultRst 0->1 then held at 1: {bad[0].describe()}" if bad else
                                       f"{spec.permits('no fault to reset').name}: FaultRst 0->1 then held at 1, "
                                       "Ready and not Faulted throughout"), link.exchanges())
    problems: list[str] = []

    def force(holding: int) -> float | None:
        """ForceFault 0 -> 1 (then 0 again) with byte 0 ``control | holding``: how long until Faulted."""
        link.force_fault_used = True
        for value in (b"\0", b"\1"):
            problem = link.write(*FORCE_FAULT, value)
            if problem is not None:
                problems.append(problem)
                return None
        took, _ = link.send(control | holding, SPEED_REFERENCE, FAULT_S, until=lambda s: s.faulted)
        link.write(*FORCE_FAULT, b"\0")
        return took

    if force(0) is None:
        problems.append(f"ForceFault 0->1: no Faulted within {FAULT_S:g} s")
    else:
        link.hold(control, SETTLE_S)
        cleared, _ = link.send(control | FAULT_RST, SPEED_REFERENCE, FAULT_S, until=lambda s: not s.faulted)
        if cleared is None:
            problems.append(f"FaultRst 0->1: still Faulted after {FAULT_S:g} s")
        else:
            # FaultRst stays 1 from here: a fault forced now must stay.
            if force(FAULT_RST) is None:
                problems.append("ForceFault with FaultRst held at 1: no Faulted")
            else:
                held = link.hold(control | FAULT_RST, HOLD_S)
                if not held:
                    problems.append(f"no T->O packet in the {HOLD_S:g} s FaultRst was held at 1")
                elif not all(s.faulted for s in held):
                    problems.append("FaultRst held at 1 reset the fault again (a level, not a 0->1 edge)")
    if not problems:
        link.hold(control, SETTLE_S)
        if link.send(control | FAULT_RST, SPEED_REFERENCE, FAULT_S, until=lambda s: not s.faulted)[0] is None:
            problems.append("the second FaultRst 0->1 did not reset")
    return outcome(spec, not problems, "; ".join(problems) or f"{spec.permits('edge resets').name}: a forced fault "
                   "is reset by a FaultRst 0->1 edge and not by FaultRst held at 1", link.exchanges())


NET_CTRL_REFERENCE = ("CompoNet manual, Tables B-3/B-4 and D-4 (Net Ctrl, Ctrl From Net) and D-7 (Net Ref, Ref From "
                      "Net)")


def _source(spec: CheckSpec, before: bool | None, on: bool | None, after: bool | None) -> str | None:
    """Which declared behaviour a source flag showed for its request bit 0 -> 1 -> 0, or None."""
    if (before, on, after) == (False, True, False):
        return spec.permits("follows").name
    if before is not None and before == on == after:
        return f"{spec.permits('set locally').name} at {int(before)}"
    return None


@check("profile.motion.net_ctrl", "NetCtl/NetRef hand run/stop and the reference to the network and back",
       "output 21's NetCtl (bit 5) and NetRef (bit 6) going 0 -> 1 -> 0 are seen in CtrlFromNet and RefFromNet "
       "(input 71 bits 5 and 6, else 0x29/1/15 and 0x2A/1/29) within 1 s each; a drive whose sources are set "
       "locally reports them unchanged (ACG-ET2 manual, output instance 21 note 2); with CtrlFromNet 0 a network "
       "RunFwd 0->1 does not run the drive (0.5 s watched)", f"{MOTION}; {NET_CTRL_REFERENCE}; ACG-ET2 manual, "
       "output instance 21",
       behaviours=[Behaviour("follows", "CtrlFromNet and RefFromNet follow NetCtl and NetRef within 1 s",
                             NET_CTRL_REFERENCE),
                   Behaviour("set locally", "the drive's run and reference sources are set locally (its keypad): "
                             "CtrlFromNet and RefFromNet stay as they are, whatever NetCtl and NetRef say",
                             "ACG-ET2 manual, output instance 21 note 2"),
                   Behaviour("ignores the network run", "with CtrlFromNet 0 a network RunFwd 0->1 does not run the "
                             "drive", f"{RUN_STATES}; Run and Stop count only with CtrlFromNet 1")])
def net_ctrl(ctx: Context, spec: CheckSpec) -> Outcome:
    if ctx.allow_motion and (plan := _motion_plan(ctx)) is not None and plan.ot_point != 21:
        return outcome(spec, Verdict.NOT_APPLICABLE, f"{plan.name}: output 20 has no NetCtl/NetRef bits")
    with motion_link(ctx, spec) as link:
        if isinstance(link, Outcome):
            return link
        link.control = 0
        before = link.hold(0, SETTLE_S)
        on = link.send(NET_CTL | NET_REF, SPEED_REFERENCE, HANDOVER_S,
                       until=lambda s: bool(s.ctrl_from_net and s.ref_from_net))[1]
        off = link.send(0, SPEED_REFERENCE, HANDOVER_S, until=lambda s: not s.ctrl_from_net and not s.ref_from_net)[1]
        if not (before and on and off):
            return outcome(spec, False, "no T->O packet in a phase", link.exchanges())
        phases = (before[-1], on[-1], off[-1])
        observed, problems = [], []
        sources: tuple[tuple[str, Callable[[Status], bool | None]], ...] = (
            ("CtrlFromNet", lambda s: s.ctrl_from_net), ("RefFromNet", lambda s: s.ref_from_net))
        for name, flag in sources:
            b, o, a = (flag(s) for s in phases)
            how = _source(spec, b, o, a)
            seen = f"{name} {'/'.join('?' if v is None else str(int(v)) for v in (b, o, a))}"
            observed.append(f"{seen} ({how})" if how else seen)
            if how is None:
                problems.append(f"{seen} for NetCtl/NetRef 0/1/0")
        if off[-1].ctrl_from_net is False:
            ran = [s for s in link.hold(RUN_FWD, HOLD_S) if s.running]
            link.hold(0, SETTLE_S)
            if ran:
                problems.append("a network RunFwd 0->1 ran the drive with CtrlFromNet 0")
            else:
                observed.append(f"{spec.permits('ignores the network run').name} (RunFwd with CtrlFromNet 0)")
        return outcome(spec, not problems, "; ".join(problems or observed), link.exchanges())


@check("profile.motion.idle", "idle O->T data (run/idle header bit 0) does not run the drive",
       "a stopped drive sent RunFwd 1 and a speed reference in idle packets for 1 s does not run (Running1 stays 0; "
       "the data of an idle packet is not applied) and is still stopped when run packets with RunFwd 0 follow; "
       "permitted: Ready, or Faulted where the drive's idle action trips (CompoNet manual, Table 12, P048). What a "
       "running drive does on idle is its vendor's choice (NetIdleMode 0x29/1/20, P048; the ACG-ET2 manual names "
       "none): not judged", f"{IDLE_REFERENCE}; {MOTION}; CompoNet manual, Table 12 (P048) and Table D-4 (Net Idle "
       "Mode)",
       behaviours=[Behaviour("stays stopped", "the idle packets' data is not applied: the drive stays stopped and "
                             "Ready", IDLE_REFERENCE),
                   Behaviour("stopped by its idle action", "not running, Faulted by the drive's idle action (the "
                             "MX2's and RX's P048 trips)", "CompoNet manual, Table 12 (P048)")])
@_motion
def idle(ctx: Context, spec: CheckSpec, link: MotionLink, status: Status) -> Outcome:
    during = link.hold(link.control | RUN_FWD, IDLE_S, run=False)
    after = link.hold(link.control, SETTLE_S)
    if not during:
        return outcome(spec, False, "no T->O packet while O->T was idle", link.exchanges())
    ran = [s for s in during + after if s.running]
    if ran:
        return outcome(spec, False, "ran on idle data: " + ran[0].describe(), link.exchanges())
    shown = spec.permits("stopped by its idle action" if any(s.faulted for s in during + after) else "stays stopped")
    return outcome(spec, True, f"{shown.name}: not running through the {len(during)} T->O packets of the idle "
                   "phase and after it", link.exchanges())
