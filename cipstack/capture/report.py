"""What ``capture analyze`` prints and writes: the human summary, CSV timing rows and the plot."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from ..errors import CipstackError
from .analyzer import Connection, Direction, Totals
from .decoding import path_text

#: How many explicit exchanges / anomalies the human summary lists (the totals count them all).
LIST_LIMIT = 20


def _t(time: float | None, origin: float) -> str:
    return "-" if time is None else f"{time - origin:.6f}s"


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:g}"


def explicit_line(record: dict[str, Any], origin: float) -> str:
    request = record.get("request") or {}
    shown = request.get("embedded", request)
    text = f"{_t(record.get('time', record.get('reply_time')), origin)} {record['client']} -> {record['target']} "
    text += f"session 0x{record['session']:08X} "
    if request:
        text += f"{shown.get('service_name', '?')} {path_text(shown)}"
        if "route" in request and isinstance(request["route"], list):
            hops = ", ".join(f"port {h['port']} link {h['link']}" + (f" ({h['network']})" if "network" in h else "")
                             for h in request["route"])
            text += f" routed by {request.get('service_name')} via {hops}"
        data = shown.get("data") or {}
        if "text" in data:
            text += f" = {data['text']}"
    if "unanswered" in record:
        return text + f": unanswered ({record['unanswered']})"
    reply = record["reply"]
    if not request:
        text += f"reply to service 0x{reply['service']:02X} with no request in the capture"
    text += f": {reply['status_name']}"
    value = reply.get("data") or {}
    if "text" in value:
        text += f" -> {value['text']}"
    if "latency_ms" in record:
        text += f" ({record['latency_ms']:g} ms)"
    return text


def connection_text(connection: Connection, origin: float) -> list[str]:
    c = connection.as_dict()
    triad = c["triad"]
    lines = [f"Connection {c['number']}: {c['originator']} -> {c['target']}, opened {_t(c['opened'], origin)} "
             f"(frames {connection.frame_numbers[0]}/{connection.frame_numbers[1]})",
             f"  triad: connection serial 0x{triad['connection_serial']:04X}, vendor {triad['vendor_id']}, "
             f"originator serial 0x{triad['originator_serial']:08X}",
             f"  ids: O->T 0x{c['o_t_id']:08X}, T->O 0x{c['t_o_id']:08X}; points: config {c['config']}, "
             f"O->T {c['o_t_point']}, T->O {c['t_o_point']}; class {c['transport_class']} {c['trigger']}, "
             f"timeout multiplier {c['timeout_multiplier']}"]
    for name, key, api, kind in (("O->T", "o_t", c["o_t_api_ms"], c["o_t_type"]),
                                 ("T->O", "t_o", c["t_o_api_ms"], c["t_o_type"])):
        d = c[key]
        rpi_us = connection.request.ot_rpi_us if key == "o_t" else connection.request.to_rpi_us
        lines.append(f"  {name}: RPI {_ms(rpi_us / 1000)} ms, API {_ms(api)} ms, {d['size']} bytes, "
                     f"{kind.replace('_', '-')}: {d['frames']} frames, "
                     f"interval p50 {_ms(d['p50_ms'])} / p99 {_ms(d['p99_ms'])} / max {_ms(d['max_ms'])} ms, "
                     f"{_ms(d['within_0.5ms_pct'])} % within +-0.5 ms, {d['late']} late (> 1.5 RPI), "
                     f"{d['lost']} lost, {d['duplicates']} duplicate, {d['stale']} stale")
    if c["run_idle_change_count"]:
        changes = ", ".join(f"{x['mode']} at {_t(x['time'], origin)}" for x in c["run_idle_changes"][:6])
        lines.append(f"  run/idle: {c['run_idle_change_count']} change(s): {changes}")
    if c["data_change_count"]:
        lines.append(f"  data changes: {c['data_change_count']} (by {c['declarations']})")
        for change in c["data_changes"][:8]:
            fields = ", ".join(f"{k} {v[0]} -> {v[1]}" for k, v in list(change["changes"].items())[:6])
            lines.append(f"    {_t(change['time'], origin)} {change['direction'].replace('_', '->').upper()} "
                         f"assembly {change['assembly']}: {fields}")
    duration = "" if c["ended"] is None else f" after {c['ended'] - c['opened']:.3f} s"
    lines.append(f"  ended: {c['end_reason']} at {_t(c['ended'], origin)}{duration}")
    return lines


def summary_text(name: str, totals: Totals, identities: dict[str, dict[str, Any]], explicit: list[dict[str, Any]],
                 anomalies: list[dict[str, Any]], connections: list[Connection], sources: dict[str, str]) -> str:
    origin = totals.first_time or 0.0
    span = (totals.last_time or 0.0) - origin
    lines = [f"{name}: {totals.frames} frames over {span:.3f} s; {totals.enip_frames} EtherNet/IP frames, "
             f"{totals.io_frames} class 1 frames; {totals.explicit} explicit exchanges ({totals.errors} error "
             f"replies, {totals.unanswered} unanswered); {totals.connections} class 1 connections; "
             f"{totals.anomalies} anomalies"]
    for target, identity in identities.items():
        lines.append(f"Target {target}: {identity['product_name']} (vendor {identity['vendor_id']}, device type "
                     f"{identity['device_type']}, product code {identity['product_code']}, revision "
                     f"{identity['revision']}), decoded by {sources.get(target, 'standard objects')}")
    if totals.services:
        lines.append("Explicit messages: " + ", ".join(f"{k} {v}" for k, v in sorted(totals.services.items())))
    for record in explicit[:LIST_LIMIT]:
        lines.append("  " + explicit_line(record, origin))
    if totals.explicit + totals.unanswered > min(len(explicit), LIST_LIMIT):
        lines.append(f"  ... (the first exchanges and the errors, unanswered and routed ones; --json lists all "
                     f"{totals.explicit + totals.unanswered})")
    for connection in connections:
        lines.append("")
        lines.extend(connection_text(connection, origin))
    if anomalies:
        lines.append("")
        lines.append(f"Anomalies: {totals.anomalies}")
        for a in anomalies[:LIST_LIMIT]:
            where = f" at offset {a['offset']}" if a.get("offset") is not None else ""
            lines.append(f"  frame {a['frame']} {a.get('source', '')} -> {a.get('destination', '')} "
                         f"[{a['layer']}]{where}: {a['reason']}")
    return "\n".join(lines)


def samples(direction: Direction) -> list[tuple[float, float]]:
    """(time, interval) of a direction: its uniform sample plus its largest intervals."""
    return sorted(set(direction.reservoir.items) | {(t, v) for v, t in direction.worst.heap})


def write_csv(directory: Path, connections: list[Connection]) -> list[Path]:
    """``connections.csv`` (one row per connection and direction) and ``connection-N.csv`` (inter-arrival
    times: a uniform sample of at most 5,000 per direction plus the 50 largest; time, direction, ms)."""
    directory.mkdir(parents=True, exist_ok=True)
    written = [directory / "connections.csv"]
    columns = ["connection", "direction", "o_t_id", "t_o_id", "rpi_ms", "size", "frames", "intervals", "p50_ms",
               "p99_ms", "max_ms", "within_0.5ms_pct", "late", "lost", "duplicates", "stale", "end_reason"]
    with written[0].open("w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(columns)
        for connection in connections:
            c = connection.as_dict()
            for key in ("o_t", "t_o"):
                d = c[key]
                writer.writerow([c["number"], key.replace("_", "->").upper(), f"0x{c['o_t_id']:08X}",
                                 f"0x{c['t_o_id']:08X}", *(d[k] for k in columns[4:16]), c["end_reason"]])
    for connection in connections:
        path = directory / f"connection-{connection.number}.csv"
        with path.open("w", newline="") as out:
            writer = csv.writer(out)
            writer.writerow(["time", "direction", "interval_ms", "rpi_ms"])
            rows = [(t, "O->T", i, connection.o_t.rpi_us) for t, i in samples(connection.o_t)]
            rows += [(t, "T->O", i, connection.t_o.rpi_us) for t, i in samples(connection.t_o)]
            for t, which, interval, rpi in sorted(rows):
                writer.writerow([f"{t:.6f}", which, f"{interval * 1e3:.3f}", rpi / 1000])
        written.append(path)
    return written


class PlotUnavailable(CipstackError, RuntimeError):
    pass


def write_plot(path: Path, connections: list[Connection], origin: float) -> None:
    """Inter-arrival times per connection and direction against time, with the RPI and the
    +-0.5 ms band (the tolerance of benchmarks/io.py)."""
    try:
        import matplotlib
    except ImportError:
        raise PlotUnavailable('--plot needs matplotlib: pip install "cipstack[plot]"') from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = [c for c in connections if c.o_t.intervals.count or c.t_o.intervals.count]
    rows = max(1, len(shown))
    figure, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows), squeeze=False)
    slots: list[Connection | None] = [*shown] or [None]
    for axis, connection in zip(axes[:, 0], slots, strict=False):
        if connection is None:
            axis.text(0.5, 0.5, "no class 1 traffic", ha="center", va="center")
            continue
        for name, direction, colour in (("O->T", connection.o_t, "tab:blue"), ("T->O", connection.t_o, "tab:orange")):
            points = samples(direction)
            if not points:
                continue
            rpi = direction.rpi_us / 1000
            axis.plot([t - origin for t, _ in points], [i * 1e3 for _, i in points], ".", markersize=2,
                      color=colour, label=f"{name} (RPI {rpi:g} ms)")
            axis.axhline(rpi, color=colour, linewidth=0.8)
            axis.axhspan(rpi - 0.5, rpi + 0.5, color=colour, alpha=0.12)
        axis.set_title(f"connection {connection.number}: O->T 0x{connection.ot_id:08X}, T->O 0x{connection.to_id:08X}",
                       fontsize=9)
        axis.set_ylabel("interval (ms)")
        axis.legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(path, dpi=80)
    plt.close(figure)
