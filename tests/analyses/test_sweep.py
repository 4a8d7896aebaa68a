"""Sweeps and Monte Carlo: the same rows whoever runs them, draws that do not
depend on the sweep's size, failed runs as rows with their reason, and every metric of
the registry equal to the toolkit's single analysis of that run.

The sweeps are small (4-6 runs of 0.2 s, hybrid friction at RK4 1e-4 s: ~20 ms a run)
so that the pools' and the cluster's start-up dominates."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import trapezoid

import ema_casadi as ema
from ema_casadi.cli import main
from ema_casadi.sweeps import METRICS, SweepError, parse_sweep, sweep

SCENARIO = {"duration": 0.2, "x_cmd": "step:1mm@0.01", "solver": "rk4", "dt": 1e-4, "dt_out": 1e-3}
HYBRID = {"friction": "hybrid", "controller": "PI"}


def _grid_mc(samples=2):
    return {"sweep": {"seed": 11, "samples": samples}, "variants": HYBRID,
            "parameters": {"B": {"values": [2e-5, 3e-4]},
                           "F_seal": {"distribution": "uniform", "low": 0.5, "high": 1.5, "relative": True},
                           "C": {"distribution": "normal", "mean": 1.0, "std": 0.2, "low": 0.7, "high": 1.3,
                                 "relative": True},
                           "K_i_x": {"values": [3000.0]}},
            "scenario": SCENARIO, "metrics": {"step": {}, "hunting": {"from": 0.1}, "peak": {"signals": ["i_q"]}}}


def test_grid_and_monte_carlo_rows_are_the_same_on_one_two_workers_and_dask(params, tmp_path):
    """Bit-identical tables (compared as files: every number written with 17 digits)
    with 1 worker, 2 processes, 2 threads and a Dask LocalCluster."""
    distributed = pytest.importorskip("dask.distributed")
    spec = parse_sweep(_grid_mc(), params)
    assert len(spec.runs) == 4
    one = sweep(spec, tmp_path / "one.csv", jobs=1)
    assert one.info["failed"] == 0
    sweep(spec, tmp_path / "procs.csv", jobs=2)
    sweep(spec, tmp_path / "threads.csv", jobs=2, backend="threads")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster:
        sweep(spec, tmp_path / "dask.csv", scheduler=cluster.scheduler_address)
    ref = (tmp_path / "one.csv").read_bytes()
    for name in ("procs", "threads", "dask"):
        assert (tmp_path / f"{name}.csv").read_bytes() == ref, name
    # the grid is crossed with the draws, and every grid point sees the same draws
    rows = one.rows
    assert [r["B"] for r in rows] == [2e-5, 2e-5, 3e-4, 3e-4]
    assert [r["F_seal"] for r in rows[:2]] == [r["F_seal"] for r in rows[2:]]
    assert not list(tmp_path.glob(".*journal"))  # removed once the table is in place


def test_draws_do_not_depend_on_the_number_of_samples_and_keep_their_bounds(params):
    """Draw s of a parameter comes from its own generator ([seed, s, k]): the first
    draws of a larger sweep are the smaller sweep's; bounds hold (the normal's std of
    0.2 with bounds +-0.3 truncates about 13 % of the draws)."""
    small, big = parse_sweep(_grid_mc(2), params), parse_sweep(_grid_mc(40), params)
    assert [r.values for r in small.runs[:2]] == [r.values for r in big.runs[:2]]
    C = np.array([r.values["C"] for r in big.runs[:40]]) / params.screw.C
    F = np.array([r.values["F_seal"] for r in big.runs[:40]]) / params.friction.F_seal
    assert C.min() >= 0.7 and C.max() <= 1.3 and F.min() >= 0.5 and F.max() <= 1.5
    assert len(set(C)) == 40  # not clipped onto the bounds
    other = _grid_mc(2)
    other["sweep"]["seed"] = 12
    assert parse_sweep(other, params).runs[0].values != small.runs[0].values


def test_a_run_outside_the_envelope_is_a_failed_row_with_its_reason(params):
    """A 0.3 mm stroke under a 2 mm step: the rod passes stroke + 1 mm overtravel."""
    spec = parse_sweep({"variants": HYBRID, "parameters": {"stroke": {"values": [0.075, 3e-4]}},
                        "scenario": {**SCENARIO, "x_cmd": "step:2mm@0.01"}, "metrics": {"peak": {}}}, params)
    res = sweep(spec, jobs=1)
    ok, bad = res.rows
    assert ok["status"] == "ok" and abs(ok["peak_x_rod"] - 2e-3) < 5e-5
    assert bad["status"] == "failed" and np.isnan(bad["peak_x_rod"])
    assert "x_rod" in bad["reason"] and "envelope" in bad["reason"] and "at t = " in bad["reason"]
    assert res.summary()["failed"] == 1


def test_bad_descriptions_are_refused_before_any_run(params):
    cases = [
        ({"parameters": {"Bx": {"values": [1]}}}, "no parameter 'Bx'"),
        ({"parameters": {"B": {"distribution": "uniform", "low": 0, "high": 1e-4}}}, "seed"),
        ({"parameters": {"B": {"values": [-1e-3]}}}, "run 0"),
        ({"parameters": {"v_s": {"values": [1e-4]}}, "variants": {"friction": "hybrid"}}, "not read by the model"),
        ({"parameters": {"w_aw": {"values": [0.02]}}}, "w_aw: not read by the model: anti_windup = backcalc does not "
                                                       r"use it \(only clamping\)"),
        ({"metrics": {"stepp": {}}}, "did you mean 'step'"),
        ({"metrics": {"peak_temperature": {}}}, "thermal"),
        ({"scenario": {**SCENARIO, "dt": 3e-4}}, "whole number"),
        ({"metrics": {"energy": {}}}, "at least every 0.0001 s"),
    ]
    for change, text in cases:
        data = {"parameters": {"B": {"values": [2e-5]}}, "scenario": SCENARIO, "metrics": {"step": {}}, **change}
        with pytest.raises(SweepError, match=text):
            parse_sweep(data, params)


def _json(argv, capsys):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_every_metric_equals_the_single_analysis(params, tmp_path, capsys):
    """One run at non-nominal values (K_x, F_seal), every metric of the registry against
    the toolkit's own single analysis of a parameter file holding those values (the
    CLI's margins and sine stream), or an independent reduction of ema.simulate's
    result; the same code on the same numbers, so equal to the last bit (margins,
    sine stream) or to round-off (integrals: 1e-12 relative)."""
    values = {"K_x": 60.0, "F_seal": 200.0}
    lumped = {"thermal": "lumped", "friction": "hybrid"}
    metrics = {"step": {}, "hunting": {"from": 0.1}, "margins": {}, "bandwidth": {},
               "sine_stream": {"amplitude": 1e-3, "freqs": [5.0]}, "peak_temperature": {}, "energy": {},
               "peak": {"signals": ["i_q", "x_rod"]}, "maximum": {"signals": ["i_q", "x_rod"]}}
    assert set(metrics) == set(METRICS)
    scenario = {**SCENARIO, "dt_out": 1e-4}  # the energy integrates the kept samples: every step
    spec = parse_sweep({"variants": lumped, "parameters": {k: {"values": [v]} for k, v in values.items()},
                        "scenario": scenario, "metrics": metrics}, params)
    row = sweep(spec, jobs=1).rows[0]
    assert row["status"] == "ok", row["reason"]
    moved = params.replace(**values)
    model_file = moved.to_toml(tmp_path / "moved.toml")
    var = [a for k, v in lumped.items() for a in ("--variant", f"{k}={v}")]
    m = _json(["margins", str(model_file), *var], capsys)["loops"]
    for loop, lm in m.items():
        for k in ("gm_db", "gm_down_db", "pm_deg", "f_gc_hz", "f_pc_hz", "f_down_hz", "disk_margin"):
            want = math.nan if lm[k] is None else float(lm[k])  # None: no such crossover; JSON may carry "inf"
            got = row[f"margins_{loop}_{k}"]
            assert got == want or (math.isnan(want) and math.isnan(got)), (loop, k)
    fr = _json(["freqresp", str(model_file), *var, "--amplitudes", "1mm", "--freqs", "5"], capsys)["points"][0]
    assert row["sine_5Hz_gain_db"] == fr["gain_db"] and row["sine_5Hz_phase_deg"] == fr["phase_deg"]
    model = ema.build_model(moved, lumped)
    bw = ema.frequency.bandwidth(ema.closed_loop(model, ema.operating_point(model)))
    assert row["bandwidth_hz"] == bw
    res = ema.simulate(model, 0.2, "step:1mm@0.01", solver="rk4", dt=1e-4, dt_out=1e-4)
    t, x = res.t, res["x_rod"]
    assert row["step_overshoot"] == pytest.approx(max(0.0, x.max() / 1e-3 - 1), abs=1e-12)
    e = (x - res["x_cmd"])[t >= 0.1]
    assert row["hunting_amplitude_m"] == pytest.approx(0.5 * (e.max() - e.min()), rel=1e-12)
    assert row["peak_T_w_degC"] == res["T_w"].max() and row["peak_T_inv_degC"] == res["T_inv"].max()
    assert row["energy_in_J"] == pytest.approx(trapezoid(res["P_dc"], t), rel=1e-12)
    losses = sum(res[n] for n in model.outputs_of("loss"))
    assert row["energy_loss_J"] == pytest.approx(trapezoid(losses, t), rel=1e-12)
    # and the two close the energy balance (no load: input = losses + stored mechanical
    # and magnetic energy; the heat the losses make is E_th); measured 6.1e-3 of the input
    # over these 0.2 s (the trapezoid over 1e-4 s samples of the step's spikes), asserted 2e-2
    stored = res["E_stored"][-1] - res["E_stored"][0]
    assert abs(row["energy_in_J"] - row["energy_loss_J"] - stored) < 2e-2 * row["energy_in_J"]
    assert row["peak_i_q"] == np.abs(res["i_q"]).max() and row["peak_x_rod"] == np.abs(x).max()
    assert row["max_i_q"] == res["i_q"].max() and row["max_x_rod"] == x.max()


def test_the_table_written_reads_back_and_resume_takes_it(params, tmp_path):
    """A finished table is resumed without running anything; a journal without
    --resume is refused; one of another sweep is refused with --resume."""
    spec = parse_sweep(_grid_mc(1), params)
    out = tmp_path / "t.csv"
    first = sweep(spec, out, jobs=1)
    again = sweep(spec, out, jobs=1, resume=True)
    assert again.info["computed"] == 0 and again.rows == first.rows
    journal = tmp_path / ".t.csv.journal"
    journal.write_text('{"journal": "ema sweep", "version": 1, "fingerprint": "other"}\n')
    with pytest.raises(SweepError, match="--resume"):
        sweep(spec, out, jobs=1)
    with pytest.raises(SweepError, match="another sweep"):
        sweep(spec, out, jobs=1, resume=True)


def test_the_slurm_example_builds_its_cluster_and_job_script(capsys):
    """studies/sweep_slurm.py (docs: sweeps): dask-jobqueue builds the SLURMCluster here
    without SLURM, and its batch script asks for what the flags say and starts a Dask
    worker of this Python on the cluster's scheduler."""
    import importlib.util
    import signal

    # dask_jobqueue installs a SIGINT handler (sys.exit) when imported: put Python's own
    # back, or a later test in this process that expects KeyboardInterrupt gets SystemExit
    before = signal.getsignal(signal.SIGINT)
    try:
        pytest.importorskip("dask_jobqueue")
    finally:
        signal.signal(signal.SIGINT, before)

    path = Path(__file__).resolve().parents[2] / "studies" / "sweep_slurm.py"
    mod_spec = importlib.util.spec_from_file_location("sweep_slurm", path)
    mod = importlib.util.module_from_spec(mod_spec)
    mod_spec.loader.exec_module(mod)
    assert mod.main(["--print-script", "--cores", "8", "--memory", "16GB", "--walltime", "01:30:00",
                     "--queue", "short", "--account", "ema"]) == 0
    script = capsys.readouterr().out
    for line in ("#SBATCH -p short", "#SBATCH -A ema", "#SBATCH --cpus-per-task=8", "#SBATCH --mem=15G",
                 "#SBATCH -t 01:30:00"):
        assert line in script, line
    assert f"{sys.executable} -m distributed.cli.dask_worker tcp://" in script and "--nthreads 8" in script


def test_a_variant_list_is_a_grid_axis_and_a_column(params):
    """screw = ["elastic", "rigid"] crossed with two backlash values: four runs, the
    variant in its own column, each run on its own model (the rigid screw's rod moves
    like the elastic one's within the backlash and compliance: 1 mm step, 0.1 s, the
    peaks within 1e-3 relative; measured 2.2e-4, from the 0.08 mm larger gap)."""
    spec = parse_sweep({"variants": {"screw": ["elastic", "rigid"]}, "parameters": {"B": {"values": [2e-5, 1e-4]}},
                        "scenario": {**SCENARIO, "duration": 0.1, "solver": "cvodes", "dt": 1e-3},
                        "metrics": {"peak": {}}}, params)
    res = sweep(spec, jobs=1)
    assert res.columns[:3] == ["run", "screw", "B"]
    assert [(r["screw"], r["B"]) for r in res.rows] == [("elastic", 2e-5), ("elastic", 1e-4), ("rigid", 2e-5),
                                                        ("rigid", 1e-4)]
    peaks = res.column("peak_x_rod")
    assert res.info["failed"] == 0 and np.all(np.abs(peaks / peaks[0] - 1) < 1e-3), peaks
