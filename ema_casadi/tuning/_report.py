"""One-line texts of tuning results: a constraint group in the requirement's words, and
the outcome message of a tune."""

from __future__ import annotations

from ._requirements import Requirements


def _loads_text(loads) -> str:
    return ", ".join(f"{f / 1e3:g}" for f in loads) + " kN"


def describe_constraint(v: dict, req: Requirements | None = None) -> str:
    """One-line text of a constraint group (an entry of :attr:`TuneResult.violations` or
    ``active``), with the requirement's numbers.

    Parameters
    ----------
    v : dict
        The group: ``kind``, ``loads`` (N), ``loop``, optionally ``at_hz`` (Hz).
    req : Requirements, optional
        The requirements it stands for (default :class:`Requirements`).
    """
    r = req or Requirements()
    if r.ms is not None:
        margin = f"sensitivity peak Ms <= {r.ms:g}"
    else:
        margin = f"margins GM >= {r.gm_db:g} dB / PM >= {r.pm_deg:g} deg"
    text = {
        "margin": margin,
        "rate": f"loop gain below 1 above the ECU sample rate / {r.rate_ratio:g}",
        "bandwidth": "bandwidth (objective)",
        "bandwidth_min": f"bandwidth >= {r.bandwidth_min_hz:g} Hz" if r.bandwidth_min_hz else "minimum bandwidth",
        "overshoot": f"step overshoot <= {100 * r.overshoot:g} %",
        "current": f"current limit on a {r.step * 1e3:g} mm step",
        "voltage": f"voltage limit on a {r.step * 1e3:g} mm step",
        "eigenvalue": f"closed-loop eigenvalues left of -{r.sigma:g} 1/s",
        "cascade_margin": f"{margin} with the outer loops open",
        "unconditional": f"unconditional stability (no phase crossover above -{r.margin_targets()[0]:g} dB) "
                         "with the outer loops open",
        "separation": f"loop separation >= {r.separation:g} x the next outer loop's crossover",
        "noise": (f"current-command response to {r.sensor_noise * 1e6:g} µm of position-sensor noise "
                  f"<= {100 * r.command_noise:g} % of I_max"),
    }.get(v["kind"], v["kind"])
    where = f"{v['loop']} loop, " if v.get("loop") and v["kind"] in (
        "margin", "rate", "cascade_margin", "unconditional", "separation") else ""
    at = f" near {v['at_hz']:.3g} Hz" if v.get("at_hz") else ""
    return f"{text} ({where}{_loads_text(v['loads'])}{at})"


def _message(converged, status, violations, ver, req) -> str:
    if converged and not violations and ver["meets"]:
        return f"tuned: IPOPT {status}; every requirement met in every load case (verified)"
    fails = ver.get("failures", [])
    if violations:
        worst = sorted(violations, key=lambda v: -max(v["slack"], -v["min"]))[:2]
        text = ("infeasible request: no gains meet every constraint; the least-violating gains "
                f"(IPOPT {status}) still break the " + " and the ".join(describe_constraint(v, req) for v in worst))
        return text + (f"; e.g. {fails[0]}" if fails else "")
    if not converged:
        return f"tuning failed: IPOPT {status}" + (f"; at the last point {fails[0]}" if fails else "")
    return (f"tuning failed: IPOPT {status}, but the independent check finds " + "; ".join(fails[:3]))
