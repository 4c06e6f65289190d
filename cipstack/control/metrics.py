"""``GET /metrics``: the emulated devices' counters in the Prometheus text format, for a cluster's
monitoring to scrape.

Nothing is counted for it: the counters are the ones the devices keep anyway (the encapsulation
target's, the message router's replies by service and status, the Connection Manager's Forward_Open
counters, the class 1 connections' packet counts, the RS-485 slave's frames), read when Prometheus
scrapes (``DeviceCollector.collect``). The class 1 and explicit paths pay nothing for it: no lock, no
object per packet (benchmarks/README.md). A class 1 connection's counts are added to its target's
``closed_stats`` when it closes, so the totals only grow.

The format is prometheus_client's (the ``http`` extra): its collector interface and exposition. A
fleet spread over workers merges the workers' exposition into one (``merge_families``), with the
shard's gauges of its own.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable, Iterator, Mapping
from typing import TYPE_CHECKING

from aiohttp import web
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.exposition import CONTENT_TYPE_LATEST, generate_latest
from prometheus_client.parser import text_string_to_metric_families
from prometheus_client.registry import Collector, CollectorRegistry

if TYPE_CHECKING:
    from .service import DeviceService

#: What the Connection Manager's instance 1 counts (CIP Vol. 1, Connection Manager instance attributes
#: 2 to 4): the Forward_Opens it refused, by why.
_REFUSED = {2: "format", 3: "resource", 4: "other"}
#: The RS-485 slave's counters that are errors of the line, by their label.
_RTU_ERRORS = ("crc_errors", "truncated", "oversize", "interrupted", "overrun")


class ShardGauges:
    """What a fleet shard says of itself: its devices, and how many of them serve."""

    def __init__(self, shard: str, devices: Callable[[], tuple[int, int]],
                 workers: WorkerGauges | None = None) -> None:
        """``devices``: (devices, devices up) when asked; ``workers``: the load of its process(es)."""
        self.shard = shard
        self.devices = devices
        self.workers = workers

    def families(self) -> list[Metric]:
        total, up = self.devices()
        count = GaugeMetricFamily("cipstack_fleet_devices", "devices of this fleet shard", labels=["shard"])
        count.add_metric([self.shard], total)
        serving = GaugeMetricFamily("cipstack_fleet_devices_up", "devices of this fleet shard that serve "
                                    "(powered, in a worker that runs)", labels=["shard"])
        serving.add_metric([self.shard], up)
        return [count, serving, *(self.workers.families() if self.workers is not None else [])]


class WorkerGauges:
    """What a fleet's parent knows of each worker's load from its heartbeat: whether it is late, how far
    behind its loop runs, and its devices' class 1 productions (sent, late, missed), for an operator to
    see overload per worker where the devices' own counters are spread over hundreds of series."""

    def __init__(self, loads: Callable[[], Iterable[tuple[int, Mapping[str, float]]]]) -> None:
        """``loads``: (worker number, its load: ``late``, ``lag``, ``sent``, ``late_productions``,
        ``missed``) of each serving worker that has answered, when asked."""
        self.loads = loads

    def families(self) -> list[Metric]:
        label = ["worker"]
        late = GaugeMetricFamily("cipstack_fleet_worker_late", "1 while the worker's productions go late "
                                 "(overloaded: it goes on serving)", labels=label)
        lag = GaugeMetricFamily("cipstack_fleet_worker_loop_lag_seconds", "how late the worker's event loop "
                                "ran its last sampling", labels=label)
        counters = {key: CounterMetricFamily(f"cipstack_fleet_worker_productions_{name}", text, labels=label)
                    for key, name, text in (("sent", "sent", "class 1 productions of the worker's devices"),
                                            ("late_productions", "late", "class 1 productions later than "
                                             "their tolerance"),
                                            ("missed", "missed", "class 1 production slots skipped "
                                             "(the loop came too late for them)"))}
        for number, load in self.loads():
            late.add_metric([str(number)], load["late"])
            lag.add_metric([str(number)], load["lag"])
            for key, family in counters.items():
                family.add_metric([str(number)], load[key])
        return [late, lag, *counters.values()]


class DeviceCollector(Collector):
    """The counters of ``devices`` (by the address the API gives each), read at each scrape."""

    def __init__(self, devices: Mapping[str, DeviceService], shard: ShardGauges | None = None) -> None:
        self.devices = devices
        self.shard = shard

    def collect(self) -> Iterator[Metric]:
        families = self.families()
        for name, service in sorted(self.devices.items()):
            self.add_device(families, name, service)
        yield from families.values()
        if self.shard is not None:
            yield from self.shard.families()

    async def render(self) -> bytes:
        """``collect``'s exposition, read and written in slices with the event loop's other work between
        them (class 1 productions are due every few milliseconds on the same loop)."""
        families = self.families()
        for index, (name, service) in enumerate(sorted(self.devices.items()), start=1):
            self.add_device(families, name, service)
            if index % DEVICES_PER_SLICE == 0:
                await asyncio.sleep(0)
        return await render([*families.values(), *(self.shard.families() if self.shard is not None else [])])

    @staticmethod
    def families() -> dict[str, Metric]:
        """The families, without samples yet, by their short name."""
        label = ["device"]
        families: dict[str, Metric] = {name: GaugeMetricFamily(f"cipstack_{name}", text, labels=label)
                                       for name, text in _GAUGES}
        families.update((name, CounterMetricFamily(f"cipstack_{name}", text, labels=label)) for name, text in _COUNTERS)
        families.update((name, CounterMetricFamily(f"cipstack_{name}", text, labels=["device", extra]))
                        for name, text, extra in _LABELLED)
        families["requests"] = CounterMetricFamily("cipstack_requests", "explicit requests the message router "
                                                   "answered, by service and general status",
                                                   labels=["device", "service", "status"])
        return families

    @staticmethod
    def add_device(families: dict[str, Metric], name: str, service: DeviceService) -> None:
        """The samples of the device ``name`` (read now from the counters it keeps)."""
        def put(family: str, number: float, *extra: str) -> None:
            families[family].add_metric([name, *extra], number)  # type: ignore[attr-defined]

        runtime = service.runtime
        device = runtime.device
        put("powered", 1 if runtime.power.powered else 0)
        put("sessions", len(runtime.target.sessions))
        put("class3_connections", len(device.connection_table.connections))
        put("class1_connections", len(runtime.io.connections) if runtime.io else 0)
        put("faults_active", len(service.faults.active))
        put("tripped", 1 if (device.status_fields() or {}).get("trip") else 0)
        stats = runtime.target.stats
        put("sessions_opened", stats.sessions_opened)
        put("encapsulation_frames", stats.frames)
        put("encapsulation_errors", stats.errors)
        put("encapsulation_dropped", stats.dropped)
        counts = device.connection_manager.counters.values
        put("forward_opens", counts.get(1, 0))
        for attribute, reason in _REFUSED.items():
            put("forward_opens_refused", counts.get(attribute, 0), reason)
        put("trips", service.events.counts.get("trip", 0))
        put("connection_timeouts", device.connection_table.timeouts, "3")
        io = runtime.io
        every = [io.closed_stats, *(c.stats for c in list(io.connections.values()))] if io is not None else []
        if io is not None:
            put("connection_timeouts", io.timeouts, "1")
            put("class1_dropped", io.dropped)
        put("class1_packets_sent", sum(s.sent for s in every))
        put("class1_packets_received", sum(s.received for s in every))
        put("class1_packets_late", sum(s.late for s in every))
        put("class1_packets_lost", sum(s.lost for s in every))
        put("class1_productions_missed", sum(s.skipped_slots for s in every))
        for key, count in sorted(device.router.reply_counts.items()):
            families["requests"].add_metric([name, f"0x{key >> 8:02X}", f"0x{key & 0xFF:02X}"],  # type: ignore[attr-defined]
                                            count)
        if runtime.rtu is not None:
            line = runtime.rtu.slaves[0].counters
            put("rtu_frames", line.frames)
            for kind in _RTU_ERRORS:
                put("rtu_errors", getattr(line, kind), kind)


#: Devices read, and samples written, between two returns to the event loop during a scrape: a slice
#: holds the loop a few hundred microseconds (benchmarks/metrics.py), less than a class 1 tolerance.
DEVICES_PER_SLICE = 4
SAMPLES_PER_SLICE = 24

_GAUGES = (
    ("powered", "1 while the device is powered (a power-cycle fault turns it off)"),
    ("sessions", "open encapsulation sessions"),
    ("class3_connections", "open class 3 (explicit) connections"),
    ("class1_connections", "open class 1 (I/O) connections"),
    ("faults_active", "injected faults in effect"),
    ("tripped", "1 while the drive is tripped"))
_COUNTERS = (
    ("sessions_opened", "encapsulation sessions registered"),
    ("encapsulation_frames", "encapsulation frames received"),
    ("encapsulation_errors", "encapsulation frames answered with an error status"),
    ("encapsulation_dropped", "encapsulation frames dropped unanswered"),
    ("forward_opens", "Forward_Open requests (Connection Manager instance attribute 1, 16 bits)"),
    ("class1_packets_sent", "class 1 packets produced"),
    ("class1_packets_received", "class 1 packets consumed"),
    ("class1_packets_late", "class 1 productions later than their tolerance"),
    ("class1_packets_lost", "class 1 packets the device never saw"),
    ("class1_productions_missed", "class 1 production slots skipped (its process came too late for them)"),
    ("class1_dropped", "class 1 datagrams dropped (malformed, or for no open connection)"),
    ("trips", "drive trips seen since the HTTP API started"),
    ("rtu_frames", "Modbus-RTU frames on the device's RS-485 line"))
#: Counters with a second label: name, help, the label.
_LABELLED = (
    ("connection_timeouts", "connections closed by their watchdog", "transport_class"),
    ("forward_opens_refused", "Forward_Opens refused, by why (Connection Manager instance attributes 2-4, 16 bits)",
     "reason"),
    ("rtu_errors", "Modbus-RTU frames refused, by why", "kind"))


def exposition(collectors: Iterable[Collector]) -> bytes:
    """The text of ``collectors`` in the Prometheus format."""
    registry = CollectorRegistry(auto_describe=False)
    for collector in collectors:
        registry.register(collector)
    return generate_latest(registry)


async def render(families: Iterable[Metric]) -> bytes:
    """The exposition of ``families``, written ``SAMPLES_PER_SLICE`` samples at a time with the event loop's
    other work between: prometheus_client's own text of each part, the family's HELP and TYPE kept once."""
    parts = []
    for family in families:
        samples = family.samples
        for start in range(0, max(len(samples), 1), SAMPLES_PER_SLICE):
            part = Metric(family.name, family.documentation, family.type)
            part.samples = samples[start:start + SAMPLES_PER_SLICE]
            text = exposition([Families([part])])
            if start:   # HELP and TYPE once, before the family's first sample
                text = b"".join(line for line in text.splitlines(keepends=True) if not line.startswith(b"# "))
            parts.append(text)
            await asyncio.sleep(0)
    return b"".join(parts)


class Families(Collector):
    """Families already built (read from other processes' ``/metrics``), collected as they are."""

    def __init__(self, families: Iterable[Metric]) -> None:
        self.families = list(families)

    def collect(self) -> Iterator[Metric]:
        return iter(self.families)


def merge_families(texts: Iterable[str]) -> dict[str, Metric]:
    """The families of ``texts`` (each a process's ``/metrics``) by name, each once with the samples of all.
    A sample that several give with the same labels is their sum, so that the answer stays valid: the
    gauges of fleets that are not shards of one plant (each says ``shard="0/1"``) add up to the plant's."""
    merged: dict[str, Metric] = {}
    where: dict[tuple[str, tuple[tuple[str, str], ...]], int] = {}   # a sample -> its index in its family
    for text in texts:
        for family in text_string_to_metric_families(text):
            into = merged.setdefault(family.name, Metric(family.name, family.documentation, family.type))
            for sample in family.samples:
                key = (sample.name, tuple(sorted(sample.labels.items())))
                if key in where:
                    index = where[key]
                    into.samples[index] = into.samples[index]._replace(value=into.samples[index].value + sample.value)
                else:
                    where[key] = len(into.samples)
                    into.samples.append(sample)
    return merged


def powered_devices(families: Mapping[str, Metric]) -> int:
    """How many devices ``families`` say are powered (``cipstack_powered`` 1)."""
    family = families.get("cipstack_powered")
    return sum(1 for sample in family.samples if sample.value == 1) if family is not None else 0


def metrics_response(body: bytes) -> web.Response:
    return web.Response(body=body, headers={"Content-Type": CONTENT_TYPE_LATEST})


def add_metrics_route(app: web.Application, devices: Mapping[str, DeviceService],
                      shard: ShardGauges | None = None) -> None:
    """``GET /metrics`` on ``app``: the counters of ``devices`` (and ``shard``'s gauges), read at each scrape."""
    collector = DeviceCollector(devices, shard)

    async def metrics(request: web.Request) -> web.Response:
        return metrics_response(await collector.render())

    app.router.add_get("/metrics", metrics)


__all__ = ["DeviceCollector", "Families", "ShardGauges", "WorkerGauges", "add_metrics_route", "exposition",
           "merge_families", "metrics_response", "powered_devices", "render"]
