"""The reports' one number formatting (``signals.format_quantity``): SI in, the unit an
engineer reads out, round-off printed as 0; and the commands' text reports use it (no
SI length or bare exponent where a reading in mm, µm or A belongs)."""

from __future__ import annotations

import math

import pytest

from ema_casadi.signals import (
    ENGINEERING,
    NOISE,
    column_unit,
    format_fixed,
    format_number,
    format_quantity,
    in_unit,
    is_noise,
    unit_text,
)


@pytest.mark.parametrize("value, si, text", [
    (5.523e-6, "m", "5.523 µm"), (0.0099841, "m", "9.984 mm"), (1e-3, "m", "1 mm"), (0.088322, "m/s", "88.32 mm/s"),
    (15e3, "N", "15 kN"), (150.0, "N", "150 N"), (0.1397, "s", "139.7 ms"), (2.0, "s", "2 s"),
    (8.2556, "A", "8.256 A"), (math.pi / 6, "rad", "30°"), (2.4e8, "N/m", "240 N/µm"), (0.3, "Wb", "0.3 Wb"),
    (0.0012, "kg*m^2", "0.0012 kg·m²"), (200.0, "N*s/m", "200 N·s/m"),
    (1234.5, "W", "1.234 kW"), (float("inf"), "A", "inf A"), (-2e-3, "m", "-2 mm"),
])
def test_each_kind_is_printed_in_its_engineering_unit(value, si, text):
    """The rung is the largest one the magnitude reaches (1 mm is mm, 0.99 mm is µm);
    the conversion is the unit's size (a µm is 1e-6 m, a degree pi/180 rad)."""
    assert format_quantity(value, si) == text


@pytest.mark.parametrize("value, si", [(-2.6809e-17, "A"), (3.8632e-32, "A"), (-4e-16, "m"), (1e-13, "N")])
def test_round_off_is_printed_as_zero(value, si):
    """The values the issue found printed (``-2.6809e-17``, ``3.8632e-32 A``): below
    ``NOISE`` of the reference unit (1e-12 of a mm, A, N) they read 0."""
    assert is_noise(value, si)
    assert format_quantity(value, si).split()[0] == "0"


def test_the_noise_floor_spares_real_small_readings():
    """A 0.01 µm ripple, a 1 nA leakage and a 1e-12 x limit are readings, above the floor
    (NOISE x 1 mm = 1e-15 m); the floor scales with the size the value is read against."""
    assert format_quantity(1e-8, "m") == "0.01 µm"
    assert format_quantity(1e-9, "A") == "1e-09 A"
    assert not is_noise(1e-6, "A", scale=1.0) and is_noise(1e-6, "A", scale=1e-5 / NOISE)
    assert format_number(-2.6809e-17) == "0" and format_number(0.505) == "0.505"
    assert format_fixed(-0.0004, 3) == "0.000" and format_fixed(-0.0006, 3) == "-0.001"
    assert format_number(float("nan")) == "nan" and format_number(-float("inf")) == "-inf"


def test_a_column_keeps_one_unit_chosen_by_its_largest_value():
    assert column_unit("m", [2e-6, 9.2e-3]) == ("mm", 1e-3)
    assert column_unit("m", [2e-6, 9e-4]) == ("µm", 1e-6)
    assert column_unit("m", [float("nan"), 2e-3]) == ("mm", 1e-3)
    assert column_unit("Wb", [0.3]) == ("Wb", 1.0)
    assert column_unit("m", [0.0, -1e-19]) == ("mm", 1e-3) and format_quantity(0.0, "N") == "0 kN"
    assert in_unit(2e-6, 1e-3, si_unit="m") == "0.002" and in_unit(-1e-20, 1e-3, si_unit="m") == "0"
    assert format_quantity(0.0099841, "m", unit="µm") == "9984 µm"
    with pytest.raises(ValueError, match="'cm' is not one of mm, µm"):
        format_quantity(1.0, "m", unit="cm")


def test_every_ladder_runs_from_large_to_small_and_ends_open():
    """Each ladder's rungs fall, and its last takes every smaller value (lowest 0)."""
    for si, ladder in ENGINEERING.items():
        lows = [low for _, _, low in ladder]
        assert lows == sorted(lows, reverse=True) and lows[-1] == 0.0, si


def test_units_are_written_as_read():
    assert [unit_text(u) for u in ("N*s/m", "kg*m^2", "degC", "1", "V/(A*s)")] == \
        ["N·s/m", "kg·m²", "°C", "", "V/(A·s)"]
