"""Results at a glance: every public result's repr is at most five lines (one, in
practice) naming what it is, and a notebook gets the same facts as an HTML table
(``_repr_html_``). The cheap results are built here; the expensive ones (a fit, a
tuning, an orbit, a fault table) are checked by the tests that build them anyway
(:func:`conftest.assert_glance`)."""

import pytest

import ema_casadi as ema
from conftest import assert_glance
from ema_casadi.aircraft import aircraft_margins, aircraft_point
from ema_casadi.frequency import loop_margins
from ema_casadi.limitcycle import describing_function, setup
from ema_casadi.linearisation import linear_model, operating_point

#: The public result classes (each must give the glance; the ones built below or elsewhere).
RESULTS = ("Model", "Parameters", "OperatingPoint", "LinearModel", "SimResult", "FreqResponse", "SweepResult",
           "MissionResult", "LoopMargins", "AircraftMargins", "DescribingFunction", "PeriodicOrbit", "Continuation",
           "IdentResult", "TrackResult", "Comparison", "FaultResult", "TuneResult", "DesignResult")


def _class(name):
    import importlib

    for mod in ("ema_casadi", "ema_casadi.linearisation", "ema_casadi.frequency", "ema_casadi.aircraft",
                "ema_casadi.limitcycle", "ema_casadi.identification", "ema_casadi.mission"):
        cls = getattr(importlib.import_module(mod), name, None)
        if cls is not None:
            return cls
    raise AssertionError(f"{name}: not a public name")


@pytest.mark.parametrize("name", RESULTS)
def test_every_result_class_has_an_html_view(name):
    cls = _class(name)
    assert "_repr_html_" in dir(cls) and cls.__repr__ is not object.__repr__, name


@pytest.fixture(scope="module")
def linear(model_cache):
    model = model_cache()
    op = operating_point(model, f_ext=1e4)
    return model, op, linear_model(model, op)


def test_model_parameters_and_linear_results(linear, params):
    model, op, lin = linear
    text = assert_glance(model)
    assert "variants=defaults" in text and f"states={len(model.states)}" in text
    assert "cesa_ema.toml" in assert_glance(params)
    assert "f_ext=10 kN" in assert_glance(op)
    assert "states=9" in assert_glance(lin) and "f_ext 10 kN" in assert_glance(lin)
    assert assert_glance(loop_margins(model, op, "position")["position"]).startswith("LoopMargins(loop=position")
    pwm = ema.build_model(params, {"inverter": "pwm"})
    assert "inverter=pwm" in assert_glance(pwm)  # the choices that differ from the defaults


def test_simulation_frequency_response_and_aircraft(model_cache):
    assert "samples=" in assert_glance(ema.simulate(model_cache(), 0.005))
    assert "converged=" in assert_glance(ema.sine_stream(ema.load_parameters(), [1e-3], [5.0], jobs=1))
    airframe = model_cache(airframe="transport")
    assert "condition=cruise_sl" in assert_glance(aircraft_margins(airframe, "cruise_sl",
                                                                  aircraft_point(airframe, "cruise_sl")))


def test_describing_function(model_cache):
    model = model_cache()
    s = setup(model, "position")
    df = describing_function(model, "position", [2e-6, 5e-6], [4.0, 8.0], p=s["p"], x0=s["x0"], periods=4, settle=2)
    assert "2 amplitudes x 2 frequencies" in assert_glance(df)
