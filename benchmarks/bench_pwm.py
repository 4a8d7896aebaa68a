"""Benchmark: the switched PWM bridge, 1 s simulated at f_sw = 16 kHz with
every switching instant resolved, against the averaged bridge and against motulator's
carrier-comparison PWM drive simulation.

- ema, ``inverter = "pwm"``: the carrier-synchronous compiled stepper (8 sub-intervals
  per carrier period, each of length D integrated with ceil(D/dt) RK4 steps, dt = 5 us),
  1.5 mm 1 Hz sine, one sample per ms kept; its accuracy against the same run at
  dt = 1.25 us is printed (the switching instants are exact at any step).
- ema, ``inverter = "ideal"``: the averaged bridge, compiled RK4 at 5 us with the same
  sampled ECU (``zoh``), the same scenario.
- motulator (PyPI ``motulator``, optional extra ``bench``): its own 2.2 kW PMSM example
  (sensorless current-vector control, examples/drive/vector/plot_vector_ctrl_pmsm_2kw.py)
  with its PWM model enabled (``mdl.pwm = CarrierComparison()``, switching instants
  computed per sampling period and each interval integrated by SciPy's ``solve_ivp``);
  at its example's sampling period T_s = 250 us (a 2 kHz carrier: one half period per
  sample) and at T_s = 31.25 us (a 16 kHz carrier, the same switching rate as ema's).
  Wall time per simulated second of a shorter run.

Wall times: ema medians of repeated runs after a warm-up (compilation excluded);
motulator one run. Run alone on the machine for meaningful ratios.

Usage: python benchmarks/bench_pwm.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import numpy as np  # noqa: E402
from _timing import timed  # noqa: E402

import ema_casadi as ema  # noqa: E402
from ema_casadi import Signal  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
X_CMD = Signal.sine(1.5e-3, 1.0)


def motulator_run(T_s: float, t_stop: float) -> float:
    """Wall time (s) of motulator's PMSM example with carrier comparison over t_stop."""
    import motulator.drive.control.sm as control
    from motulator.drive import model
    from motulator.drive.utils import BaseValues, NominalValues, SynchronousMachinePars

    nom = NominalValues(U=370, I=4.3, f=75, P=2.2e3, tau=14)
    base = BaseValues.from_nominal(nom, n_p=3)
    mdl_par = SynchronousMachinePars(n_p=3, R_s=3.6, L_d=.036, L_q=.051, psi_f=.545)
    mdl = model.Drive(model.VoltageSourceConverter(u_dc=540), model.SynchronousMachine(mdl_par),
                      model.StiffMechanicalSystem(J=.015))
    mdl.pwm = model.CarrierComparison()
    cfg = control.CurrentReferenceCfg(mdl_par, nom_w_m=base.w, max_i_s=1.5 * base.i)
    ctrl = control.CurrentVectorControl(mdl_par, cfg, J=.015, T_s=T_s, sensorless=True)
    ctrl.ref.w_m = lambda t: (t > .02) * 2 * base.w
    mdl.mechanics.tau_L = lambda t: (t > .08) * .7 * nom.tau
    t0 = time.perf_counter()
    model.Simulation(mdl, ctrl).simulate(t_stop=t_stop)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repeats and a shorter motulator run")
    args = ap.parse_args()
    repeat = 2 if args.quick else 5
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    pwm = ema.build_model(params, {"inverter": "pwm"})
    avg = ema.build_model(params)
    t_pwm, r = timed(lambda: ema.simulate(pwm, 1.0, X_CMD, dt=5e-6, dt_out=1e-3, solver="rk4"), repeat, warmup=True)
    fine = ema.simulate(pwm, 1.0, X_CMD, dt=1.25e-6, dt_out=1e-3, solver="rk4")
    err_x = float(np.abs(r["x_rod"] - fine["x_rod"]).max())
    err_i = float(np.abs(r["i_a"] - fine["i_a"]).max())
    t_avg, _ = timed(lambda: ema.simulate(avg, 1.0, X_CMD, dt=5e-6, dt_out=1e-3, zoh=True, solver="rk4"), repeat,
                                          warmup=True)
    periods = r.info["carrier_periods"]
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print("| simulator | per simulated second (s) | ratio to ema pwm |")
    print("|---|---|---|")
    print(f"| ema inverter=pwm, 16 kHz, switching resolved ({periods} periods x 8 sub-intervals) | {t_pwm:.3f} | 1 |")
    print(f"| ema inverter=ideal, averaged, RK4 5 us, sampled ECU | {t_avg:.3f} | {t_avg / t_pwm:.2f} |")
    print(f"(ema pwm: {1e6 * t_pwm / periods:.1f} us per carrier period; against dt = 1.25 us: "
          f"rod {err_x:.2g} m, phase current {err_i:.2g} A)")
    try:
        import motulator  # noqa: F401
    except ImportError:
        print("motulator not installed (pip install -e .[bench]): its rows skipped")
        return
    for T_s, t_stop in ((250e-6, 0.1 if args.quick else 0.3), (31.25e-6, 0.02 if args.quick else 0.05)):
        w = motulator_run(T_s, t_stop) / t_stop
        print(f"| motulator PMSM example, CarrierComparison, T_s = {T_s * 1e6:g} us "
              f"({0.5e-3 / T_s:g} kHz carrier), {t_stop:g} s run | {w:.3f} | {w / t_pwm:.1f} |")


if __name__ == "__main__":
    main()
