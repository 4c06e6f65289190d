"""The motor behind ``fake_target``'s AC drive: output assembly 20/21 in, input 70/71 out, the
Control Supervisor and AC/DC Drive attributes kept in step, in real time.

It does what the profile asks (ACG-ET2 manual, Control Supervisor object; CompoNet manual, Tables
B-1 to B-8 and D-4): a run starts on a RunFwd 0->1 edge while CtrlFromNet is 1 (NetCtl), the speed
ramps to the reference at ``ACCEL_MS`` / ``DECEL_MS`` per full speed, AtReference once there,
Running1 until the speed is 0, a ForceFault rising edge faults it, a FaultRst 0->1 edge resets, and
the data of idle packets is not applied. ``deviations`` names the motion checks it deviates for.
Written from the wire and the manuals, importing nothing of cipstack.
"""

from __future__ import annotations

import struct
import threading
import time

ACCEL_MS, DECEL_MS, MAX_SPEED = 400, 400, 1800
#: The deviating stop: this many times slower than its DecelTime says (past the check's bound).
SLOW_STOP = 40
RUN_FWD, FAULT_RST, NET_CTL, NET_REF = 0x01, 0x04, 0x20, 0x40


class FakeDrive:
    def __init__(self, deviations: set[str]) -> None:
        self.deviations = deviations
        self._lock = threading.Lock()
        self.t = time.monotonic()
        self.speed = 0.0
        self.reference = 0
        self.run = False
        self.faulted = False
        self.net_ctl = self.net_ref = False
        self.force = False
        self._previous = 0  # byte 0 of the last output consumed
        #: Moved by the network at least once: from then on the attributes follow the model.
        self.touched = False

    def _advance(self) -> None:
        now = time.monotonic()
        dt, self.t = now - self.t, now
        target = self.reference if self.run and not self.faulted else 0
        rate = MAX_SPEED / ACCEL_MS * 1000 if abs(target) > abs(self.speed) else MAX_SPEED / DECEL_MS * 1000
        if "profile.motion.stop" in self.deviations and abs(target) < abs(self.speed):
            rate /= SLOW_STOP
        step = rate * dt
        self.speed = target if abs(target - self.speed) <= step else self.speed + step * (1 if target > self.speed
                                                                                          else -1)

    def consume(self, output: int, data: bytes, run: bool) -> None:
        """O->T data of output assembly ``output`` (20 or 21); ``run``: the run/idle header's run bit."""
        if not run and "profile.motion.idle" not in self.deviations:
            return  # idle: the data is not applied
        with self._lock:
            self._advance()
            self.touched = True
            bits = data[0]
            if output == 21:
                self.net_ctl, self.net_ref = bool(bits & NET_CTL), bool(bits & NET_REF)
            reset = bits & FAULT_RST
            if reset and (not self._previous & FAULT_RST or "profile.motion.fault_reset" in self.deviations):
                self.faulted = False
            obeys = self.net_ctl or "profile.motion.net_ctrl" in self.deviations
            if not self.net_ctl and "profile.motion.net_ctrl" not in self.deviations:
                self.run = False  # the local source commands no run
            elif obeys and bits & RUN_FWD and not self._previous & RUN_FWD and not self.faulted:
                self.run = True
            elif not bits & RUN_FWD:
                self.run = False
            if self.net_ref:
                self.reference = struct.unpack_from("<h", data, 2)[0]
            self._previous = bits

    def set(self, class_id: int, attribute: int, value: bytes) -> None:
        """Set_Attribute_Single of a settable attribute."""
        with self._lock:
            self._advance()
            flag = bool(value[:1] != b"\0")
            if (class_id, attribute) == (0x29, 17):
                if flag and not self.force:
                    self.faulted, self.run = True, False
                self.force = flag
            elif (class_id, attribute) == (0x29, 3):
                self.run = flag and self.run
            elif (class_id, attribute) == (0x29, 5):
                self.net_ctl = flag
            elif (class_id, attribute) == (0x2A, 4):
                self.net_ref = flag
            elif (class_id, attribute) == (0x2A, 8):
                self.reference = struct.unpack("<h", value[:2])[0]

    @property
    def running(self) -> bool:
        return (self.run or self.speed != 0) and not self.faulted

    @property
    def at_reference(self) -> bool:
        return (self.run and self.reference != 0 and self.speed == self.reference
                and "profile.motion.run_forward" not in self.deviations)

    def state(self) -> int:
        if self.faulted:
            return 7
        return 4 if self.run else 5 if self.speed else 3

    def input(self, instance: int) -> bytes:
        """Input assembly 70 or 71 now."""
        with self._lock:
            self._advance()
            bits = int(self.faulted) | self.running << 2
            state = 0
            if instance == 71:
                bits |= ((not self.faulted) << 4 | self.net_ctl << 5 | self.net_ref << 6
                         | self.at_reference << 7)
                state = self.state()
            return bytes((bits, state)) + struct.pack("<h", round(self.speed))

    def sync(self, supervisor: dict[int, bytes], drive: dict[int, bytes]) -> None:
        """The attributes as the model is now (once the network has moved it)."""
        if not self.touched:
            return
        with self._lock:
            self._advance()
            supervisor.update({5: bytes((self.net_ctl,)), 6: bytes((self.state(),)), 7: bytes((self.running,)),
                               9: bytes((not self.faulted,)), 10: bytes((self.faulted,)),
                               15: bytes((self.net_ctl,)), 17: bytes((self.force,))})
            drive.update({3: bytes((self.at_reference,)), 4: bytes((self.net_ref,)),
                          7: struct.pack("<h", round(self.speed)), 8: struct.pack("<h", self.reference),
                          29: bytes((self.net_ref,))})
