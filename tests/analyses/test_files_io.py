"""Files in and out (the file layout, docs: simulate): CSV and .mat time series, units in headers, SI by
default, encodings; the output grid ends at t_end; negative flag values."""

import numpy as np
import pytest
import scipy.io

import ema_casadi as ema
from conftest import REFERENCE
from ema_casadi.cli import build_parser, join_values, main
from ema_casadi.signals import Signal, SignalError, parse_signal

TEXT = REFERENCE.read_text()


def _csv(path):
    """(header, unit row, data) of a CSV the toolkit wrote."""
    lines = path.read_text(encoding="utf-8").splitlines()
    data = np.loadtxt(path, delimiter=",", skiprows=2, ndmin=2)
    return lines[0].split(","), lines[1].split(","), data


# -- the round trip ---------------------------------------------------------------------
def test_simulate_out_then_in_reproduces_the_command(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    flags = ["--t-end", "0.03", "--dt-out", "1e-4"]
    assert main(["simulate", str(REFERENCE), *flags, "--x-cmd", "step:1mm@0.01+sine:0.2mm@40", "--out",
                 "run.csv"]) == 0
    assert main(["simulate", str(REFERENCE), *flags, "--x-cmd", "run.csv:x_rod", "--out", "again.csv"]) == 0
    assert main(["simulate", str(REFERENCE), *flags, "--x-cmd", "run.csv:x_cmd", "--out", "same.csv"]) == 0
    capsys.readouterr()
    h1, _, d1 = _csv(tmp_path / "run.csv")
    h2, _, d2 = _csv(tmp_path / "again.csv")
    h3, _, d3 = _csv(tmp_path / "same.csv")
    assert h1 == h2 == h3
    t, x_cmd, x_rod = h1.index("time"), h1.index("x_cmd"), h1.index("x_rod")
    assert np.array_equal(d1[:, t], d2[:, t])
    # the second run's command is the first run's rod position, sample for sample
    assert np.abs(d2[:, x_cmd] - d1[:, x_rod]).max() <= 1e-12
    assert np.abs(d3[:, x_cmd] - d1[:, x_cmd]).max() <= 1e-12
    assert np.ptp(d1[:, x_rod]) > 5e-4  # a signal that moves, not a trivial zero


def test_csv_is_the_sdi_layout_and_exact(tmp_path, model_cache):
    model = model_cache()
    res = ema.simulate(model, 0.005, "step:1mm@0.001", dt=5e-6, dt_out=5e-5, solver="rk4")
    path = res.to_csv(tmp_path / "run.csv")
    header, units, data = _csv(path)
    assert header[0] == "time" and units[0] == "Unit:"
    assert header[1:] == res.columns()[1:]
    assert units[1:] == [model.units[c] for c in header[1:]]
    # %.17g: every float comes back bit for bit
    assert np.array_equal(data, res.table())
    # no temporary file left beside it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]


def test_mat_holds_one_struct_with_time_signals_and_units(tmp_path, model_cache):
    model = model_cache()
    res = ema.simulate(model, 0.005, "step:1mm@0.001", dt=5e-6, dt_out=5e-5, solver="rk4")
    path = res.to_mat(tmp_path / "run.mat")
    m = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    s = m["ema_sim"]
    assert np.array_equal(s.time, res.t)
    assert np.array_equal(s.x_rod, res["x_rod"]) and np.array_equal(s.i_q, res["i_q"])
    assert s.units.x_rod == "m" and s.units.time == "s" and s.units.f_ext == "N"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mat"]


def test_cli_writes_mat(tmp_path, capsys):
    out = tmp_path / "run.mat"
    assert main(["simulate", str(REFERENCE), "--t-end", "0.005", "--out", str(out)]) == 0
    capsys.readouterr()
    s = scipy.io.loadmat(out, squeeze_me=True, struct_as_record=False)["ema_sim"]
    assert s.time[-1] == 0.005 and len(s.x_rod) == len(s.time)


# -- reading tables ---------------------------------------------------------------------
@pytest.mark.parametrize(
    "text, kind, expected",
    [
        ("t,value\n0,0\n1,0.002\n", "length", 1e-3),             # SI by default
        ("time,x_cmd [mm]\n0,0\n1,2\n", "length", 1e-3),         # a unit in the header
        ("time [ms],x_cmd\n0,0\n1000,0.002\n", "length", 1e-3),  # the time in ms
        ("time,x_cmd\nUnit:,mm\n0,0\n1,2\n", "length", 1e-3),    # a Unit: row (SDI)
        ("time,x\nType:,double\nUnit:,um\nInterp:,linear\n0,0\n1,2000\n", "length", 1e-3),
        ("0,0\n1,0.002\n", "length", 1e-3),                      # no header: t, value in SI
        ("# a comment\ntime,f_ext [kN]\n0,0\n1,20\n", "force", 10e3),
        ("time,f_ext\n\n0,0\n\n1,20000\n", "force", 10e3),      # blank lines skipped
        ("time,x [%]\n0,0\n1,2\n", "length", 0.01 * 0.075),     # % of the stroke
    ],
)
def test_table_units(tmp_path, text, kind, expected):
    path = tmp_path / "sig.csv"
    path.write_text(text, encoding="utf-8")
    s = parse_signal(str(path), kind, bare="mm", stroke=0.075)
    assert s(np.array([0.5]))[0] == pytest.approx(expected, rel=1e-12)


def test_bare_numbers_in_a_file_are_si_even_where_the_flag_is_mm(tmp_path, capsys):
    path = tmp_path / "cmd.csv"
    path.write_text("time,x_cmd\n0,0.001\n1,0.001\n")
    out = tmp_path / "run.csv"
    assert main(["simulate", str(REFERENCE), "--t-end", "0.002", "--x-cmd", str(path), "--out", str(out)]) == 0
    capsys.readouterr()
    header, _, data = _csv(out)
    assert data[-1, header.index("x_cmd")] == 0.001  # 1 mm, not 1 m


def test_selector_picks_a_column_of_a_multi_column_table(tmp_path):
    path = tmp_path / "run.csv"
    path.write_text("time,x_cmd,f_ext\nUnit:,m,N\n0,0,0\n1,0.002,1000\n")
    assert parse_signal(f"{path}:f_ext", "force")(np.array([0.5]))[0] == 500.0
    assert parse_signal(f"{path}:x_cmd", "length")(np.array([0.5]))[0] == 1e-3
    with pytest.raises(SignalError, match="2 signal columns .*pick one with run.csv:COLUMN"):
        parse_signal(str(path), "length")
    with pytest.raises(SignalError, match="column 'f_ext': unit 'N' is not a length unit"):
        parse_signal(f"{path}:f_ext", "length")


def test_bom_is_accepted_in_tables_and_parameter_files(tmp_path, capsys):
    table = tmp_path / "bom.csv"
    table.write_bytes(b"\xef\xbb\xbftime,x_cmd [mm]\r\n0,0\r\n1,2\r\n")
    assert parse_signal(str(table), "length")(np.array([0.5]))[0] == pytest.approx(1e-3)
    toml = tmp_path / "bom.toml"
    toml.write_bytes(b"\xef\xbb\xbf" + TEXT.encode("utf-8"))
    assert ema.load_parameters(toml).screw.M == 3.0
    assert main(["simulate", str(toml), "--t-end", "0.001", "--x-cmd", str(table)]) == 0
    capsys.readouterr()


@pytest.mark.parametrize("data", [TEXT.replace("# CESA", "# CÉSA").encode("latin-1"), TEXT.encode("utf-16")],
                         ids=["latin-1", "utf-16"])
def test_a_parameter_file_that_is_not_utf8_is_one_line(tmp_path, data):
    path = tmp_path / "enc.toml"
    path.write_bytes(data)
    with pytest.raises(ema.ParameterError) as exc:
        ema.load_parameters(path)
    msg = str(exc.value)
    assert str(path) in msg and "UTF" in msg and "\n" not in msg


# -- the output grid --------------------------------------------------------------------
@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
def test_samples_end_exactly_at_t_end(model_cache, solver):
    model = model_cache()
    cmd = Signal.step(1e-3, 0.01)
    res = ema.simulate(model, 0.25, cmd, dt=5e-6, dt_out=0.1, solver=solver)
    assert res.t.tolist() == pytest.approx([0.0, 0.1, 0.2, 0.25], abs=1e-15)
    assert res.t[-1] == 0.25
    # the same instants as a finer grid that divides t_end
    fine = ema.simulate(model, 0.25, cmd, dt=5e-6, dt_out=0.05, solver=solver)
    tol = 0.0 if solver == "rk4" else 1e-10  # rk4 takes the same steps; cvodes restarts at 0.2 s
    assert abs(res["x_rod"][-1] - fine["x_rod"][-1]) <= tol
    assert abs(res["x_rod"][2] - fine["x_rod"][4]) <= tol


@pytest.mark.parametrize("solver", ["rk4", "cvodes"])
def test_dt_out_longer_than_t_end_gives_start_and_end(model_cache, solver):
    res = ema.simulate(model_cache(), 0.02, 0.0, dt=5e-6, dt_out=10.0, solver=solver)
    assert res.t.tolist() == [0.0, 0.02]


def test_a_large_dt_out_over_dt_costs_no_more_than_a_small_one(model_cache):
    model = model_cache()
    big = ema.simulate(model, 0.1, Signal.step(1e-3, 0.01), dt=5e-6, dt_out=0.05,
                       solver="rk4")  # 10000 steps per sample
    small = ema.simulate(model, 0.1, Signal.step(1e-3, 0.01), dt=5e-6, dt_out=1e-4, solver="rk4")
    assert big.t.tolist() == pytest.approx([0.0, 0.05, 0.1])
    assert big["x_rod"][-1] == small["x_rod"][-1]
    assert big.info["decimate"] == 10000 and big.info["steps"] == 20000


def test_hybrid_cvodes_tail_counts_its_switches(model_cache):
    model = model_cache(friction="hybrid")
    cmd = Signal.sine(0.2e-3, 5.0)
    whole = ema.simulate(model, 0.3, cmd, solver="cvodes", dt_out=0.01)
    tail = ema.simulate(model, 0.3, cmd, solver="cvodes", dt_out=0.04)  # 7 intervals, then 0.02 s
    assert tail.t[-1] == 0.3 and len(tail.t) == 9
    assert abs(tail["x_rod"][-1] - whole["x_rod"][-1]) < 1e-8
    assert abs(tail.info["mode_switches"] - whole.info["mode_switches"]) <= 2


def test_rk4_refuses_a_t_end_that_is_not_whole_steps(model_cache):
    with pytest.raises(ema.SimulationError, match=r"t_end 0.2 s is not a whole number of RK4 steps dt 3e-06 s"):
        ema.simulate(model_cache(), 0.2, dt=3e-6, solver="rk4", decimate=1)


# -- flags ------------------------------------------------------------------------------
def test_negative_values_follow_their_flags():
    parser, _ = build_parser()
    j = join_values
    assert j(["simulate", "--f-ext", "-30kN"], parser) == ["simulate", "--f-ext=-30kN"]
    assert j(["simulate", "--f-e", "-.5kN"], parser) == ["simulate", "--f-e=-.5kN"]  # a unique prefix
    assert j(["freqresp", "--loads", "-30kN,0"], parser) == ["freqresp", "--loads=-30kN,0"]
    assert j(["simulate", "--json", "-1"], parser) == ["simulate", "--json", "-1"]  # takes no value
    assert j(["simulate", "--x-cmd", "-step"], parser) == ["simulate", "--x-cmd", "-step"]  # not a number
    assert j(["simulate", "--", "--f-ext", "-1"], parser) == ["simulate", "--", "--f-ext", "-1"]


def test_a_pulling_load_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", str(REFERENCE), "--t-end", "0.002", "--f-ext", "-30kN", "--out", str(out)]) == 0
    assert main(["linearize", str(REFERENCE), "--f-ext", "-20kN", "--x-cmd", "-1mm", "--json"]) == 0
    capsys.readouterr()
    header, _, data = _csv(out)
    assert data[-1, header.index("f_ext")] == -30e3
