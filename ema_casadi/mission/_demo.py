"""The demo's short mission: three minutes of flight through the thermal network."""

from __future__ import annotations

import time
import tomllib
from pathlib import Path

from ..model.params import Parameters
from ._profile import parse_mission
from ._run import run_mission

__all__ = ["SHORT_MISSION", "demo_mission"]

#: A 3-minute flight in the mission format: ground check at +40 degC, take-off, climb
#: into a cold cavity, cruise at -40 degC, descent, landing.
SHORT_MISSION = """
[mission]
name = "Short flight (3 min): ground check at +40 degC, cruise at -40 degC"
T_start = 40.0

[[segment]]
name = "ground check"
duration = 30.0
x_cmd = "step:70mm@2+step:-140mm@8+step:70mm@14"
f_ext = "0.5kN"
T_amb = 40.0

[[segment]]
name = "take-off"
duration = 30.0
x_cmd = "step:-20mm@5+step:12mm@11+sine:2mm@0.5@11"
f_ext = "step:-22kN@5+step:10kN@11+sine:-2kN@0.5@11"
T_amb = [35.0, 30.0]

[[segment]]
name = "climb"
duration = 45.0
x_cmd = "-5mm+sine:1.5mm@0.3+sine:0.5mm@1.1"
f_ext = "-8kN+sine:-1.5kN@0.3"
T_amb = [30.0, -40.0]

[[segment]]
name = "cruise"
duration = 40.0
x_cmd = "-2mm+sine:0.3mm@0.5+sine:0.15mm@1.7"
f_ext = "-5kN+sine:-0.5kN@0.5"
T_amb = -40.0

[[segment]]
name = "descent"
duration = 15.0
x_cmd = "-3mm+sine:1mm@0.3"
f_ext = "-6kN+sine:-1kN@0.3"
T_amb = [-40.0, 0.0]

[[segment]]
name = "landing"
duration = 20.0
x_cmd = "-11mm+step:-15mm@5+step:26mm@12"
f_ext = "-10kN+step:-18kN@5+step:28kN@12"
T_amb = [0.0, 20.0]
"""


def demo_mission(params: Parameters, out: str | Path, written: list | None = None) -> dict:
    """Run :data:`SHORT_MISSION` on the full model and write ``mission_short.png`` and
    ``mission_short.csv`` into ``out``. Returns the peaks, the energies per part, the
    heat balance and the wall time; the paths are appended to ``written``.

    Parameters
    ----------
    params : Parameters
        The parameter set.
    out : str or Path
        An existing output folder.
    written : list, optional
        Paths written so far (extended).
    """
    out = Path(out)
    t0 = time.perf_counter()
    mission = parse_mission(tomllib.loads(SHORT_MISSION), params, "demo: short mission")
    res = run_mission(params, mission)
    paths = [res.plot(out / "mission_short.png"), res.to_csv(out / "mission_short.csv")]
    if written is not None:
        written += paths
    s = res.summary()
    return {"mission": s["mission"], "duration_s": s["duration_s"], "limits_ok": s["limits_ok"],
            "peaks_degC": {n: p["peak_degC"] for n, p in s["peaks"].items()},
            "energy_by_part_J": s["energy_by_part_J"], "electrical_in_J": s["energy_J"][res.names["electrical_power"]],
            "heat_balance": s["heat_balance"], "wall_time_s": time.perf_counter() - t0}
