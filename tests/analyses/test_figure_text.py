"""No two texts of a figure run into each other: each figure the demo writes (and the
main plotting functions of the analyses) rendered from a short run, every drawn text's
box against every other's (``_text_overlap``: titles, labels, tick labels, legends,
annotations).

The figures are the package's own, written through their plot functions to a
temporary folder; the check runs on each figure as it is saved (the layout the PNG
gets). The runs are short (tens of milliseconds of simulated time, two-point sine
streams): the layout does not depend on the run's length, its texts do not either.
"""

from __future__ import annotations

import tomllib

import matplotlib.figure
import matplotlib.pyplot as plt
import numpy as np
import pytest
from _text_overlap import drawn_texts, overlaps

import ema_casadi as ema
from ema_casadi import Signal

#: A two-segment mission of the demo's kind (the demo flies 3 minutes; the figure is the same).
MISSION = """
[mission]
name = "figure check"
T_start = 40.0

[[segment]]
name = "take-off"
duration = 2.0
x_cmd = "step:-2mm@0.5"
f_ext = "step:-5kN@0.5"
T_amb = [35.0, 30.0]

[[segment]]
name = "cruise"
duration = 2.0
x_cmd = "-2mm+sine:0.3mm@0.5"
f_ext = "-5kN"
T_amb = 30.0
"""


@pytest.fixture
def checked(monkeypatch):
    """The overlaps of every figure saved while the test runs, by file name."""
    found: dict = {}
    save = matplotlib.figure.Figure.savefig

    def savefig(self, fname, *args, **kwargs):
        kwargs.setdefault("dpi", 110)
        self.set_dpi(kwargs["dpi"])  # the layout at the resolution of the PNG
        found[str(fname)] = overlaps(self)
        return save(self, fname, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return found


def _clean(found: dict, count: int):
    assert len(found) == count, sorted(found)
    bad = {name: pairs for name, pairs in found.items() if pairs}
    assert not bad, bad


def test_the_checker_sees_overlapping_text_and_passes_separate_text():
    """Two titles on one line of a figure overlap; the same titles in two rows do not;
    hidden and empty texts are not drawn and so not counted."""
    fig, axes = plt.subplots(1, 2, figsize=(4, 2))
    long = "a title long enough to run into the next axes' title"
    for ax in axes:
        ax.set_title(long)
    assert overlaps(fig) == [f"{long!r} / {long!r}"]
    for ax in axes:
        ax.set_title("short")
    fig.text(0.5, 0.5, "hidden", visible=False)
    fig.text(0.5, 0.5, "")
    assert overlaps(fig) == []
    assert "hidden" not in [t.get_text() for t, _ in drawn_texts(fig)]
    plt.close(fig)


@pytest.mark.parametrize("apart_pt, caught", [(2.0, True), (10.0, False)])
def test_two_free_texts_side_by_side_keep_a_gap(apart_pt, caught):
    """Two titles 2 pt apart read as one line (caught), 10 pt apart as two (GAP 3 pt a side)."""
    fig = plt.figure(figsize=(4, 1), dpi=110)
    first = fig.text(0.05, 0.5, "velocity loop: GM inf dB")
    [(_, box)] = drawn_texts(fig)
    x = (box.x1 + apart_pt * fig.dpi / 72.0) / fig.bbox.width
    fig.text(x, 0.5, "current loop: GM 17.9 dB")
    assert bool(overlaps(fig)) is caught, (first, overlaps(fig))
    plt.close(fig)


@pytest.fixture(scope="module")
def reference():
    params = ema.load_parameters()
    return params, ema.build_model(params)


def test_the_demo_s_time_and_frequency_figures(reference, checked, tmp_path):
    """step_*.png, sine_30kN.png, bode_closed_loop.png, dynamic_stiffness.png and
    margins.png (whose loop titles ran into each other) as the demo draws them."""
    from ema_casadi import demo
    from ema_casadi.plots._base import plot_simulation

    params, model = reference
    r = ema.simulate(model, 0.03, Signal.step(1e-3, 0.01), solver="cvodes", dt=1e-4)
    for name, title in (("step_1mm", "1 mm step, no load"), ("step_20mm", "20 mm step: rate limited at 80 mm/s"),
                        ("sine_30kN", "1 mm step + 0.375 mm 1 Hz sine against 30 kN")):
        plot_simulation(r, tmp_path / f"{name}.png", title)
    demo._frequency(model, tmp_path, [])
    _clean(checked, 6)


def test_the_demo_s_pwm_mission_and_sine_stream_figures(reference, checked, tmp_path):
    """pwm_vs_averaged.png, mission_short.png and the Fig. 14 maps' figure."""
    from ema_casadi.mission import parse_mission, run_mission
    from ema_casadi.plots._pwm import plot_pwm_vs_averaged

    params, _ = reference
    pwm = ema.build_model(params, {**params.variants, "inverter": "pwm", "motor": "pmsm"})
    avg = ema.build_model(params, {**params.variants, "inverter": "ideal"})
    sw = ema.simulate(pwm, 0.004, Signal.ramp(0.04), 20e3, dt=5e-7, decimate=1)  # inside its RK4 limit
    av = ema.simulate(avg, 0.004, Signal.ramp(0.04), 20e3, solver="cvodes", dt_out=2e-5)
    plot_pwm_vs_averaged(sw, av, tmp_path / "pwm_vs_averaged.png", int(params.motor.pp), f_sw=params.power.f_sw)
    run_mission(params, parse_mission(tomllib.loads(MISSION), params, "figure check")).plot(tmp_path / "m.png")
    stroke = params.actuator.stroke
    fr = ema.sine_stream(params, amplitudes=[0.005 * stroke, 0.1 * stroke], freqs=[1.0, 5.0])
    fr.plot(tmp_path / "fig14a.png", title="Fig. 14a", stroke=stroke)
    _clean(checked, 3)


def test_the_analyses_figures(reference, checked, tmp_path):
    """The optimal move, the fault study's coverage, the describing function's Nichols
    chart and a periodic orbit, each from a short run."""
    from ema_casadi.faults import run_faults
    from ema_casadi.limitcycle import describing_function, periodic_orbit, plot_nichols, setup
    from ema_casadi.optimal import optimal_move

    params, model = reference
    optimal_move(model, 5e-3, intervals=20).plot(tmp_path / "move.png")
    run_faults(params, healthy=0, jobs=1).plot(tmp_path / "faults.png")
    s = setup(model, "position")
    df = describing_function(model, "position", np.array([2e-6, 2e-5]), np.array([3.0, 6.0]), p=s["p"],
                             x0=s["x0"])
    plot_nichols(df, tmp_path / "nichols.png")
    hunting = ema.build_model(params, {**params.variants, "controller": "PI", "friction": "smooth"})
    periodic_orbit(hunting, "position", p=hunting.p(K_i_x=3000.0)).plot(tmp_path / "orbit.png")
    _clean(checked, 4)


@pytest.mark.slow
def test_the_longer_analyses_figures(reference, checked, tmp_path):
    """The experiment design's figure, the tuning's three and the performance envelope
    (their runs take 5-10 s each on the 2-core machine)."""
    from ema_casadi.design import design_experiment
    from ema_casadi.optimal import performance_envelope
    from ema_casadi.tuning import plot_tuning

    params, model = reference
    design_experiment(params, ["F_seal", "psi"], 2.0, max_load=0.0).plot(tmp_path / "design.png")
    plot_tuning(ema.tune(params), model, params, tmp_path)
    performance_envelope(model, [0.0, 10e3], [2e-3, 5e-3], intervals=15).plot(tmp_path / "envelope.png")
    _clean(checked, 5)
