"""Structure hints: a fit whose misfit a Stribeck hump explains names the friction
options and the command that compares them; the comparison ranks the hump first.

The witness: a 1 s chirp record (0.2 mm, 0.5-10 Hz: the rod's speed within a few
Stribeck velocities throughout) of the toolkit's own model with ``stribeck = on``, the
hump 1.4x the sliding level at 1.5 mm/s, seal friction 180 N and viscous friction
260 N s/m (reference: 150, 200, hump 1.3x at 1 mm/s)."""

from __future__ import annotations

import pytest

from ema_casadi import identification as idn
from ema_casadi.identification import _hints

SIGMA = {"x_rod": 0.3e-6, "i_q": 0.05}
TRUTH = {"F_seal": 180.0, "c_v": 260.0, "r_start": 1.4, "v_st": 1.5e-3}


@pytest.fixture(scope="module")
def hump_record(params, tmp_path_factory):
    return idn.synthetic_record(params, tmp_path_factory.mktemp("hump") / "hump.csv", t_end=1.0,
                                x_cmd="chirp:0.2mm@0.5-10", truth=TRUTH, seed=5, variants={"stribeck": "on"})


def test_a_hump_the_structure_lacks_is_named(params, hump_record):
    """The default structure (smooth friction) fitted: inadequate, and the hint names
    stribeck=on (with r_start, v_st) and lugre_smooth, with the comparison's command.
    The score test: freeing the hump's height would lower the cost by 192 (measured),
    far above its threshold 12 (chi-square 1 dof at p = 1e-6; required 10x it), and
    above what freeing any one rival would (the best, C: 4.2)."""
    res = idn.identify(params, [hump_record], ["F_seal", "c_v"], sigma=SIGMA, consistency=False)
    assert not res.adequacy["adequate"]
    (hint,) = res.info["hints"]
    assert hint["score"]["decrease"] > 10 * _hints.SCORE_COST
    assert hint["score"]["decrease"] > 10 * max(hint["score"]["rivals"].values())
    options = [c["option"] for c in hint["candidates"]]
    assert options == ["stribeck=on", "friction=lugre_smooth"]
    assert hint["candidates"][0]["adds"] == ["r_start", "v_st"]
    assert "--free F_seal,c_v,r_start,v_st --compare stribeck=off,on" in hint["text"]
    assert res.to_dict()["hints"][0]["text"] == hint["text"]


def test_no_friction_hint_for_another_misfit(params, tmp_path):
    """A misfit that is not friction's (the rotor inertia +25 % while only F_seal is
    free, on a 1 mm step): inadequate, and no friction hint, although 74 % of the
    misfit sits at the starts and the hump alone would lower the cost by 22 300: freeing
    J_m or psi alone would lower it by 74 700 (measured), so the hump is not named."""
    rec = idn.synthetic_record(params, tmp_path / "m.csv", t_end=0.3, x_cmd="step:1mm@0.02",
                               truth={"F_seal": 210.0, "J_m": 1.5e-3})
    res = idn.identify(params, [rec], ["F_seal"], sigma=SIGMA)
    assert not res.adequacy["adequate"] and res.info["hints"] == []


def test_compare_ranks_the_hump_first(params, hump_record):
    """--compare stribeck=off,on with r_start, v_st freed: they are fitted only where the
    hump is on (named not used in the other row), and the hump ranks first, within the
    model error tolerated, the smooth law inadequate."""
    cmp = idn.compare(params, [hump_record], ["F_seal", "c_v", "r_start", "v_st"], {"stribeck": ["off", "on"]},
                      sigma=SIGMA)
    first, second = cmp.rows
    assert first["variants"]["stribeck"] == "on" and first["adequate"]
    assert second["variants"]["stribeck"] == "off" and not second["adequate"]
    assert second["not_used"] == ["r_start", "v_st"] and set(second["estimate"]) == {"F_seal", "c_v"}
    assert first["bic"] < second["bic"] - 10


def test_the_command_names_the_options_in_its_json_and_text(hump_record, capsys):
    """``ema identify`` with the default structure: exit 3, the JSON document carries
    the hint, the text report prints it on a line of its own."""
    import json

    from ema_casadi.cli import main

    argv = ["identify", str(hump_record), "--free", "F_seal,c_v", "--sigma", "x_rod=0.3um", "--sigma", "i_q=0.05A",
            "--no-progress"]
    assert main([*argv, "--json"]) == 3
    doc = json.loads(capsys.readouterr().out)
    assert doc["verdict"] == "inadequate" and "--compare stribeck=off,on" in doc["hints"][0]["text"]
    assert main(argv) == 3
    assert "\nhint: a Stribeck hump would lower the cost by" in capsys.readouterr().out
