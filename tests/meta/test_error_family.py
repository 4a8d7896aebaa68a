"""The one error family: every exception class of the package derives from ``EmaError``
through the kind that says what the user can do (input: exit 2; infeasible or failed:
exit 3), keeps its older base for scripts, and crosses a process boundary whole (pickled
by a worker, unpickled by the parent, whatever its ``__init__`` takes)."""

from __future__ import annotations

import importlib
import inspect
import pickle
import pkgutil
from concurrent.futures import ProcessPoolExecutor

import pytest

import ema_casadi
from ema_casadi import EmaError, InfeasibleError, InputError, RunError

#: Exception classes outside the family on purpose: an interrupt is not an error.
OUTSIDE = {"ema_casadi._util._interrupts.Interrupted"}
#: The kind of each class whose kind is not its name's (the rest: "...Error" is input,
#: "...Failed", "GaveUp", "OrbitNotFound" a failed run, "Infeasible" infeasible).
KIND = {"Infeasible": InfeasibleError, "GaveUp": RunError, "OrbitNotFound": RunError}
#: Constructor arguments of the classes whose ``__init__`` takes more than a message.
ARGS = {"RunFailed": ("x_rod = 0.08 m beyond its envelope", 0.25), "GaveUp": ("CVODES gave up", 0.125),
        "Infeasible": ("no move within the current limit",)}


def _classes():
    found = {}
    for info in pkgutil.walk_packages(ema_casadi.__path__, "ema_casadi."):
        if info.name.endswith("__main__"):
            continue  # running it is the command line
        mod = importlib.import_module(info.name)
        for _, obj in inspect.getmembers(mod, inspect.isclass):
            if issubclass(obj, BaseException) and not issubclass(obj, Warning) \
                    and obj.__module__.startswith("ema_casadi"):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return found


CLASSES = _classes()
FAMILY = {k: c for k, c in CLASSES.items() if k not in OUTSIDE}


def test_the_walk_finds_the_known_classes():
    names = {c.__name__ for c in FAMILY.values()}
    assert len(FAMILY) >= 30, sorted(names)
    assert {"ParameterError", "RunFailed", "GaveUp", "Infeasible", "UserError", "PointFailed", "MissionFailed",
            "OrbitNotFound", "OutputPathError", "FitFailed", "DesignFailed"} <= names


@pytest.mark.parametrize("name", sorted(FAMILY))
def test_every_error_class_is_of_the_family_and_of_its_kind(name):
    cls = FAMILY[name]
    assert issubclass(cls, EmaError), name
    if cls in (EmaError, InputError, InfeasibleError, RunError):
        return
    base = cls.__name__
    kind = KIND.get(base, InputError if base.endswith("Error") else RunError)
    assert issubclass(cls, kind), (name, kind)
    assert cls.exit_status == (2 if kind is InputError else 3)


@pytest.mark.parametrize("name", sorted(FAMILY))
def test_every_error_pickles_with_its_message_and_attributes(name):
    cls = FAMILY[name]
    exc = _instance(cls)
    back = pickle.loads(pickle.dumps(exc))
    assert type(back) is cls and str(back) == str(exc) and back.args == exc.args
    assert vars(back) == vars(exc)


def test_older_bases_stay_for_scripts():
    from ema_casadi import ParameterError, SignalError, SimulationError
    from ema_casadi.optimal import Infeasible

    assert issubclass(ParameterError, ValueError) and issubclass(SignalError, ValueError)
    assert issubclass(SimulationError, ValueError) and issubclass(Infeasible, RuntimeError)


def _raise_run_failed(t):
    from ema_casadi.simulation import RunFailed

    raise RunFailed("x_rod = 0.08 m beyond its envelope", t)


def test_a_workers_run_failed_reaches_the_parent_whole():
    """The error a worker raises arrives as itself (it broke the process pool when its
    ``__init__``'s required ``time`` was not restored)."""
    from ema_casadi.simulation import RunFailed

    with ProcessPoolExecutor(1) as pool:
        fut = pool.submit(_raise_run_failed, 0.5)
        with pytest.raises(RunFailed) as info:
            fut.result(timeout=60)
    assert info.value.time == 0.5 and info.value.reason == "x_rod = 0.08 m beyond its envelope at t = 0.5 s"


def _instance(cls):
    """An instance with the sample arguments of its nearest listed class (as many as its
    ``__init__`` requires), else one message."""
    sample = next((ARGS[b.__name__] for b in cls.__mro__ if b.__name__ in ARGS), ("--flag 1.5: out of range",))
    required = [p for p in list(inspect.signature(cls.__init__).parameters.values())[1:]
                if p.default is p.empty and p.kind is p.POSITIONAL_OR_KEYWORD]
    return cls(*sample[:max(1, len(required))])
