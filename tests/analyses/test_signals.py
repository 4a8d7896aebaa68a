"""Signal syntax (docs: simulate) and the symbolic/NumPy forms agreeing."""

import casadi as ca
import numpy as np
import pytest

from ema_casadi.signals import Signal, SignalError, parse_signal


@pytest.mark.parametrize(
    "text, t, expected",
    [
        ("step:1mm@0.01", [0.0, 0.00999, 0.01, 1.0], [0, 0, 1e-3, 1e-3]),
        ("step:0.5%", [0.0], [0.5 / 100 * 0.075]),
        ("ramp:80mm/s@0.5", [0.4, 0.75], [0.0, 0.02]),
        ("sine:2mm@5Hz", [0.1, 0.025], [0.0, 2e-3 * np.sin(2 * np.pi * 5 * 0.025)]),
        ("0.3", [0.0, 1.0], [0.3e-3, 0.3e-3]),
        ("step:1mm@0.01+sine:0.375mm@1@0.5", [0.75], [1e-3 + 0.375e-3]),
    ],
)
def test_parse_lengths(text, t, expected):
    s = parse_signal(text, "length", bare="mm", stroke=0.075)
    np.testing.assert_allclose(s(np.array(t)), expected, atol=1e-15)


def test_forces_and_chirp():
    assert parse_signal("10kN", "force")(np.array([0.0]))[0] == 10e3
    s = parse_signal("chirp:1mm@1-11", "length", bare="mm", duration=2.0)
    # instantaneous frequency f0 + (f1-f0) t/T: phase 2 pi (t + 2.5 t^2)
    t = np.array([0.3, 1.7])
    np.testing.assert_allclose(s(t), 1e-3 * np.sin(2 * np.pi * (t + 2.5 * t**2)))


def test_csv_table(tmp_path):
    # a table is SI whatever the flag's bare unit (the file layout, docs: simulate); a header may name one
    path = tmp_path / "cmd.csv"
    path.write_text("t,value\n0,0\n1,2e-3\n2,2e-3\n")
    s = parse_signal(str(path), "length", bare="mm")
    np.testing.assert_allclose(s(np.array([0.5, 1.5, 3.0])), [1e-3, 2e-3, 2e-3])
    assert s.breakpoints() == [0.0, 1.0, 2.0]
    path.write_text("time [ms],x_cmd [mm]\n0,0\n1000,2\n2000,2\n")
    s = parse_signal(str(path), "length", bare="mm")
    np.testing.assert_allclose(s(np.array([0.5, 1.5, 3.0])), [1e-3, 2e-3, 2e-3])
    assert s.breakpoints() == [0.0, 1.0, 2.0]


def test_symbolic_equals_numpy():
    s = (Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5) + Signal.chirp(1e-4, 1, 5, 1.0)
         + Signal.table([0, 1], [0, 1e-3]))
    t = ca.SX.sym("t")
    f = ca.Function("s", [t], [s.sym(t)])
    grid = np.linspace(0, 1.2, 37)
    np.testing.assert_allclose(np.asarray(f(grid.reshape(1, -1))).ravel(), s(grid), rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("bad", ["stp:1mm", "sine:1mm", "sine:1mm@-2", "step:1furlong", "chirp:1mm@5", "", "step:1mm@"])
def test_bad_signals_raise_one_line(bad):
    with pytest.raises(SignalError) as exc:
        parse_signal(bad, "length", bare="mm", duration=1.0)
    assert "\n" not in str(exc.value)


def test_bad_csv(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("t,value\n0,0\n0,1\n")
    with pytest.raises(SignalError, match="increase strictly"):
        parse_signal(str(path), "length")
