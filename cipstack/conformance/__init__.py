"""An open conformance battery for any EtherNet/IP target (``cipstack conform``).

``run(host, port=..., eds=..., groups=...)`` sends each check's request, compares what comes back
with what the specification (and the target's EDS file) expects, and returns a ``Report`` of
outcomes: pass, fail, warning or not applicable, each with the bytes sent and received. Safe by
default: nothing is written without ``allow_writes``, the device is not reset without
``allow_reset``, nothing exhausts the device's resources without ``allow_stress``, requests are
rate-bounded and every connection opened is closed. A target that stops answering stops the run, by
the name of the check after which it went silent.
"""

from __future__ import annotations

from .model import GROUPS, CheckSpec, Exchange, Outcome, Report, Verdict
from .registry import CHECKS
from .runner import check_ids, parse_groups, run
from .wire import TargetUnreachable

__all__ = ["CHECKS", "GROUPS", "CheckSpec", "Exchange", "Outcome", "Report", "TargetUnreachable", "Verdict",
           "check_ids", "parse_groups", "run"]
