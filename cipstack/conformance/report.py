"""A report in the four forms the command writes: text, JSON, JUnit XML, one self-contained HTML page."""

from __future__ import annotations

import html
import json
from xml.etree import ElementTree

from .model import GROUPS, Exchange, Outcome, Report, Verdict

#: Failures first, then warnings, passes, checks that do not apply, checks not asked for.
_ORDER = {Verdict.FAIL: 0, Verdict.WARNING: 1, Verdict.PASS: 2, Verdict.NOT_APPLICABLE: 3, Verdict.NOT_RUN: 4}


def _identity_line(report: Report) -> str:
    identity = report.identity
    if not identity:
        return report.target
    revision = identity.get("revision") or {}
    return (f"{report.target}: {identity.get('product_name')!r} (vendor {identity.get('vendor_id')}, device type "
            f"{identity.get('device_type')}, product code {identity.get('product_code')}, revision "
            f"{revision.get('major')}.{revision.get('minor')})")


def _counts_text(outcomes: list[Outcome]) -> str:
    counts = {v: sum(o.verdict is v for o in outcomes) for v in Verdict}
    return (f"{counts[Verdict.PASS]} pass, {counts[Verdict.FAIL]} fail, {counts[Verdict.WARNING]} warning, "
            f"{counts[Verdict.NOT_APPLICABLE]} n/a, {counts[Verdict.NOT_RUN]} not run")


def summary_line(report: Report) -> str:
    return f"{len(report.outcomes)} checks: {_counts_text(report.outcomes)} ({report.duration_s:.1f} s)"


def stopped_line(report: Report) -> str:
    """Where the run stopped because the target stopped answering ("" when it did not)."""
    stopped = report.stopped
    if stopped is None:
        return ""
    left = stopped.get("not_run", 0)
    return (f"the run stopped: the target stopped answering after {stopped['after']} ({stopped['reason']}); "
            f"{left} check{'' if left == 1 else 's'} after it not run")


def group_lines(report: Report) -> list[str]:
    """One line per group: its name, its id and its counts."""
    groups = _grouped(report)
    width = max((len(GROUPS[g]) + len(g) for g, _ in groups), default=0) + 4
    return [f"  {f'{GROUPS[g]} ({g})':<{width}} {len(members):>4} {'check:' if len(members) == 1 else 'checks:':<7} "
            f"{_counts_text(members)}" for g, members in groups]


def _hex(data: bytes | None, limit: int = 96) -> str:
    if data is None:
        return "(nothing)"
    text = data[:limit].hex(" ")
    return text + (f" ... ({len(data)} bytes)" if len(data) > limit else "")


def _grouped(report: Report) -> list[tuple[str, list[Outcome]]]:
    groups = []
    for group in GROUPS:
        members = sorted((o for o in report.outcomes if o.group == group), key=lambda o: _ORDER[o.verdict])
        if members:
            groups.append((group, members))
    return groups


def _exchange_lines(exchange: Exchange, indent: str) -> list[str]:
    return [f"{indent}sent ({exchange.transport}):     {_hex(exchange.sent)}",
            f"{indent}received ({exchange.transport}): {_hex(exchange.received)}"]


def to_text(report: Report) -> str:
    lines = [f"cipstack conform {_identity_line(report)}", summary_line(report), *group_lines(report)]
    if report.stopped is not None:
        lines.append(stopped_line(report))
    if report.options.get("connection_points"):
        lines.append(f"connection points: {report.options['connection_points']}")
    failures = [o for _, members in _grouped(report) for o in members if o.verdict is Verdict.FAIL]
    if failures:
        lines += ["", "Failures"]
        for item in failures:
            lines += [f"  FAIL {item.name}: {item.spec.title}", f"       expected:  {item.spec.expected}",
                      f"       observed:  {item.observed}", f"       reference: {item.spec.reference}"]
            for exchange in item.shown_exchanges():
                lines += _exchange_lines(exchange, "       ")
    width = max((len(o.name) for o in report.outcomes), default=10)
    for group, members in _grouped(report):
        lines += ["", GROUPS[group]]
        for item in members:
            lines.append(f"  {item.verdict.value:<7} {item.name:<{width}}  {item.observed}")
    return "\n".join(lines)


def to_json(report: Report) -> str:
    return json.dumps(report.as_dict())


#: What JUnit shows as skipped (unless ``--strict`` makes a warning a failure).
_SKIPPED = (Verdict.NOT_APPLICABLE, Verdict.NOT_RUN, Verdict.WARNING)


def to_junit(report: Report, strict: bool = False) -> str:
    """JUnit XML, a test suite per group: a failure is ``<failure>``; a warning is ``<skipped>`` with its
    message (``strict``: a ``<failure>``); a check that does not apply, or was not asked for, is ``<skipped>``."""
    def failed(item: Outcome) -> bool:
        return item.verdict is Verdict.FAIL or (strict and item.verdict is Verdict.WARNING)

    suites = ElementTree.Element("testsuites", name=f"cipstack conform {report.target}",
                                 tests=str(len(report.outcomes)), failures=str(sum(map(failed, report.outcomes))),
                                 time=f"{report.duration_s:.3f}")
    for group, members in _grouped(report):
        suite = ElementTree.SubElement(
            suites, "testsuite", name=f"{group}: {GROUPS[group]}", tests=str(len(members)),
            failures=str(sum(map(failed, members))),
            skipped=str(sum(not failed(o) and o.verdict in _SKIPPED for o in members)))
        for item in members:
            case = ElementTree.SubElement(suite, "testcase", classname=f"conform.{group}", name=item.name)
            detail = "\n".join([f"expected: {item.spec.expected}", f"observed: {item.observed}",
                                f"reference: {item.spec.reference}",
                                *(line for e in item.exchanges for line in _exchange_lines(e, ""))])
            if failed(item):
                prefix = "warning (--strict): " if item.verdict is Verdict.WARNING else ""
                ElementTree.SubElement(case, "failure", message=prefix + item.observed).text = detail
            elif item.verdict is Verdict.WARNING:
                ElementTree.SubElement(case, "skipped", message=f"warning: {item.observed}").text = detail
            elif item.verdict in (Verdict.NOT_APPLICABLE, Verdict.NOT_RUN):
                ElementTree.SubElement(case, "skipped", message=item.observed)
            else:
                ElementTree.SubElement(case, "system-out").text = detail
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ElementTree.tostring(suites, encoding="unicode")


_STYLE = """
body { font-family: sans-serif; margin: 2em; color: #222; }
table { border-collapse: collapse; margin-bottom: 1.5em; }
table.checks { width: 100%; table-layout: auto; }
th, td { border: 1px solid #ccc; padding: 3px 8px; vertical-align: top; text-align: left; }
th { background: #eee; }
td.num { text-align: right; }
code, pre { font-family: monospace; font-size: 90%; }
code.id { white-space: nowrap; }
pre { white-space: pre-wrap; overflow-wrap: anywhere; margin: 0.3em 0; }
details summary { cursor: pointer; color: #555; }
cite { font-style: normal; color: #555; font-size: 90%; }
.pass { background: #e6f4e6; } .fail { background: #fbe3e3; } .warning { background: #fff4d6; }
.na { color: #777; }
p.stopped { background: #fbe3e3; padding: 0.5em; }
"""


def _anchor(text: str) -> str:
    """An HTML id of ``text``: letters, digits, ``-``, ``_`` and ``.`` kept, anything else ``-``."""
    return "".join(c if c.isalnum() or c in "-_." else "-" for c in text)


def _css(verdict: Verdict) -> str:
    return {Verdict.NOT_APPLICABLE: "na", Verdict.NOT_RUN: "na"}.get(verdict, verdict.value)


def _html_row(item: Outcome) -> str:
    e = html.escape
    wire = "".join(f"<pre>{e(x.transport)} &rarr; {e(_hex(x.sent))}\n{e(x.transport)} &larr; {e(_hex(x.received))}"
                   "</pre>" for x in item.shown_exchanges())
    folded = (f"<details><summary>request and reply bytes</summary>{wire}</details>" if wire else "")
    return (f'<tr class="{_css(item.verdict)}" id="check-{_anchor(item.name)}"><td><code class="id">{e(item.name)}'
            f"</code></td><td>{e(item.spec.title)}</td><td>{e(item.verdict.value)}</td><td>{e(item.spec.expected)}"
            f"</td><td>{e(item.observed)}<br><cite>{e(item.spec.reference)}</cite>{folded}</td></tr>")


def to_html(report: Report) -> str:
    """One self-contained page: a summary table per group with links, the failures and warnings
    first, then each group's checks (failures, warnings, passes, checks that do not apply), each row
    short with its request and reply bytes folded away."""
    e = html.escape
    groups = _grouped(report)
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>cipstack conform {e(report.target)}</title>", f"<style>{_STYLE}</style></head><body>",
             f"<h1>cipstack conform {e(_identity_line(report))}</h1>", f"<p>{e(summary_line(report))}</p>",
             *([f'<p class="stopped"><strong>{e(stopped_line(report))}</strong>'
                + (f' (<a href="#check-{_anchor(report.stopped["after"])}">its row</a>)'
                   if any(o.name == report.stopped["after"] for o in report.outcomes) else "") + "</p>"]
               if report.stopped is not None else []),
             *([f"<p>connection points: {e(str(report.options['connection_points']))}</p>"]
               if report.options.get("connection_points") else []),
             '<h2 id="summary">Summary</h2>', "<table><tr><th>group</th><th>checks</th><th>fail</th><th>warning</th>"
             "<th>pass</th><th>n/a</th><th>not run</th></tr>"]
    for group, members in groups:
        count = {v: sum(o.verdict is v for o in members) for v in Verdict}
        parts.append(f'<tr><td><a href="#group-{group}">{e(GROUPS[group])}</a> (<code>{e(group)}</code>)</td>'
                     f'<td class="num">{len(members)}</td><td class="num">{count[Verdict.FAIL]}</td>'
                     f'<td class="num">{count[Verdict.WARNING]}</td><td class="num">{count[Verdict.PASS]}</td>'
                     f'<td class="num">{count[Verdict.NOT_APPLICABLE]}</td>'
                     f'<td class="num">{count[Verdict.NOT_RUN]}</td></tr>')
    parts.append("</table>")
    for verdict, heading in ((Verdict.FAIL, "Failures"), (Verdict.WARNING, "Warnings")):
        found = [o for _, members in groups for o in members if o.verdict is verdict]
        if found:
            parts += [f'<h2 id="{verdict.value}s">{heading}</h2>', "<ul>"]
            parts += [f'<li><a href="#check-{_anchor(o.name)}"><code class="id">{e(o.name)}</code></a>: '
                      f"{e(o.observed)}</li>" for o in found]
            parts.append("</ul>")
    head = ("<tr><th>check</th><th>title</th><th>verdict</th><th>expected</th><th>observed, reference, bytes</th>"
            "</tr>")
    for group, members in groups:
        parts += [f'<h2 id="group-{group}">{e(GROUPS[group])} (<code>{e(group)}</code>): '
                  f"{e(_counts_text(members))}</h2>", '<p><a href="#summary">summary</a></p>',
                  f'<table class="checks">{head}', *(_html_row(o) for o in members), "</table>"]
    parts.append("</body></html>")
    return "\n".join(parts)


def markdown_table(group: str) -> str:
    """The docs' table of a group's checks, generated from their declarations (docs/conformance.md)."""
    from .registry import CHECKS

    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    rows = ["| check | what it sends | what the specification expects | permitted answers | reference |",
            "|---|---|---|---|---|"]
    for spec in CHECKS.values():
        if spec.group == group:
            codes = ", ".join([*(f"0x{c.value:0{4 if c.value > 0xFF else 2}X} ({c.meaning})"
                                 + (" warning" if c.verdict is Verdict.WARNING else "") for c in spec.codes),
                               *(f"{b.name}: {b.meaning}" for b in spec.behaviours)])
            title = spec.title + (f" (only with `--allow-stress`: it {spec.stress})" if spec.stress else "")
            rows.append(f"| `{spec.id}` | {cell(title)} | {cell(spec.expected)} | {cell(codes) or '-'} | "
                        f"{cell(spec.reference)} |")
    return "\n".join(rows)
