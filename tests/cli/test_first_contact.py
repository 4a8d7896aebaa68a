"""What a new user meets in the first hour: an installed package that works from any
folder, one default for each thing (solver, sample spacing, progress), and none of the
traps a first run used to fall into (each test names the one it guards against)."""

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import ema_casadi as ema
from conftest import REFERENCE
from ema_casadi.cli import main
from ema_casadi.simulation import progress_bar


def _ema(args, cwd, **kw):
    return subprocess.run([sys.executable, "-m", "ema_casadi.cli", *args], cwd=cwd, capture_output=True, text=True,
                          **kw)


# -- installed means usable ---------------------------------------------------------------
def test_the_packaged_reference_files_are_the_defaults_in_any_folder(tmp_path):
    from ema_casadi._util._resources import packaged_file, packaged_files

    assert {"cesa_ema.toml", "mission_regional.toml", "sweep_reference.toml"} <= set(packaged_files())
    assert packaged_file().read_bytes() == REFERENCE.read_bytes()  # one copy: the repository's models/
    proc = _ema(["margins", "--json"], tmp_path)  # an empty folder: no models/ here
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["model"].endswith("cesa_ema.toml")
    version = _ema(["--version"], tmp_path)
    assert version.returncode == 0 and version.stdout.strip() == f"ema_casadi {ema.__version__}"
    assert ema.load_parameters().source == str(packaged_file())


def test_a_path_given_is_read_as_given(tmp_path, capsys):
    assert main(["margins", "cesa_ema.toml"]) == 2  # not in the working folder: not the packaged one
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cesa_ema.toml" in err


# -- one default sample spacing and the fast solver by default ----------------------------
def test_one_dt_out_default_for_the_api_and_the_cli(tmp_path, model_cache):
    """1e-4 s whatever the solver; the README's 1 s example no longer writes every 10 us step."""
    model = model_cache()
    for solver in ("auto", "rk4", "cvodes", "rosenbrock"):
        r = ema.simulate(model, 0.01, 1e-3, solver=solver)
        assert len(r.t) == 101 and np.allclose(np.diff(r.t), 1e-4, rtol=1e-9, atol=0), solver
    out = tmp_path / "run.csv"
    assert main(["simulate", "--t-end", "0.01", "--out", str(out), "--json", "--no-progress"]) == 0
    assert len(out.read_text().splitlines()) == 2 + 101


def test_auto_picks_the_compiled_solver_the_model_needs_and_says_so(model_cache):
    smooth = ema.simulate(model_cache(), 0.01, 1e-3)
    assert smooth.info["solver"] == "rosenbrock" and smooth.info["solver_requested"] == "auto"
    assert smooth.info["tolerance"] == {"rtol": ema.simulation.AUTO_RTOL, "atol": ema.simulation.AUTO_ATOL}
    hybrid = ema.simulate(model_cache(friction="hybrid"), 0.01, 1e-3)
    assert hybrid.info["solver"] == "rk4" and hybrid.info["tolerance"]["dt"] == 1e-5
    assert hybrid.info["tolerance"]["dt_max"] > 1e-5  # RK4's stability limit on the model (rk4_step_limit)
    assert "stick" in hybrid.info["solver_reason"]
    zoh = ema.simulate(model_cache(), 0.01, 1e-3, zoh=True)
    assert zoh.info["solver"] == "rk4"
    # auto on the continuous model agrees with a tight CVODES run to its tolerance: the
    # difference measured 1.6e-9 m on this 1 mm step; asserted 1e-8 m (x6), 1 % of 1 um
    tight = ema.simulate(model_cache(), 0.01, 1e-3, solver="cvodes", rtol=1e-10, atol=1e-13)
    assert np.abs(smooth["x_rod"] - tight["x_rod"]).max() < 1e-8


def test_the_cli_reports_the_choice_in_json(tmp_path):
    proc = _ema(["simulate", "--t-end", "0.01", "--json"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    r = json.loads(proc.stdout)
    assert r["solver"] == "rosenbrock" and r["solver_requested"] == "auto" and set(r["tolerance"]) == {"rtol", "atol"}


# -- --from-trim ---------------------------------------------------------------------------
def test_from_trim_starts_at_the_operating_point_of_the_first_inputs(model_cache, tmp_path):
    """A 30 kN load from t = 0: from rest it knocks the rod back by a quarter of a mm;
    from the trimmed point the rod holds still (an equilibrium: measured 1e-22 m)."""
    model = model_cache()
    rest = ema.simulate(model, 0.05, 0.0, 30e3)
    trim = ema.simulate(model, 0.05, 0.0, 30e3, from_trim=True)
    assert np.abs(rest["x_rod"]).max() > 0.2e-3
    assert np.abs(trim["x_rod"]).max() < 1e-9
    with pytest.raises(ema.SimulationError, match="x0 or from_trim"):
        ema.simulate(model, 0.05, 0.0, 30e3, from_trim=True, x0=model.x0())
    proc = _ema(["simulate", "--f-ext", "30kN", "--x-cmd", "0", "--t-end", "0.05", "--from-trim", "--json"], tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert abs(json.loads(proc.stdout)["final"]["x_rod"]) < 1e-9


# -- progress: one convention, no carriage returns into a log ------------------------------------
def test_progress_into_a_log_is_whole_lines(capsys):
    for k in range(101):
        progress_bar(k / 100, True, "unit-test", f"{k} of 100")
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.splitlines()
    assert len(lines) == 11 and lines[0].startswith("unit-test [") and "100.0%" in lines[-1]  # one per tenth
    progress_bar(0.5, False, "unit-test")
    assert capsys.readouterr().err == ""


def test_progress_is_off_by_default_when_stderr_is_not_a_terminal(tmp_path):
    quiet = _ema(["simulate", "--t-end", "0.01"], tmp_path)
    loud = _ema(["simulate", "--t-end", "0.01", "--progress"], tmp_path)
    assert quiet.returncode == loud.returncode == 0
    assert quiet.stderr == "" and "simulate [" in loud.stderr and "\r" not in loud.stderr


# -- --variant blames --variant -----------------------------------------------------------------
def test_a_wrong_variant_flag_blames_the_flag(capsys):
    assert main(["margins", "--variant", "motor=bldc"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--variant: unknown motor variant 'bldc'" in err and ".toml" not in err
    with pytest.raises(ema.ParameterError, match=r"^variants: unknown motor variant 'bldc'"):
        ema.build_model(ema.load_parameters(REFERENCE, {"motor": "bldc"}))


# -- envelope messages ----------------------------------------------------------------------------
def test_an_envelope_message_shows_the_value_beyond_its_bound():
    from ema_casadi.simulation._envelope import _distinct

    assert _distinct(0.0760004, 0.076) == ("0.0760004", "0.076")
    assert _distinct(-0.07612, 0.076) == ("-0.07612", "0.076")
    assert _distinct(1234.0, 1000.0) == ("1234", "1000")


def test_a_run_past_the_stroke_reads_differently_from_its_bound(model_cache):
    import re

    with pytest.raises(ema.RunFailed) as exc:
        ema.simulate(model_cache(), 2.0, ema.Signal.ramp(0.08))  # 80 mm/s: past the 75 mm stroke at ~0.95 s
    m = re.search(r"= (-?[0-9.e+-]+) m left its physical envelope \|\w+\| <= ([0-9.e+-]+) m", str(exc.value))
    assert m, str(exc.value)
    assert m.group(1).lstrip("-") != m.group(2) and abs(float(m.group(1))) > float(m.group(2))


# -- parameter files: units like the flags, only the tables the variants read ----------------------
def _reference_without(tables, **replace):
    import re

    out, skip = [], False
    for line in REFERENCE.read_text().splitlines():
        head = re.match(r"^\[(\w+)\]", line)
        if head:
            skip = head.group(1) in tables
        if not skip:
            for key, text in replace.items():
                if line.startswith(f"{key} = "):
                    line = f"{key} = {text}"
            out.append(line)
    return "\n".join(out) + "\n"


def test_parameter_files_take_the_units_the_flags_take(tmp_path):
    ref = ema.load_parameters(REFERENCE)
    path = tmp_path / "units.toml"
    path.write_text(_reference_without((), B='"20 um"', F_seal='{ value = 0.15, unit = "kN" }',
                                       stroke='{ value = 75, unit = "mm" }', T_ref='"20 degC"'))
    p = ema.load_parameters(path)
    # the unit factors are powers of ten: the converted values equal the SI ones to rounding
    assert p.screw.B == pytest.approx(ref.screw.B, rel=1e-15) and p.actuator.stroke == pytest.approx(0.075, rel=1e-15)
    assert p.friction.F_seal == pytest.approx(150.0, rel=1e-15) and p.thermal.T_ref == 20.0
    path.write_text(_reference_without((), B='"20 kg"'))
    with pytest.raises(ema.ParameterError, match=r"\[screw\] B: '20 kg': unknown length unit 'kg'"):
        ema.load_parameters(path)
    path.write_text(_reference_without((), C='"240 kN/mm"'))
    with pytest.raises(ema.ParameterError, match=r"\[screw\] C: .*in its SI unit 'N/m'"):
        ema.load_parameters(path)


def test_a_file_without_the_newer_tables_serves_the_variants_it_can(tmp_path):
    """Written before [thermal], [endstop] and [airframe]: the default model builds and
    agrees with the full file's; a variant that reads a missing table names it."""
    path = tmp_path / "old.toml"
    path.write_text(_reference_without(("thermal", "endstop", "airframe")))
    old = ema.load_parameters(path)
    assert set(old.missing) == {"thermal", "endstop"}  # [airframe] has a default for every key
    a = ema.linearize(ema.build_model(old))
    b = ema.linearize(ema.build_model(ema.load_parameters(REFERENCE)))
    assert np.array_equal(a.A, b.A)  # the same numbers: the missing tables were never read
    for variant, table in (("endstop", "endstop"), ("thermal", "thermal")):
        value = {"endstop": "elastic", "thermal": "lumped"}[variant]
        with pytest.raises(ema.ParameterError, match=rf"old.toml: missing table \[{table}\] .* {variant} = {value}"):
            ema.build_model(old, {variant: value})


# -- the default sweep: step metrics over the step's window ----------------------------------------
def test_the_default_sweeps_step_metrics_are_the_steps():
    """The packaged sweep (a step, then a sine from 0.5 s): overshoot and settling of the
    step, finite in every run; every metric has values; the figure has no empty panel."""
    import tomllib

    from ema_casadi._util._resources import packaged_file
    from ema_casadi.sweeps import parse_sweep, sweep

    data = tomllib.loads(packaged_file("sweep_reference.toml").read_text())
    data["sweep"]["samples"] = 3
    spec = parse_sweep(data, ema.load_parameters(), "sweep_reference.toml (3 samples)")
    res = sweep(spec, jobs=1)
    assert res.info["failed"] == 0
    over = res.column("step_overshoot")
    settle = res.column("step_settling_time_s")
    # the 1 mm step of the reference set: ~1 % overshoot, settled (2 % band) within 0.1 s;
    # before, the window ran into the sine: 37 % "overshoot" and never settled
    assert (over < 0.1).all() and np.isfinite(settle).all() and (settle < 0.2).all()
    stats = res.summary()["statistics"]
    # a margin with no such crossover in any run is inf and its frequency undefined (the
    # position loop has no gain-reduction margin, the velocity loop no upper gain margin):
    # no statistic, n = 0
    none = {m for m in stats if not np.isfinite(res.column(m)).any()}
    assert all(s["n"] == 3 for m, s in stats.items() if m not in none), {m: s["n"] for m, s in stats.items()}
    assert all(stats[m]["n"] == 0 for m in none) and all(("margins" in m) for m in none), none


def test_the_sweep_figure_has_no_empty_panel_and_no_overlapping_text():
    import tomllib

    from ema_casadi._util._resources import packaged_file
    from ema_casadi.sweeps import parse_sweep, sweep

    data = tomllib.loads(packaged_file("sweep_reference.toml").read_text())
    data["sweep"]["samples"] = 4
    res = sweep(parse_sweep(data, ema.load_parameters(), "s"), jobs=1)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = res.plot()
    canvas = FigureCanvasAgg(fig)  # the figure is closed to pyplot: draw it on a canvas of its own
    canvas.draw()
    renderer = canvas.get_renderer()
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert visible and all(ax.has_data() for ax in visible)
    def drawn_ticks(axis):  # the locator also places ticks outside the view: not drawn
        lo, hi = sorted(axis.get_view_interval())
        return [t.label1 for t in axis.get_major_ticks() if lo <= t.get_loc() <= hi]

    boxes = []
    for ax in visible:
        texts = [ax.title, ax.xaxis.label, ax.yaxis.label, ax.xaxis.get_offset_text(), ax.yaxis.get_offset_text(),
                 *drawn_ticks(ax.xaxis), *drawn_ticks(ax.yaxis)]
        boxes += [(id(ax), t.get_window_extent(renderer)) for t in texts if t.get_visible() and t.get_text()]
    clashes = [(a, b) for i, (ia, a) in enumerate(boxes) for ib, b in boxes[i + 1:]
               if ia != ib and a.overlaps(b)]
    assert not clashes  # text of one panel never runs into another panel's


# -- sweeps started from a script without the __main__ guard ---------------------------------------
def test_an_unguarded_script_is_refused_before_any_worker_starts(tmp_path):
    script = tmp_path / "unguarded.py"
    body = """
        import ema_casadi as ema
        from ema_casadi._util._resources import packaged_file
        from ema_casadi.sweeps import load_sweep, sweep

        spec = load_sweep(packaged_file("sweep_reference.toml"), ema.load_parameters())
        sweep(spec, jobs=2)
        print("ran")
    """
    script.write_text(textwrap.dedent(body))
    proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1 and "ran" not in proc.stdout
    last = proc.stderr.strip().splitlines()[-1]
    assert "SweepError" in last and "unguarded.py, line 7" in last and 'if __name__ == "__main__":' in last
    guarded = tmp_path / "guarded.py"
    lines = textwrap.dedent(body).strip().splitlines()
    guarded.write_text("\n".join(lines[:4]) + "\n\nif __name__ == '__main__':\n" + "\n".join(
        "    " + line for line in lines[4:]) + "\n")
    from ema_casadi._util._parallel import _inside_main_guard

    assert _inside_main_guard(str(guarded), 8) and not _inside_main_guard(str(script), 7)


def test_the_check_passes_where_there_is_no_script():
    from ema_casadi._util._parallel import check_main_guard
    from ema_casadi.sweeps import SweepError

    check_main_guard(SweepError, "sweep(jobs=2)")  # pytest's __main__ is no user script calling sweep
