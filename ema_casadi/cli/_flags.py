"""Shared checks of the commands' flags: parameter values set by flags (checked as a
parameter file's values, named by the flag), flags given where they have no effect
(each command's ``NO_EFFECT`` table, :class:`NoEffect`), the
airframe chosen by ``--variant airframe=...`` or ``--airframe``, and an output folder
of several files written whole or not at all."""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from . import UserError, check_output_dir, check_output_path

__all__ = ["overrides", "refuse_dt", "rk4_step", "fill_defaults", "airframe_variant", "new_output_folder",
           "output_folder", "NoEffect", "COMMON", "given", "no_effect", "refuse_no_effect", "check_bare"]


@dataclass(frozen=True)
class NoEffect:
    """A combination in which a flag has no effect: given there, the flag is refused in
    one line (``FLAG has no effect WHY``), never silently dropped.

    Every command declares ``NO_EFFECT``: each flag it adds -> the combinations that
    disable it (an empty tuple: the flag acts in every combination). The command-line
    tests run every ``example`` and check the one line, so a flag added without a
    declaration, or a declared combination that is not refused, fails them.

    Attributes
    ----------
    example : tuple of str
        A command line after the command's name, the flag included, where the flag has
        no effect (the tests run it: exit status 2, one line naming the flag).
    why : str
        The end of the message after "FLAG has no effect"; ``{attr}`` fields are filled
        from the parsed arguments (``"with --format {format}"``).
    when : callable, optional
        ``when(args) -> bool`` on the parsed arguments: checked by the dispatcher
        before any work (:func:`refuse_no_effect`). None where it takes the model (the
        command checks it with :func:`no_effect` once the model is built).
    """

    example: tuple
    why: str
    when: Callable | None = None


#: The flags every command has (:func:`~ema_casadi.cli._parser.add_common`,
#: :func:`~ema_casadi.cli._options.add_progress`): they act everywhere unless the
#: command's own ``NO_EFFECT`` says otherwise.
COMMON = {"--variant": (), "--json": (), "--progress": ()}


def given(args, flag: str) -> bool:
    """Whether ``flag`` was on the command line (also at its default value): the set the
    dispatcher records (``args._given``), else, for arguments built by hand, a value
    other than None, False or empty.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments.
    flag : str
        The flag's long name (``"--dt"``).
    """
    marks = getattr(args, "_given", None)
    if marks is not None:
        return flag in marks
    return getattr(args, flag[2:].replace("-", "_"), None) not in (None, False, [], ())


def no_effect(args, flag: str, why: str) -> None:
    """Refuse ``flag`` when it was given: UserError ``FLAG has no effect WHY``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments.
    flag : str
        The flag.
    why : str
        Where and why it has no effect (``"with --solver rk4: ..."``).
    """
    if given(args, flag):
        raise UserError(f"{flag} has no effect {why}")


def refuse_no_effect(args, table: dict) -> None:
    """The first flag of a command's ``NO_EFFECT`` table that was given in a combination
    whose ``when`` holds: UserError, one line naming it (before any work).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments (``args._given``: the flags on the command line).
    table : dict
        Flag -> tuple of :class:`NoEffect`.
    """
    for flag, rules in table.items():
        for rule in rules:
            if rule.when is not None and given(args, flag) and rule.when(args):
                no_effect(args, flag, rule.why.format(**vars(args)))


def new_output_folder(out: str | Path, names, flag: str = "--out") -> Path | None:
    """Check an output folder of the files ``names`` before any work; return the highest
    folder of ``out`` that does not exist yet (assembled aside with what lies below it
    and moved in at the end by :func:`output_folder`: a failure leaves no empty folder),
    or None when ``out`` exists (each file is then written aside and renamed).

    Raises
    ------
    UserError
        The outputs cannot be written there (one line naming ``flag``).
    """
    if not str(out).strip() or Path(out).name in ("", ".", ".."):  # '' would be the working folder
        raise UserError(f"{flag} '{out}': names no folder of its own; name the output folder")
    names, out = list(names), Path(out)
    missing = [p for p in (out, *out.parents) if not p.exists()]
    if not missing:
        for name in names:
            check_output_path(str(out / name), (Path(name).suffix,), flag)
        return None
    check_output_dir(str(missing[-1]), names if missing[-1] == out else (), flag)
    return missing[-1]


@contextlib.contextmanager
def output_folder(out: Path, top: Path | None):
    """The folder to write the outputs into: ``out`` itself when it existed, else its
    place inside the copy of ``top`` (from :func:`new_output_folder`) that is assembled
    aside and moved in whole when the block ends without an error."""
    from .._util._files import atomic_dir

    if top is None:
        yield out
        return
    with atomic_dir(top) as tmp:
        folder = tmp / out.relative_to(top)
        folder.mkdir(parents=True, exist_ok=True)
        yield folder


def overrides(params, flags: dict) -> dict:
    """Parameter values set by flags, checked as a parameter file's values are, the
    message naming the flag: ``{"--backlash": ("B", 0.1, 1e-3)}`` (flag -> flat name,
    value as given or None when not given, factor to SI) -> ``{"B": 1e-4}``.

    Parameters
    ----------
    params : Parameters
        The parameter set the values go into.
    flags : dict
        Flag -> (flat parameter name, value or None, factor to SI).
    """
    from ..model import checked
    from ..model.params import ParameterError

    out = {}
    for flag, (name, value, factor) in flags.items():
        if value is None:
            continue
        try:
            out[name] = checked(name, value * factor, f"{flag} {value:g}")
        except ParameterError as exc:  # the value as given, not in SI
            raise UserError(str(exc).split(", got ")[0]) from None
    return out


def refuse_dt(dt, solver, hint: str = "give --solver rk4 or drop --dt") -> None:
    """``--dt`` is the RK4 step: given while another solver runs (``solver`` the one
    chosen, or True where the model switches and RK4 always steps) it would be dropped
    without a word, so it is refused.

    Parameters
    ----------
    dt : float or None
        The --dt given (None: not given).
    solver : str or bool
        The solver that runs (``"rk4"``, ``"rosenbrock"``, ``"cvodes"``), or True.
    hint : str
        What to do instead.
    """
    if dt is not None and solver not in (True, "rk4"):
        raise UserError(f"--dt is the RK4 step; the solver chosen is {solver}: {hint}")


def rk4_step(model, dt_given, default: float, zoh: bool, load: float = 0.0) -> float:
    """The RK4 step of a command: ``--dt`` refused above RK4's stability limit on the
    model at ``load`` (N) and, with ``zoh``, where one step would hold two ECU sampling
    instants; without ``--dt`` the largest step under the margin x the limit and
    ``default`` that divides them (:func:`~ema_casadi.simulation.inside_limit`).

    Parameters
    ----------
    model : Model
        The model that runs.
    dt_given : float or None
        The --dt given.
    default : float
        The command's largest default step (s).
    zoh : bool
        The ECU is sampled.
    load : float
        The run's largest load (N).
    """
    from ..simulation import inside_limit, rk4_step_limit, sampling_split

    if dt_given is None:  # a constant load: its peak over any length
        return inside_limit(model, {"load": load}, 1.0, zoh, default)
    limit = rk4_step_limit(model, load=load, zoh=zoh)
    text = limit.message(dt_given, "--dt")
    if text is not None:
        raise UserError(text)
    if zoh and not model.switched:  # split at the instants; refused where a step holds two
        sampling_split(model, dt_given, model.p(), UserError, "--dt")
    return dt_given


def fill_defaults(args, defaults: dict) -> None:
    """Set each attribute of ``defaults`` that is None in ``args`` to its default (flags
    whose default is None so that a command can tell whether they were given).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed arguments.
    defaults : dict
        Attribute -> default value.
    """
    for attr, value in defaults.items():
        if getattr(args, attr, None) is None:
            setattr(args, attr, value)


def airframe_variant(args, default: str, choices) -> str:
    """The airframe of a command with an ``--airframe`` flag: ``--variant airframe=X``
    and ``--airframe`` name the same choice; both given and different is a mistake
    (never one silently overriding the other). Appends the choice to ``args.variant``.

    Parameters
    ----------
    args : argparse.Namespace
        With ``variant`` (list of pairs) and ``airframe`` (None when not given).
    default : str
        The command's default airframe.
    choices : iterable of str
        The airframes the command takes.
    """
    given = [v for k, v in args.variant if k == "airframe"]
    chosen = given[-1] if given else None
    if chosen is not None and args.airframe is not None and chosen != args.airframe:
        raise UserError(f"--variant airframe={chosen} and --airframe {args.airframe} disagree; give one")
    airframe = chosen or args.airframe or default
    if airframe not in choices:
        raise UserError(f"--variant airframe={airframe}: this command takes {', '.join(choices)}"
                        f"{_nearest(airframe, choices)}")
    args.airframe = airframe
    args.variant = [*[(k, v) for k, v in args.variant if k != "airframe"], ("airframe", airframe)]
    return airframe


def _nearest(name, options) -> str:
    from .._util._checks import nearest

    return nearest(name, options)


def check_bare(flag: str, name: str, text: str, value: float, kind, si: str, model) -> None:
    """A bare number (no unit) is read in SI; refused, with the units that would read it
    plausibly, where that reading is beyond what its quantity can be on the model
    (:func:`~ema_casadi._util._checks.plausible_limit`: ``--sigma x_rod=0.3`` is 0.3 m,
    four times the stroke), as a record's unitless column is.

    Parameters
    ----------
    flag, name, text : str
        The flag, the name given and the value's text.
    value : float
        The value read (SI).
    kind : str or None
        Its quantity (``length``, ...).
    si : str
        Its SI unit.
    model : Model
        The model.
    """
    from .._util._checks import plausible_limit
    from ..signals import UNITS

    try:
        float(text)
    except ValueError:
        return  # a unit was given
    bound = plausible_limit(model, kind)
    if bound is None or not abs(value) > bound[0]:
        return
    fits = [u for u, f in sorted(UNITS[kind].items(), key=lambda kv: -kv[1]) if f < 1 and abs(value) * f <= bound[0]]
    fix = " or ".join(f"{name}={text.strip()}{u}" for u in fits[:2]) or f"{name}=VALUE UNIT"
    raise UserError(f"{flag} {name}={text.strip()}: a bare number is SI, {value:g} {si}, beyond {bound[0]:.4g} {si} "
                    f"({bound[1]}); give its unit: {fix}")
