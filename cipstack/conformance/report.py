"""A report in the four forms the command writes: text, JSON, JUnit XML, one self-contained HTML page."""

from __future__ import annotations

import html
import json
from xml.etree import ElementTree

from .model import GROUPS, Exchange, Outcome, Report, Verdict

#: Failures first, then warnings, passes, checks that do not apply.
_ORDER = {Verdict.FAIL: 0, Verdict.WARNING: 1, Verdict.PASS: 2, Verdict.NOT_APPLICABLE: 3}


def _identity_line(report: Report) -> str:
    identity = report.identity
    if not identity:
        return report.target
    revision = identity.get("revision") or {}
    return (f"{report.target}: {identity.get('product_name')!r} (vendor {identity.get('vendor_id')}, device type "
            f"{identity.get('device_type')}, product code {identity.get('product_code')}, revision "
            f"{revision.get('major')}.{revision.get('minor')})")


def summary_line(report: Report) -> str:
    counts = report.counts()
    return (f"{len(report.outcomes)} checks: {counts['pass']} pass, {counts['fail']} fail, {counts['warning']} "
            f"warning, {counts['n/a']} n/a ({report.duration_s:.1f} s)")


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
    lines = [f"cipstack conform {_identity_line(report)}", summary_line(report)]
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


def to_junit(report: Report) -> str:
    suites = ElementTree.Element("testsuites", name=f"cipstack conform {report.target}",
                                 tests=str(len(report.outcomes)), failures=str(len(report.failures)),
                                 time=f"{report.duration_s:.3f}")
    for group, members in _grouped(report):
        suite = ElementTree.SubElement(
            suites, "testsuite", name=f"{group}: {GROUPS[group]}", tests=str(len(members)),
            failures=str(sum(o.verdict is Verdict.FAIL for o in members)),
            skipped=str(sum(o.verdict is Verdict.NOT_APPLICABLE for o in members)))
        for item in members:
            case = ElementTree.SubElement(suite, "testcase", classname=f"conform.{group}", name=item.name)
            detail = "\n".join([f"expected: {item.spec.expected}", f"observed: {item.observed}",
                                f"reference: {item.spec.reference}",
                                *(line for e in item.exchanges for line in _exchange_lines(e, ""))])
            if item.verdict is Verdict.FAIL:
                ElementTree.SubElement(case, "failure", message=item.observed).text = detail
            elif item.verdict is Verdict.NOT_APPLICABLE:
                ElementTree.SubElement(case, "skipped", message=item.observed)
            else:
                prefix = "warning: " if item.verdict is Verdict.WARNING else ""
                ElementTree.SubElement(case, "system-out").text = prefix + detail
    return '<?xml version="1.0" encoding="utf-8"?>\n' + ElementTree.tostring(suites, encoding="unicode")


_STYLE = """
body { font-family: sans-serif; margin: 2em; color: #222; }
table { border-collapse: collapse; width: 100%; margin-bottom: 1.5em; }
th, td { border: 1px solid #ccc; padding: 4px 8px; vertical-align: top; text-align: left; }
th { background: #eee; }
code, pre { font-family: monospace; font-size: 90%; white-space: pre-wrap; word-break: break-all; }
.pass { background: #e6f4e6; } .fail { background: #fbe3e3; } .warning { background: #fff4d6; }
.na { color: #777; }
"""


def to_html(report: Report) -> str:
    e = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>cipstack conform {e(report.target)}</title>", f"<style>{_STYLE}</style></head><body>",
             f"<h1>cipstack conform {e(_identity_line(report))}</h1>", f"<p>{e(summary_line(report))}</p>"]
    for group, members in _grouped(report):
        parts += [f"<h2>{e(GROUPS[group])}</h2>", "<table><tr><th>verdict</th><th>check</th><th>expected</th>"
                  "<th>observed</th><th>reference</th><th>sent / received</th></tr>"]
        for item in members:
            css = "na" if item.verdict is Verdict.NOT_APPLICABLE else item.verdict.value
            wire = "<br>".join(f"{e(x.transport)} &rarr; <code>{e(_hex(x.sent))}</code><br>{e(x.transport)} &larr; "
                               f"<code>{e(_hex(x.received))}</code>" for x in item.shown_exchanges())
            parts.append(f'<tr class="{css}"><td>{e(item.verdict.value)}</td><td><code>{e(item.name)}</code><br>'
                         f"{e(item.spec.title)}</td><td>{e(item.spec.expected)}</td><td>{e(item.observed)}</td>"
                         f"<td>{e(item.spec.reference)}</td><td>{wire}</td></tr>")
        parts.append("</table>")
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
            codes = ", ".join(f"0x{c.value:0{4 if c.value > 0xFF else 2}X} ({c.meaning})"
                              + (" warning" if c.verdict is Verdict.WARNING else "") for c in spec.codes)
            rows.append(f"| `{spec.id}` | {cell(spec.title)} | {cell(spec.expected)} | {cell(codes) or '-'} | "
                        f"{cell(spec.reference)} |")
    return "\n".join(rows)
