"""An independent reader, eds-pie, reads what ``format_eds`` writes.

eds-pie logs what it finds wrong instead of raising. Reading the adapter sample as written by
``format_eds``, the only warnings it may log are its known false positives: it knows no
entries of [Groups] and [Port], so it calls each of them, and each of their fields, unknown
(its "Unknown Entry" message is a literal template that never names the entry).

It cannot read keywords that begin with digits (vendor keywords such as ``259_Firmware``):
its lexer takes them for numbers and stops. The sample keeps its vendor data in a
vendor-specific section, whose keywords are the vendor's own and need no prefix.
"""

from __future__ import annotations

import logging
from typing import Any

import pytest

from cipstack.eds.model import FieldKind, format_epath
from cipstack.eds.reader import parse_eds
from cipstack.eds.writer import format_eds

from .conftest import EdsPieLog
from .samples import ADAPTER_EDS

pytestmark = pytest.mark.interop

UNKNOWN_ENTRY = "Unknown Entry [{section.keyword,}].{entry.keyword}"
KNOWN_FALSE_POSITIVES = [
    UNKNOWN_ENTRY,
    "Unknown Field [Groups].Group1.field0",
    "Unknown Field [Groups].Group1.field1",
    "Unknown Field [Groups].Group1.field2",
    "Unknown Field [Groups].Group1.field3",
    "Unknown Field [Groups].Group1.field4",
    "Unknown Field [Groups].Group1.field5",
    UNKNOWN_ENTRY,
    "Unknown Field [Groups].Group2.field0",
    "Unknown Field [Groups].Group2.field1",
    "Unknown Field [Groups].Group2.field2",
    "Unknown Field [Groups].Group2.field3",
    "Unknown Field [Groups].Group2.field4",
    UNKNOWN_ENTRY,
    "Unknown Field [Port].Port1.field0",
    "Unknown Field [Port].Port1.field1",
    "Unknown Field [Port].Port1.field2",
    "Unknown Field [Port].Port1.field3",
]




def _number(value: Any) -> float:
    if isinstance(value, (int, float)):
        return value
    try:
        return int(value, 0)
    except ValueError:
        return float(value)


def test_eds_pie_reads_the_written_sample(cip_eds: Any, eds_pie_log: EdsPieLog) -> None:
    ours = parse_eds(ADAPTER_EDS)
    text = format_eds(ours)
    theirs = cip_eds(text)
    assert [record.getMessage() for record in eds_pie_log.records] == KNOWN_FALSE_POSITIVES
    assert all(record.levelno == logging.WARNING for record in eds_pie_log.records)
    assert theirs.protocol == "EtherNetIP"
    assert theirs.get_value("Device", "VendCode") == 259
    assert theirs.get_value("Device", "ProdName") == "CENT"


def test_eds_pie_sees_the_same_values(cip_eds: Any, eds_pie_log: EdsPieLog) -> None:
    ours = parse_eds(format_eds(parse_eds(ADAPTER_EDS), layout=True))
    theirs = cip_eds(format_eds(ours))
    assert list(theirs.sections) == [section.name for section in ours]
    for section in ours:
        their_section = theirs.get_section(section.name)
        assert list(their_section.entries) == [entry.keyword for entry in section]
        for entry in section:
            their_fields = their_section.entries[entry.keyword].fields
            assert len(their_fields) == len(entry.fields), entry.keyword
            for mine, their in zip(entry.fields, their_fields, strict=True):
                where = f"[{section.name}] {entry.keyword} {their.name}"
                if mine.kind is FieldKind.EMPTY:
                    assert their.value == "", where
                elif mine.kind in (FieldKind.INT, FieldKind.FLOAT):
                    assert _number(their.value) == mine.value, where
                elif mine.kind is FieldKind.EPATH:
                    assert their.value == format_epath(mine.value), where
                elif mine.kind in (FieldKind.STRING, FieldKind.KEYWORD):
                    assert their.value == mine.value, where
                else:
                    assert str(their.value) == mine.raw, where
