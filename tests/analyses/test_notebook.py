"""Results in a notebook: ``plot()`` returns a matplotlib Figure (a path writes the PNG
instead), ``to_pandas()`` gives the same numbers as the result, and the reprs are one
short line."""

import tomllib

import numpy as np
import pytest
from matplotlib.figure import Figure

import ema_casadi as ema
from conftest import assert_glance

pd = pytest.importorskip("pandas")


@pytest.fixture(scope="module")
def run(model_cache):
    return ema.simulate(model_cache(), 0.05, ema.Signal.step(1e-3, 0.01), 5e3)


def test_a_simulation_plots_and_converts(run, tmp_path):
    fig = run.plot(signals=["x_rod", "x_cmd", "F_in"])
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # one panel per unit: m, N
    assert {line.get_label() for line in fig.axes[0].lines} == {"x_rod", "x_cmd"}
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_ydata(), run["x_rod"] * 1e3)  # mm on the axis
    assert isinstance(run.plot(), Figure)
    assert run.plot(path=tmp_path / "r.png") == tmp_path / "r.png" and (tmp_path / "r.png").stat().st_size > 1000
    with pytest.raises(KeyError, match="no signal 'x_rood'"):
        run.plot(signals=["x_rood"])
    frame = run.to_pandas()
    assert frame.index.name == "time" and list(frame.columns) == run.columns()[1:]
    np.testing.assert_array_equal(frame.index.to_numpy(), run.t)
    np.testing.assert_array_equal(frame["x_rod"].to_numpy(), run["x_rod"])
    assert frame.attrs["units"]["F_in"] == "N"
    text = repr(run)
    assert text.startswith("SimResult(") and "\n" not in text and len(text) < 200 and "solver=rosenbrock" in text
    assert "<table>" in run._repr_html_()


def test_a_frequency_response_plots_and_converts():
    fr = ema.sine_stream(ema.load_parameters(), [1e-3], [1.0, 4.0], jobs=1)
    fig = fr.plot()
    assert isinstance(fig, Figure)
    frame = fr.to_pandas()
    assert len(frame) == 2 and list(frame["freq_Hz"]) == [1.0, 4.0]
    np.testing.assert_array_equal(frame["gain_db"].to_numpy(), fr.data["gain_db"].ravel())
    assert repr(fr).startswith("FreqResponse(") and "converged=2 of 2" in repr(fr)


def test_a_sweep_converts(tmp_path):
    data = tomllib.loads(ema.packaged_file("sweep_reference.toml").read_text())
    data["sweep"]["samples"] = 2
    data["metrics"] = {"peak": {"signals": ["x_rod"]}}
    from ema_casadi.sweeps import parse_sweep, sweep

    res = sweep(parse_sweep(data, ema.load_parameters(), "s"), jobs=1)
    frame = res.to_pandas()
    assert frame.index.name == "run" and len(frame) == 2
    np.testing.assert_array_equal(frame["peak_x_rod"].to_numpy(), res.column("peak_x_rod"))
    assert repr(res).startswith("SweepResult(") and "runs=2" in assert_glance(res)
    assert isinstance(res.plot(), Figure)


def test_a_mission_plots_and_converts(tmp_path):
    from ema_casadi.mission import load_mission, run_mission

    path = tmp_path / "m.toml"
    path.write_text('[mission]\nname = "m"\nT_start = 20.0\n\n[[segment]]\nname = "hold"\nduration = 2.0\n'
                    'x_cmd = "1mm"\nf_ext = "5kN"\nT_amb = 20.0\n')
    params = ema.load_parameters()
    res = run_mission(params, load_mission(path, params), dt=2e-4, dt_out=2e-4)
    assert isinstance(res.plot(), Figure)
    frame = res.to_pandas()
    assert frame.index.name == "time" and list(frame.index) == [0.0, 1.0, 2.0]
    assert frame.attrs["units"]["T_w"] == "degC"
    assert assert_glance(res).startswith("MissionResult(mission=m")
    assert res.info["solver"] == "rk4"  # the mission's hybrid friction sticks
