"""MX2 and RX inverter models and the identity their CompoNet option board serves.

The option board's Identity object (Table C-2) depends on the inverter it is mounted on:
the product code and product name come from the inverter model (Tables 2/3 and C-3/C-4),
as does the EDS file a configurator needs. Each model is declared once below; the MX2
1-phase and 3-phase 200 V models of the same capacity share one product code, one product
name and one EDS file (Table 2 lists them in pairs, Table C-3 on one row).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from enum import Enum

from ...errors import NotFound


class Family(Enum):
    MX2 = "MX2"
    RX = "RX"

    @property
    def option_board(self) -> str:
        """Model of the CompoNet option board for this inverter family (Table 1)."""
        return f"3G3AX-{self.value}-CRT-E"


#: Identity attribute 1: "47 (OMRON Corporation)" (Table C-2).
VENDOR_ID = 47
#: Identity attribute 2: "2 (AC Drive)", the CompoNet profile of the board (Table C-2, Table 1).
DEVICE_TYPE = 2
#: Identity attribute 4 is "Depending on unit" (Table C-2): the manual gives no number, so the
#: emulated board reports 1.1. Configurators must use an EDS file of the same revision.
REVISION = (1, 1)
#: Identity attribute 0x65 "Firmware Revision Option Board", also "Depending on unit" (Table C-2).
FIRMWARE_REVISION = (1, 1)
#: Identity attribute 9 "Configuration Consistency Value" starts at 0 (Table C-2).
INITIAL_CONSISTENCY_VALUE = 0


@dataclass(frozen=True)
class Model:
    """One inverter model as the option board's Identity object and EDS file see it."""

    #: Inverter model name, e.g. "MX2-A2015-E" (Tables 2/3).
    name: str
    family: Family
    #: Identity attribute 3 (Tables 2/3, C-3/C-4, decimal).
    product_code: int
    #: Identity attribute 7 (Tables C-3/C-4).
    product_name: str
    #: EDS file for this model (Tables 2/3, C-3/C-4).
    eds_file: str

    @property
    def voltage_class(self) -> int:
        """200 or 400 (V): the digit after the series letter, "A2..."/"AB..." vs "A4..."/"B4..."."""
        return 200 if self.name.split("-")[1][1] in "2B" else 400

    @property
    def single_phase(self) -> bool:
        """The MX2-AB models are the 1-phase 200 V ones (section 2-3-1, Step 3)."""
        return self.name.split("-")[1].startswith("AB")


def _mx2(names: tuple[str, ...], product_code: int) -> tuple[Model, ...]:
    # Product name and EDS file join the capacity codes of the models that share them:
    # "3G3AX-MX2-CRT-AB001_A2001-E" for the pair MX2-AB001-E / MX2-A2001-E (Table C-3).
    codes = "_".join(name.split("-")[1] for name in names)
    product_name = f"3G3AX-MX2-CRT-{codes}-E"
    return tuple(Model(name, Family.MX2, product_code, product_name, f"{product_name}.eds") for name in names)


def _rx(name: str, product_code: int) -> Model:
    product_name = f"3G3AX-RX-CRT-{name.split('-')[1]}-E"
    return Model(name, Family.RX, product_code, product_name, f"{product_name}.eds")


# Table 2 / Table C-3 (MX2): 27 model names on 21 rows of product codes.
_MX2_ROWS: tuple[tuple[tuple[str, ...], int], ...] = (
    (("MX2-AB001-E", "MX2-A2001-E"), 1800),
    (("MX2-AB002-E", "MX2-A2002-E"), 1801),
    (("MX2-AB004-E", "MX2-A2004-E"), 1802),
    (("MX2-AB007-E", "MX2-A2007-E"), 1804),
    (("MX2-AB015-E", "MX2-A2015-E"), 1806),
    (("MX2-AB022-E", "MX2-A2022-E"), 1807),
    (("MX2-A2037-E",), 1809),
    (("MX2-A2055-E",), 1811),
    (("MX2-A2075-E",), 1812),
    (("MX2-A2110-E",), 1813),
    (("MX2-A2150-E",), 1814),
    (("MX2-A4004-E",), 1822),
    (("MX2-A4007-E",), 1824),
    (("MX2-A4015-E",), 1826),
    (("MX2-A4022-E",), 1827),
    (("MX2-A4030-E",), 1828),
    (("MX2-A4040-E",), 1830),
    (("MX2-A4055-E",), 1831),
    (("MX2-A4075-E",), 1832),
    (("MX2-A4110-E",), 1833),
    (("MX2-A4150-E",), 1834),
)

# Table 3 / Table C-4 (RX): 34 models, one product code each.
_RX_ROWS: tuple[tuple[str, int], ...] = (
    ("RX-A2004-E", 2041), ("RX-A2007-E", 2042), ("RX-A2015-E", 2043), ("RX-A2022-E", 2044),
    ("RX-A2037-E", 2045), ("RX-A2055-E", 2046), ("RX-A2075-E", 2047), ("RX-A2110-E", 2048),
    ("RX-A2150-E", 2049), ("RX-A2185-E", 2050), ("RX-A2220-E", 2051), ("RX-A2300-E", 2052),
    ("RX-A2370-E", 2053), ("RX-A2450-E", 2054), ("RX-A2550-E", 2055),
    ("RX-A4004-E", 2068), ("RX-A4007-E", 2069), ("RX-A4015-E", 2070), ("RX-A4022-E", 2071),
    ("RX-A4040-E", 2072), ("RX-A4055-E", 2073), ("RX-A4075-E", 2074), ("RX-A4110-E", 2075),
    ("RX-A4150-E", 2076), ("RX-A4185-E", 2077), ("RX-A4220-E", 2078), ("RX-A4300-E", 2079),
    ("RX-A4370-E", 2080), ("RX-A4450-E", 2081), ("RX-A4550-E", 2082),
    ("RX-B4750-E", 2083), ("RX-B4900-E", 2084), ("RX-B411K-E", 2085), ("RX-B413K-E", 2086),
)

#: Every model, MX2 first, in the manual's order.
MODELS: tuple[Model, ...] = (
    *(m for names, code in _MX2_ROWS for m in _mx2(names, code)),
    *(_rx(name, code) for name, code in _RX_ROWS),
)

_BY_NAME: dict[str, Model] = {m.name: m for m in MODELS}


class UnknownModelError(NotFound, KeyError):
    """An inverter model name that Tables 2/3 do not list."""

    def __init__(self, name: str, near: list[str]) -> None:
        self.name = name
        self.near = near
        hint = f": did you mean {', '.join(near)}?" if near else ":"
        # A name nothing resembles still says where the valid ones are, as every unknown name does.
        listed = f"`cipstack models` lists the {len(MODELS)} models ({MODELS[0].name} to {MODELS[-1].name})"
        # NotFound's __str__ comes before KeyError's: the message plain, not its repr.
        super().__init__(f"unknown inverter model {name!r}{hint} {listed}")


def model(name: str) -> Model:
    """The model called ``name`` (case and surrounding blanks ignored), e.g. ``model("MX2-A2015-E")``."""
    key = name.strip().upper()
    found = _BY_NAME.get(key)
    if found is None:
        raise UnknownModelError(name, difflib.get_close_matches(key, _BY_NAME, n=5, cutoff=0.6))
    return found


def models_of(family: Family) -> tuple[Model, ...]:
    return tuple(m for m in MODELS if m.family is family)


def models_with_product_code(product_code: int) -> tuple[Model, ...]:
    """The models one product code stands for (two for the paired MX2 200 V models)."""
    return tuple(m for m in MODELS if m.product_code == product_code)


def eds_files(family: Family | None = None) -> tuple[str, ...]:
    """Each EDS file once, in the manual's order: one per product code."""
    seen: dict[str, None] = {}
    for m in MODELS:
        if family is None or m.family is family:
            seen.setdefault(m.eds_file)
    return tuple(seen)
