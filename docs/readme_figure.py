"""Draw the README's figure, ``docs/_static/fig14a.png`` (run from the repository root:
``python docs/readme_figure.py``; about 10 s). The figure is committed (a small PNG);
rerun this script when the model changes what it shows.

The paper's Fig. 14a by sine stream: gain and phase of x_rod/x_cmd of the nonlinear
reference actuator at 0.5, 2, 5 and 10 % of the 75 mm stroke, no load.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import ema_casadi as ema  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> Path:
    params = ema.load_parameters(ROOT / "models" / "cesa_ema.toml")
    stroke = params.actuator.stroke
    pct = (0.5, 2.0, 5.0, 10.0)
    fr = ema.sine_stream(params, amplitudes=[p / 100 * stroke for p in pct], freqs=np.geomspace(0.1, 20.0, 24))
    fig, (ax_g, ax_p) = plt.subplots(1, 2, figsize=(8.0, 3.0))
    for p, amp in zip(pct, fr.axes["amplitude"], strict=True):
        c = fr.curve(amplitude=amp)
        ax_g.semilogx(c["freq_Hz"], c["gain_db"], label=f"{p:g} % of stroke")
        ax_p.semilogx(c["freq_Hz"], c["phase_deg"])
    ax_g.set(xlabel="frequency (Hz)", ylabel="gain x_rod/x_cmd (dB)", ylim=(-15, 2))
    ax_p.set(xlabel="frequency (Hz)", ylabel="phase (deg)")
    ax_g.legend(fontsize=7, loc="lower left")
    for ax in (ax_g, ax_p):
        ax.grid(alpha=0.3, which="both")
    fig.suptitle("Nonlinear frequency response of the reference EMA (the paper's Fig. 14a)", fontsize=9)
    fig.tight_layout()
    out = ROOT / "docs" / "_static" / "fig14a.png"
    fig.savefig(out, dpi=90)
    return out


if __name__ == "__main__":
    print(main())
