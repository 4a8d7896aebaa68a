"""Meta-tests that keep the public API honest (python-control's ``kwargs_test.py`` and
``docstrings_test.py``, PyBaMM's option checks).

The public API is what the ``__all__`` of ``ema_casadi`` and of every public module
under it names (walked, so a module that is added, split or renamed is covered without
editing this file): its functions, and the methods of its classes.

1. Every function that takes ``**kwargs`` rejects an unknown keyword with a TypeError
   naming it (an explicit table says how to call each one).
2. Every parameter of every public function is documented in a numpydoc ``Parameters``
   section (for a class, its constructor's in ``Parameters`` or ``Attributes``).
3. Every part's declarations are complete: units, meanings, kinds, parameter names.
4. Every variant value and option value is dispatched to the part that serves it.
"""

from __future__ import annotations

import importlib
import inspect
import math
import pkgutil
import warnings

import pytest
from numpydoc.docscrape import NumpyDocString

import ema_casadi
from ema_casadi.model.components import INPUT_KINDS, OPTIONS, OUTPUT_KINDS, PART_CLASSES, REGISTRY
from ema_casadi.model.params import Parameters


# -- the public API -----------------------------------------------------------------
def _public_modules():
    mods = [ema_casadi]
    for info in pkgutil.walk_packages(ema_casadi.__path__, "ema_casadi."):
        if not any(part.startswith("_") for part in info.name.split(".")):
            mods.append(importlib.import_module(info.name))
    return mods


def _plain(attr):
    return attr.__func__ if isinstance(attr, (staticmethod, classmethod)) else attr


def _public_api():
    """``{qualified name: function or class}``: the functions and classes named in an
    ``__all__``, and the methods their classes define (each object once)."""
    found, seen = {}, set()

    def add(obj):
        if id(obj) not in seen and getattr(obj, "__module__", "").startswith("ema_casadi"):
            seen.add(id(obj))
            found[f"{obj.__module__}.{obj.__qualname__}"] = obj
            return True
        return False

    for mod in _public_modules():
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if inspect.isfunction(obj):
                add(obj)
            elif inspect.isclass(obj) and add(obj):
                for attr, value in vars(obj).items():
                    fn = _plain(value)
                    # a dataclass field's default may be a lambda (State.scale): not a method
                    if not attr.startswith("_") and inspect.isfunction(fn) and fn.__name__ != "<lambda>":
                        add(fn)
    return found


API = _public_api()
FUNCTIONS = {q: f for q, f in API.items() if inspect.isfunction(f)}


def _case(qualname, obj, *rest, test, label=""):
    """One parameter set, named by the object's qualified name (and a label)."""
    key = obj.__qualname__ + (f"[{label}]" if label else "")
    return pytest.param(qualname, obj, *rest, id=qualname.removeprefix("ema_casadi.") + key[len(obj.__qualname__):])


def test_the_walk_finds_the_api():
    names = {q.rsplit(".", 1)[-1] for q in API}
    assert {"build_model", "simulate", "loop_margins", "sine_stream", "operating_point"} <= names
    assert len(FUNCTIONS) > 100


# -- 1. **kwargs --------------------------------------------------------------------
def _takes_kwargs(fn) -> bool:
    return any(p.kind is p.VAR_KEYWORD for p in inspect.signature(fn).parameters.values())


@pytest.fixture(scope="module")
def ctx(params, model_cache, tmp_path_factory):
    """What the calls below need: the reference set, the default model, its trim."""
    model = model_cache()
    return {"params": params, "model": model, "op": ema_casadi.operating_point(model),
            "tmp": tmp_path_factory.mktemp("kwargs")}


#: How to call each function that takes ``**kwargs``: label -> ctx -> (args, kwargs),
#: the minimal valid call (keyed by ``__qualname__``, so the table follows a function
#: that moves to another module). Functions taking an operating point are called with
#: one (the kwargs must not be ignored because ``op`` is given) and without.
CALLS = {
    "Model.p": {"": lambda c: ((c["model"],), {})},
    "Model.u": {"": lambda c: ((c["model"],), {})},
    "Model.u_expr": {"": lambda c: ((c["model"], c["model"].p()), {})},
    "Parameters.replace": {"": lambda c: ((c["params"],), {})},
    "Parameters.vector": {"": lambda c: ((c["params"],), {})},
    "simulate": {"": lambda c: ((c["model"], 1e-3), {})},
    "run_study": {"": lambda c: ((c["params"], c["tmp"], "study"), {"amplitudes": [1e-3], "freqs": [1.0]})},
    "paper_fig14a": {"": lambda c: ((c["params"], c["tmp"]), {})},
    "paper_fig14b": {"": lambda c: ((c["params"], c["tmp"]), {})},
}
for _name in ("loop_margins", "closed_loop", "compliance", "dynamic_stiffness", "linear_model", "linearize"):
    CALLS[_name] = {"op": lambda c: ((c["model"], c["op"]), {}), "no-op": lambda c: ((c["model"],), {})}
for _name in ("loop_model", "loop_transfer"):
    CALLS[_name] = {"op": lambda c: ((c["model"], "position", c["op"]), {}),
                    "no-op": lambda c: ((c["model"], "position"), {})}

for _name in ("aircraft_point", "aircraft_margins"):  # **overrides: flat parameter names
    CALLS[_name] = {"": lambda c: ((c["model"],), {})}
for _name in ("pitch_step", "gust_response"):
    CALLS[_name] = {"": lambda c: ((c["model"], c["op"]), {})}

KWARGS_FUNCTIONS = {q: f for q, f in FUNCTIONS.items() if _takes_kwargs(f)}


def test_every_kwargs_function_has_a_call():
    have = {f.__qualname__ for f in KWARGS_FUNCTIONS.values()}
    assert have - set(CALLS) == set(), "add a call for each new **kwargs function to CALLS"
    assert set(CALLS) - have == set(), "CALLS names a function that no longer takes **kwargs"


def _kwargs_cases():
    return [_case(q, fn, make, test="kwargs", label=label)
            for q, fn in KWARGS_FUNCTIONS.items() for label, make in CALLS.get(fn.__qualname__, {}).items()]


@pytest.mark.parametrize("qualname, fn, make", _kwargs_cases())
def test_unknown_keyword_raises_type_error(ctx, qualname, fn, make):
    args, kwargs = make(ctx)
    with pytest.raises(TypeError, match="bogus_kw"):
        fn(*args, **kwargs, bogus_kw=1)


def test_loop_margins_with_an_operating_point_does_not_ignore_keywords(ctx):
    # the offender that started this file: f_ex (for f_ext) was silently ignored
    with pytest.raises(TypeError, match="'f_ex'.*did you mean 'f_ext'"):
        ema_casadi.loop_margins(ctx["model"], ctx["op"], f_ex=1.0)


# -- 2. documented parameters -------------------------------------------------------
def _documented(obj) -> set[str]:
    """Names in the numpydoc parameter sections (``a, b : float`` names both; stars
    dropped, so ``**kwargs`` documents ``kwargs``)."""
    sections = ("Parameters", "Other Parameters")
    docs = [inspect.getdoc(obj) or ""]
    if inspect.isclass(obj):
        sections += ("Attributes",)
        if "__init__" in vars(obj) and not getattr(obj, "__dataclass_fields__", None):
            docs.append(inspect.getdoc(obj.__init__) or "")
    names = set()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numpydoc warns about sections it does not know
        for doc in docs:
            parsed = NumpyDocString(doc)
            for sec in sections:
                for entry in parsed[sec]:
                    names.update(n.strip().lstrip("*") for n in entry.name.split(","))
    return names


def _parameters(obj) -> list[str]:
    sig = inspect.signature(obj)
    return [n for n in sig.parameters if n not in ("self", "cls") and not n.startswith("_")]


def _doc_cases():
    # a class is checked when it has a constructor of its own (dataclasses do)
    return [_case(q, obj, test="docs") for q, obj in API.items()
            if (not inspect.isclass(obj) or "__init__" in vars(obj)) and _parameters(obj)]


@pytest.mark.parametrize("qualname, obj", _doc_cases())
def test_every_parameter_is_documented(qualname, obj):
    documented = _documented(obj)
    missing = [n for n in _parameters(obj) if n not in documented]
    assert not missing, f"{qualname}: document {', '.join(missing)} in a numpydoc Parameters section"
    if not inspect.isclass(obj):  # a class's Attributes may list more than its constructor takes
        # text that is not a parameter parsed as one: a Returns paragraph left in Parameters
        stray = documented - set(inspect.signature(obj).parameters)
        assert not stray, f"{qualname}: the Parameters section names no parameters {sorted(stray)}"


# -- 3. part declarations -----------------------------------------------------------
#: every part class a model is assembled from (brought parts and option forms too), by the choice that assembles it
PARTS = [pytest.param(cls, id=f"{cls.__name__}:" + ",".join(f"{k}={v}" for k, v in choice.items()))
         for cls, choice in PART_CLASSES.items()]


@pytest.mark.parametrize("cls", PARTS)
def test_part_outputs_declare_unit_meaning_and_kind(cls):
    for out in cls.outputs:
        assert out.unit.strip() and out.doc.strip(), f"{cls.__name__}: output {out.name}"
        assert out.kind in OUTPUT_KINDS, f"{cls.__name__}: output {out.name} kind {out.kind!r}"


@pytest.mark.parametrize("cls", PARTS)
def test_part_states_declare_unit_doc_and_scale(cls, params):
    P = ema_casadi.build_model(params, PART_CLASSES[cls]).pdict()
    for s in cls.states:
        assert s.unit.strip() and s.doc.strip(), f"{cls.__name__}: state {s.name}"
        assert callable(s.scale), f"{cls.__name__}: state {s.name}"
        scale = s.scale(P)
        assert math.isfinite(scale) and scale > 0, f"{cls.__name__}: state {s.name} full scale {scale}"


@pytest.mark.parametrize("cls", PARTS)
def test_part_inputs_declare_a_known_kind(cls):
    for inp in cls.inputs:
        assert inp.kind in INPUT_KINDS, f"{cls.__name__}: input {inp.name} kind {inp.kind!r}"
        assert inp.unit.strip() and inp.doc.strip(), f"{cls.__name__}: input {inp.name}"


@pytest.mark.parametrize("cls", PARTS)
def test_part_parameters_exist(cls):
    unknown = set(cls.params) - set(Parameters.names())
    assert not unknown, f"{cls.__name__} names unknown parameters {sorted(unknown)}"


def test_assembly_outputs_declare_unit_meaning_and_kind(model_cache):
    for name, out in model_cache().output_info.items():
        assert out.unit.strip() and out.doc.strip() and out.kind in OUTPUT_KINDS, name


# -- 4. dispatch --------------------------------------------------------------------
VALUES = [pytest.param(key, value, id=f"{key}={value}") for key, values in REGISTRY.items() for value in values]


@pytest.mark.parametrize("key, value", VALUES)
def test_every_variant_value_is_dispatched(model_cache, key, value):
    model = model_cache(**{key: value})
    assert model.variants[key] == value
    assert any(p.family == key and p.value == value for p in model.parts), [(p.family, p.value) for p in model.parts]


OPTION_VALUES = [
    pytest.param(cls, opt, value, id=f"{cls.family}={cls.value}-{opt}={value}")
    for values in REGISTRY.values() for cls in values.values()
    for opt, allowed in cls.options.items() for value in allowed
]


def test_every_option_is_read_by_a_part():
    assert {o.values[1] for o in OPTION_VALUES} == set(OPTIONS)


@pytest.mark.parametrize("cls, opt, value", OPTION_VALUES)
def test_every_option_value_is_accepted(model_cache, cls, opt, value):
    assert value in OPTIONS[opt]
    model = model_cache(**{cls.family: cls.value, opt: value})
    (part,) = [p for p in model.parts if isinstance(p, cls)]  # or the form an option selects (ShortedPmsm)
    assert model.variants[opt] == value and part.opt[opt] == value
