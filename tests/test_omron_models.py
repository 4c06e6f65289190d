"""MX2/RX models and the option board identity: Tables 1-3, C-2, C-3 and C-4."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cipstack.devices.omron.models import (
    DEVICE_TYPE,
    INITIAL_CONSISTENCY_VALUE,
    MODELS,
    VENDOR_ID,
    Family,
    UnknownModelError,
    eds_files,
    model,
    models_of,
    models_with_product_code,
)


def test_identity_constants_of_table_c2():
    assert VENDOR_ID == 47          # "47 (OMRON Corporation)"
    assert DEVICE_TYPE == 2         # "2 (AC Drive)"
    assert INITIAL_CONSISTENCY_VALUE == 0


def test_option_board_models_of_table_1():
    assert Family.MX2.option_board == "3G3AX-MX2-CRT-E"
    assert Family.RX.option_board == "3G3AX-RX-CRT-E"


def test_counts_equal_the_tables_rows():
    # Table 2 lists 27 MX2 model names; Table C-3 puts them on 21 rows, one per product code and EDS file.
    assert len(models_of(Family.MX2)) == 27
    assert len({m.product_code for m in models_of(Family.MX2)}) == 21
    assert len(eds_files(Family.MX2)) == 21
    # Tables 3 and C-4: 34 RX models, each with its own product code and EDS file.
    assert len(models_of(Family.RX)) == 34
    assert len({m.product_code for m in models_of(Family.RX)}) == 34
    assert len(eds_files(Family.RX)) == 34
    assert len(MODELS) == 61
    assert len({m.name for m in MODELS}) == 61


@pytest.mark.parametrize(("name", "code", "product_name", "eds"), [
    ("MX2-AB001-E", 1800, "3G3AX-MX2-CRT-AB001_A2001-E", "3G3AX-MX2-CRT-AB001_A2001-E.eds"),
    ("MX2-A2001-E", 1800, "3G3AX-MX2-CRT-AB001_A2001-E", "3G3AX-MX2-CRT-AB001_A2001-E.eds"),
    ("MX2-A2007-E", 1804, "3G3AX-MX2-CRT-AB007_A2007-E", "3G3AX-MX2-CRT-AB007_A2007-E.eds"),
    ("MX2-AB022-E", 1807, "3G3AX-MX2-CRT-AB022_A2022-E", "3G3AX-MX2-CRT-AB022_A2022-E.eds"),
    ("MX2-A2037-E", 1809, "3G3AX-MX2-CRT-A2037-E", "3G3AX-MX2-CRT-A2037-E.eds"),
    ("MX2-A2150-E", 1814, "3G3AX-MX2-CRT-A2150-E", "3G3AX-MX2-CRT-A2150-E.eds"),
    ("MX2-A4004-E", 1822, "3G3AX-MX2-CRT-A4004-E", "3G3AX-MX2-CRT-A4004-E.eds"),
    ("MX2-A4030-E", 1828, "3G3AX-MX2-CRT-A4030-E", "3G3AX-MX2-CRT-A4030-E.eds"),
    ("MX2-A4150-E", 1834, "3G3AX-MX2-CRT-A4150-E", "3G3AX-MX2-CRT-A4150-E.eds"),
    ("RX-A2004-E", 2041, "3G3AX-RX-CRT-A2004-E", "3G3AX-RX-CRT-A2004-E.eds"),
    ("RX-A2550-E", 2055, "3G3AX-RX-CRT-A2550-E", "3G3AX-RX-CRT-A2550-E.eds"),
    ("RX-A4004-E", 2068, "3G3AX-RX-CRT-A4004-E", "3G3AX-RX-CRT-A4004-E.eds"),
    ("RX-A4040-E", 2072, "3G3AX-RX-CRT-A4040-E", "3G3AX-RX-CRT-A4040-E.eds"),
    ("RX-A4055-E", 2073, "3G3AX-RX-CRT-A4055-E", "3G3AX-RX-CRT-A4055-E.eds"),
    ("RX-B4750-E", 2083, "3G3AX-RX-CRT-B4750-E", "3G3AX-RX-CRT-B4750-E.eds"),
    ("RX-B411K-E", 2085, "3G3AX-RX-CRT-B411K-E", "3G3AX-RX-CRT-B411K-E.eds"),
    ("RX-B413K-E", 2086, "3G3AX-RX-CRT-B413K-E", "3G3AX-RX-CRT-B413K-E.eds"),
])
def test_rows_of_tables_2_3_c3_c4(name, code, product_name, eds):
    found = model(name)
    assert (found.name, found.product_code, found.product_name, found.eds_file) == (name, code, product_name, eds)
    assert found.family is (Family.MX2 if name.startswith("MX2") else Family.RX)


def test_paired_mx2_models_share_one_product_code():
    assert [m.name for m in models_with_product_code(1806)] == ["MX2-AB015-E", "MX2-A2015-E"]
    assert [m.name for m in models_with_product_code(1831)] == ["MX2-A4055-E"]
    assert models_with_product_code(1803) == ()     # Table 2 skips 1803, 1805, 1808, ...


def test_first_and_last_eds_files_in_manual_order():
    assert eds_files()[0] == "3G3AX-MX2-CRT-AB001_A2001-E.eds"
    assert eds_files()[20] == "3G3AX-MX2-CRT-A4150-E.eds"
    assert eds_files()[-1] == "3G3AX-RX-CRT-B413K-E.eds"
    assert len(eds_files()) == 55


def test_voltage_class_and_single_phase():
    assert model("MX2-AB004-E").single_phase and model("MX2-AB004-E").voltage_class == 200
    assert not model("MX2-A2004-E").single_phase and model("MX2-A2004-E").voltage_class == 200
    assert model("MX2-A4004-E").voltage_class == 400
    assert model("RX-B4900-E").voltage_class == 400
    assert model("RX-A2185-E").voltage_class == 200


def test_lookup_ignores_case_and_blanks():
    assert model("  rx-a4055-e ") is model("RX-A4055-E")


def test_unknown_model_lists_near_matches():
    with pytest.raises(KeyError) as caught:
        model("MX2-A2016-E")
    error = caught.value
    assert isinstance(error, UnknownModelError)
    assert "MX2-A2015-E" in error.near
    assert "MX2-A2015-E" in str(error)
    # The RX has no 3 kW 400 V model (Table 3), the MX2 has (Table 2).
    with pytest.raises(UnknownModelError) as caught:
        model("RX-A4030-E")
    assert "MX2-A4030-E" in caught.value.near or "RX-A4040-E" in caught.value.near


def test_unknown_model_without_near_match():
    with pytest.raises(UnknownModelError) as caught:
        model("ACG-ET2")
    assert caught.value.near == []
    assert str(caught.value) == ("unknown inverter model 'ACG-ET2': `cipstack models` lists the 61 models "
                                 "(MX2-AB001-E to RX-B413K-E)")


@given(st.sampled_from(MODELS))
def test_names_derive_from_the_option_board(found):
    prefix = f"3G3AX-{found.family.value}-CRT-"
    assert found.product_name.startswith(prefix) and found.product_name.endswith("-E")
    assert found.eds_file == found.product_name + ".eds"
    assert found.name.split("-")[1] in found.product_name
    assert model(found.name.lower()) is found


@given(st.text(max_size=12))
def test_any_other_name_is_refused(text):
    if text.strip().upper() in {m.name for m in MODELS}:
        return
    with pytest.raises(KeyError):
        model(text)
