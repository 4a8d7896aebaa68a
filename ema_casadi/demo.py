"""The main job on a parameter set (``ema demo``): step and sine responses, Bode,
margins, nonlinear frequency-response map; PNGs and ``summary.md``/``summary.json``.

The output folder is assembled beside its place and moved in at the end
(:func:`ema_casadi._util._files.atomic_dir`): it appears whole or not at all, also when the
run fails or is interrupted. An existing folder is replaced whole, and refused if it
holds anything but :data:`DEMO_FILES` and the :data:`KEPT_FOLDERS` (so no other file is
ever removed)."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from ._util._files import atomic_dir, check_folder, write_text
from .model.assembly import build_model
from .model.params import Parameters
from .signals import Signal
from .simulation import simulate, step_response_metrics

__all__ = ["run_demo", "DEMO_FILES", "KEPT_FOLDERS"]

#: Subfolders of the demo's folder that belong to other commands (``ema mission``
#: writes into ``out/mission``): allowed there and kept when the demo replaces the folder.
KEPT_FOLDERS = ("mission",)

#: The files the demo writes into its folder.
DEMO_FILES = (
    "step_1mm.png", "step_20mm.png", "sine_30kN.png", "bode_closed_loop.png", "dynamic_stiffness.png", "margins.png",
    "fig14a.png", "fig14a.csv", "fig14b.png", "fig14b.csv", "summary.json", "summary.md", "pwm_vs_averaged.png",
    "mission_short.png", "mission_short.csv",
)


def _step_summary(t: np.ndarray, y: np.ndarray, y_final: float, t_step: float, band: float = 0.02) -> dict:
    """Rise time 10-90 % (s), overshoot (%), settling time into +-band (s) and final
    error (m) of a step of y_final at t_step.

    Parameters
    ----------
    t : ndarray
        Times (s).
    y : ndarray
        Rod position (m).
    y_final : float
        Step height (m).
    t_step : float
        Step time (s).
    band : float
        Settling band as a fraction of ``y_final`` (-).
    """
    on = t >= t_step
    m = step_response_metrics(t[on] - t_step, y[on] / y_final, band)
    return {"rise_time_s": m["rise_time_s"], "overshoot_pct": 100 * m["overshoot"],
            "settling_time_s": m["settling_time_s"], "final_error_m": float(y[-1] - y_final)}


def _simulations(model, out: Path, written: list) -> dict:
    from .plots._base import plot_simulation

    res = {}
    r = simulate(model, 0.15, Signal.step(1e-3, 0.01), solver="cvodes", dt=1e-4)
    res["step_1mm"] = _step_summary(r.t, r["x_rod"], 1e-3, 0.01)
    written.append(plot_simulation(r, out / "step_1mm.png", "1 mm step, no load"))
    r = simulate(model, 0.5, Signal.step(20e-3, 0.01), solver="cvodes", dt=1e-4)
    plateau = r["v_rod"][(r.t > 0.1) & (r.t < 0.2)]
    res["step_20mm"] = {**_step_summary(r.t, r["x_rod"], 20e-3, 0.01),
                        "slew_rate_mm_s": float(np.median(plateau) * 1e3)}
    written.append(plot_simulation(r, out / "step_20mm.png", "20 mm step: rate limited at 80 mm/s"))
    x_cmd = Signal.step(1e-3, 0.01) + Signal.sine(0.375e-3, 1.0, 0.5)
    r = simulate(model, 1.5, x_cmd, 30e3, solver="cvodes", dt=1e-4)
    losses = {k: float(np.trapezoid(r[k], r.t)) for k in model.outputs_of("loss")}
    res["sine_30kN"] = {"energy_in_J": float(np.trapezoid(r["P_dc"], r.t)), "losses_J": losses,
                        "peak_current_A": float(np.abs(r["i_q"]).max())}
    written.append(plot_simulation(r, out / "sine_30kN.png", "1 mm step + 0.375 mm 1 Hz sine against 30 kN"))
    return res


def _pwm_vs_averaged(params: Parameters, out: Path, written: list) -> dict:
    """The switched PWM bridge (every switching instant resolved, sampled ECU) against
    the averaged bridge (continuous ECU, CVODES): the rod driven at 40 mm/s against 20 kN
    for 60 ms."""
    from .plots._pwm import plot_pwm_vs_averaged

    pwm = build_model(params, {**params.variants, "inverter": "pwm", "motor": "pmsm"})
    avg = build_model(params, {**params.variants, "inverter": "ideal"})
    x_cmd, t_end = Signal.ramp(0.04), 0.06
    # every sub-interval (the switched waveforms), at simulate()'s step inside RK4's stability limit
    sw = simulate(pwm, t_end, x_cmd, 20e3, decimate=1)
    av = simulate(avg, t_end, x_cmd, 20e3, solver="cvodes", dt_out=2e-5)
    written.append(plot_pwm_vs_averaged(sw, av, out / "pwm_vs_averaged.png", int(params.motor.pp),
                                        f_sw=params.power.f_sw))
    E_sw, E_av = sw.energies(), av.energies()
    return {"rod_difference_m": float(abs(sw["x_rod"][-1] - av["x_rod"][-1])),
            "inverter_losses_J": {"pwm": E_sw["P_inv_cond"] + E_sw["P_inv_sw"],
                                  "averaged": E_av["P_inv_cond"] + E_av["P_inv_sw"]},
            "energy_in_J": {"pwm": E_sw["P_dc"], "averaged": E_av["P_dc"]},
            "wall_time_s": {"pwm": sw.info["wall_time"], "averaged": av.info["wall_time"]}}


def _frequency(model, out: Path, written: list) -> dict:
    """Small-signal Bode (no load and 30 kN), dynamic stiffness, margins of all loops."""
    from .frequency import bandwidth, bode, closed_loop, dynamic_stiffness, frequency_grid, loop_margins, modes
    from .linearisation import loop_model, operating_point
    from .plots._frequency import plot_bode, plot_loop_margins

    f = frequency_grid(0.1, 3e3, 100)
    curves, res = [], {"closed_loop": {}}
    for load in (0.0, 30e3):
        op = operating_point(model, f_ext=load)
        T = closed_loop(model, op)
        b = bode(T, f)
        b["label"] = f"x_rod/x_cmd, f_ext = {load / 1e3:g} kN"
        curves.append(b)
        at = {fx: (float(np.interp(fx, f, b["mag_db"])), float(np.interp(fx, f, b["phase_deg"])))
              for fx in (1, 2, 5, 10)}
        res["closed_loop"][f"{load / 1e3:g}kN"] = {
            "bandwidth_3db_hz": float(bandwidth(T)),
            "at_hz": {str(k): {"mag_db": v[0], "phase_deg": v[1]} for k, v in at.items()},
        }
    written.append(plot_bode(curves, out / "bode_closed_loop.png", title="closed loop x_rod/x_cmd (small signal)"))
    op0 = operating_point(model)
    K = dynamic_stiffness(model, op0, f)
    stiffness = {"freq_hz": f, "mag_db": K["mag_db"] - 120, "phase_deg": K["phase_deg"], "label": "-f_ext/x_rod"}
    written.append(plot_bode([stiffness], out / "dynamic_stiffness.png", title="dynamic stiffness (0 dB = 1 N/um)",
                             mag_label="stiffness (dB re 1 N/um)"))
    res["static_stiffness_N_per_m"] = float(K["magnitude"][0])
    m = loop_margins(model, op0)
    f_l = frequency_grid(1e-2, 1e5, 100)
    written.append(plot_loop_margins({k: (bode(loop_model(model, k, op0), f_l), v) for k, v in m.items()},
                                     out / "margins.png", title="open loop at each break (others closed)"))
    res["margins"] = {k: v.as_dict() for k, v in m.items()}
    res["drive_train_mode"] = modes(closed_loop(model, op0))[-1]
    return res


def _nonlinear_maps(params: Parameters, out: Path, written: list, progress: bool) -> dict:
    """The paper's Fig. 14a (amplitudes) and 14b (loads) by sine stream, with the
    predictions of the reference set (docs: physics): flatness at small amplitude, rate limiting at 10 %, load phase."""
    from .sinestream import paper_fig14a, paper_fig14b

    res = {}
    a, png_a = paper_fig14a(params, out, progress=progress)
    b, png_b = paper_fig14b(params, out, progress=progress)
    written += [png_a, out / "fig14a.csv", png_b, out / "fig14b.csv"]
    f = np.asarray(a.axes["frequency"])
    rows = {}
    for amp in a.axes["amplitude"]:
        c = a.curve(amplitude=amp)
        pct = amp / params.actuator.stroke * 100
        rows[f"{pct:g}%"] = {
            "max_dev_db_0.1_6Hz": float(np.abs(c["gain_db"][f <= 6.0]).max()),
            "gain_db_at": {str(fx): float(np.interp(fx, f, c["gain_db"])) for fx in (1.5, 2.5, 5.0)},
            "phase_deg_at_5Hz": float(np.interp(5.0, f, c["phase_deg"])),
        }
    res["fig14a"] = rows
    c0, c30 = b.curve(load=0.0), b.curve(load=30e3)
    fb = np.asarray(b.axes["frequency"])
    phase_diff = np.abs(c30["phase_deg"] - c0["phase_deg"])[fb <= 5.0]
    res["fig14b"] = {"max_phase_diff_deg_30kN_to_5Hz": float(phase_diff.max())}
    res["not_converged"] = len(a.not_converged()) + len(b.not_converged())
    res["wall_time_s"] = {"fig14a": a.info.get("wall_time"), "fig14b": b.info.get("wall_time")}
    return res


def run_demo(params: Parameters, out: str | Path = "out", progress: bool = True) -> dict:
    """Run the demo and write its files into the folder ``out``. Returns the summary dict.

    Parameters
    ----------
    params : Parameters
        Parameter set (its variants are the model's).
    out : str or Path
        Output folder: assembled beside it and moved into place at the end; an
        existing folder is replaced whole (refused, with
        :class:`~ema_casadi._util._files.OutputPathError`, if it holds other files than
        :data:`DEMO_FILES`).
    progress : bool
        Print a line per stage.
    """
    out = check_folder(out, DEMO_FILES, keep=KEPT_FOLDERS)
    t0 = time.perf_counter()
    model = build_model(params)
    written: list[Path] = []
    summary: dict = {"model": params.source, "variants": model.variants}

    def stage(name):
        if progress:
            print(f"[demo] {name} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr, flush=True)

    with atomic_dir(out, keep=KEPT_FOLDERS) as tmp:
        stage("time responses")
        summary["time_responses"] = _simulations(model, tmp, written)
        stage("switched PWM bridge against the averaged bridge")
        summary["pwm_vs_averaged"] = _pwm_vs_averaged(params, tmp, written)
        stage("linearisation, Bode, margins")
        fr = _frequency(model, tmp, written)
        summary["margins"] = fr.pop("margins")
        summary["small_signal"] = fr
        stage("nonlinear frequency-response maps (paper Fig. 14a/b)")
        summary["nonlinear_frequency_response"] = _nonlinear_maps(params, tmp, written, progress)
        stage("short flight mission through the thermal network")
        from .mission import demo_mission

        summary["mission"] = demo_mission(params, tmp, written)
        summary["wall_time_s"] = time.perf_counter() - t0
        summary["written"] = [str(out / Path(p).name) for p in written]
        _write_summary(summary, tmp)
    summary["written"] += [str(out / "summary.json"), str(out / "summary.md")]
    return summary


def _write_summary(summary: dict, out: Path) -> None:
    write_text(out / "summary.json", json.dumps(summary, indent=1, default=float))
    tr = summary["time_responses"]
    lines = [
        f"# ema_casadi demo — {summary['model']}",
        "",
        "Variants: " + ", ".join(f"{k}={v}" for k, v in summary["variants"].items()),
        "",
        "## Time responses",
        "",
        "| case | rise 10-90 % (ms) | overshoot (%) | settling ±2 % (ms) |",
        "|---|---|---|---|",
    ]
    for k in ("step_1mm", "step_20mm"):
        m = tr[k]
        lines.append(f"| {k} | {m['rise_time_s'] * 1e3:.1f} | {m['overshoot_pct']:.2f} | "
                     f"{m['settling_time_s'] * 1e3:.1f} |")
    lines += ["", f"Slew rate on the 20 mm step: {tr['step_20mm']['slew_rate_mm_s']:.2f} mm/s (limit 80).", ""]
    s = tr["sine_30kN"]
    lines += ["Against 30 kN (1 mm step + 0.375 mm, 1 Hz sine, 1.5 s): electrical input "
              f"{s['energy_in_J']:.1f} J, peak current {s['peak_current_A']:.1f} A; losses (J): "
              + ", ".join(f"{k[2:]} {v:.2f}" for k, v in s["losses_J"].items()), ""]
    pw = summary["pwm_vs_averaged"]
    lines += ["Switched PWM bridge (16 kHz, every switching instant) against the averaged bridge, 40 mm/s "
              f"against 20 kN for 60 ms (`pwm_vs_averaged.png`): rod {pw['rod_difference_m'] * 1e6:.2f} um apart; "
              f"inverter losses {pw['inverter_losses_J']['pwm']:.3f} J / {pw['inverter_losses_J']['averaged']:.3f} J, "
              f"input {pw['energy_in_J']['pwm']:.2f} J / {pw['energy_in_J']['averaged']:.2f} J.", ""]
    lines += ["## Small signal (Coulomb friction and backlash off, small-signal policy)", "",
              "| f_ext | -3 dB bandwidth (Hz) | 1 Hz | 2 Hz | 5 Hz | 10 Hz |", "|---|---|---|---|---|---|"]
    for load, c in summary["small_signal"]["closed_loop"].items():
        cells = [f"{v['mag_db']:.2f} dB / {v['phase_deg']:.1f}°" for v in c["at_hz"].values()]
        lines.append(f"| {load} | {c['bandwidth_3db_hz']:.1f} | " + " | ".join(cells) + " |")
    lines += ["", "| loop | GM (dB) | at (Hz) | gain-reduction margin (dB) | at (Hz) | PM (deg) | at (Hz) | "
              "gain crossovers (Hz: PM deg) | disk margin α | meets GM, gain-reduction margin ≥ 6 dB, PM ≥ 45° |",
              "|---|---|---|---|---|---|---|---|---|---|"]

    def hz(v):
        return "-" if v is None else f"{v:.3g}"

    for k, m in summary["margins"].items():
        gcs = ", ".join(f"{c['f_hz']:.3g}: {c['pm_deg']:.1f}" for c in m["gain_crossovers"]) or "-"
        lines.append(f"| {k} | {m['gm_db']:.1f} | {hz(m['f_pc_hz'])} | {m['gm_down_db']:.1f} | {hz(m['f_down_hz'])} | "
                     f"{m['pm_deg']:.1f} | {hz(m['f_gc_hz'])} | {gcs} | {m['disk_margin']:.2f} | "
                     f"{'yes' if m['meets_requirement'] else 'NO'} |")
    lines += ["", "GM: the gain may rise by that much; gain-reduction margin: it may fall by that much (only a "
              "conditionally stable loop has one; inf otherwise). PM: the smallest over every gain crossover.", ""]
    lines.append("")
    nl = summary["nonlinear_frequency_response"]
    lines += ["## Nonlinear frequency response (sine stream, paper Fig. 14)", "",
              "| amplitude | max deviation 0.1–6 Hz (dB) | 1.5 Hz (dB) | 2.5 Hz (dB) | 5 Hz (dB) | phase 5 Hz (deg) |",
              "|---|---|---|---|---|---|"]
    for amp, r in nl["fig14a"].items():
        g = r["gain_db_at"]
        lines.append(f"| {amp} | {r['max_dev_db_0.1_6Hz']:.2f} | {g['1.5']:.2f} | {g['2.5']:.2f} | {g['5.0']:.2f} | "
                     f"{r['phase_deg_at_5Hz']:.1f} |")
    lines += ["", f"Fig. 14b: largest phase difference between 30 kN and no load up to 5 Hz at 0.5 %: "
              f"{nl['fig14b']['max_phase_diff_deg_30kN_to_5Hz']:.1f}° (paper: < 10°). "
              f"Points not settled: {nl['not_converged']}.", ""]
    lines += ["## Files", ""] + [f"- `{Path(p).name}`" for p in summary["written"]]
    write_text(out / "summary.md", "\n".join(lines) + "\n")
