"""One run of the ``ema`` command line: parse, run the command in one output transaction,
report; what an interrupt or a closed stdout does (:class:`_Stop`, :func:`_reader_gone`)."""

from __future__ import annotations

import contextlib
import os
import sys
import threading

from .._util import _interrupts
from .._util._errors import EmaError, InputError
from ._common import EXIT_FAILED, jsonable
from ._options import model_path
from ._parser import _subparsers, build_parser, flag_name, given_flags, join_values, unknown_flag


def _reader_gone() -> int:
    """The reader of stdout went away (``ema ... --json | head``): end quietly with the
    shell's status for a broken pipe (128 + SIGPIPE), as other Unix tools do; stdout is
    pointed at the null device so that the interpreter's final flush does not fail again."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())
    os.close(devnull)
    return 128 + 13


class _Stop:
    """What an interrupt does: silence the unwinding, remove the temporaries, write the
    one line, end the process (the ``ema`` process itself)."""

    def __init__(self, words):
        self.command = words[0] if words and not words[0].startswith("-") else None
        self.reported = False
        self.hint = ""  # what the interrupted command can do next (a resumable one: --resume)
        self.stderr = None
        self._once = threading.Lock()  # the main thread and the watchdog may both report

    def silence(self, signum):
        # what the unwinding prints (CasADi's warnings, a worker's error) is not for the
        # user: the one line of report() is
        self.stderr = sys.stderr
        sys.stderr = _Silent()

    def unsilence(self):
        if isinstance(sys.stderr, _Silent):
            sys.stderr = self.stderr

    def report(self, signum) -> int:
        from .._util import _files

        with self._once:
            if not self.reported:
                self.reported = True
                _files.remove_temporaries()
                stream = self.stderr or sys.stderr
                stream.write(f"ema {self.command}: interrupted{self.hint}\n" if self.command else "ema: interrupted\n")
                stream.flush()
        return _interrupts.exit_status(signum)

    def exit(self, status):
        import os

        sys.stdout.flush()
        os._exit(status)

    def force_exit(self, signum):  # the watchdog: the run did not unwind in time
        self.exit(self.report(signum))


class _Silent:
    """A stream that drops what is written to it."""

    def write(self, s):
        return len(s)

    def flush(self):
        pass


@contextlib.contextmanager
def one_line_warnings(command: str):
    """A library's warning (matplotlib's, NumPy's, SciPy's) as the contract's one line on
    stderr, ``ema COMMAND: warning: <its first line>``, each text once, instead of
    Python's two lines with a file name and a source line."""
    import warnings

    shown = set()

    def show(message, category, filename, lineno, file=None, line=None):
        text = (str(message).strip().splitlines() or [category.__name__])[0]
        if text not in shown:
            shown.add(text)
            sys.stderr.write(f"ema {command}: warning: {text}\n")

    before = warnings.showwarning
    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = before


def _refused(command: str, exc: EmaError, flags: dict | None = None) -> int:
    """An error of the family as the contract's one line on stderr; its exit status: a
    mistake in the input ``error:``, exit 2, the API's argument it starts with named by
    its flag (``flags``: argument -> flag; ``distances: ...`` -> ``--distances: ...``);
    an infeasible request or a failed run ``failed:``, exit 3."""
    import re

    text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    if isinstance(exc, InputError):
        word = re.match(r"[A-Za-z_]\w*(?=[: ])", text)
        if word and word.group() in (flags or {}):
            text = flags[word.group()] + text[word.end():]
        sys.stderr.write(f"ema {command}: error: {text}\n")
        return 2
    sys.stderr.write(f"ema {command}: failed: {text}\n")
    return EXIT_FAILED


def _run(argv, stop) -> int:
    """Parse, run the command in one output transaction, report; the exit status."""
    import json

    from .._util import _files

    os.environ.setdefault("MPLBACKEND", "Agg")  # the command line draws off screen (PNG files only)
    parser, mods = build_parser()
    process = argv is None  # the ema process itself (not main() called from Python)
    argv = join_values(list(sys.argv[1:] if process else argv), parser)
    unknown = unknown_flag(argv, parser)
    if unknown:
        sys.stderr.write(unknown + "\n")
        return 2
    args = parser.parse_args(argv)
    stop.command = args.command
    args._given = given_flags(_subparsers(parser).choices[args.command], argv[argv.index(args.command) + 1:])
    args.model_given = args.model is not None
    args.model = model_path(args)
    mod = mods[args.command]
    hint = getattr(mod, "interrupt_hint", None)
    stop.hint = hint(args) if hint else ""
    quiet = one_line_warnings(args.command) if process else contextlib.nullcontext()
    try:
        with quiet, _files.transaction():
            from ._flags import COMMON, refuse_no_effect

            refuse_no_effect(args, {**COMMON, **getattr(mod, "NO_EFFECT", {})})  # before any work
            result = mod.run(args)
            _interrupts.check()
    except EmaError as exc:  # the one place the family becomes an exit status and one line
        _interrupts.check()
        sub = _subparsers(parser).choices[args.command]
        return _refused(args.command, exc, {a.dest: flag_name(a) for a in sub._actions
                                            if any(o.startswith("--") for o in a.option_strings)})
    if args.json:
        json.dump(jsonable(result), sys.stdout, indent=1)
        sys.stdout.write("\n")
    else:
        report = getattr(mod, "report", None)
        if report:
            report(result)
        else:
            json.dump(jsonable(result), sys.stdout, indent=1)
            sys.stdout.write("\n")
    failure = result.get("failure") if isinstance(result, dict) else None
    if failure:
        sys.stderr.write(f"ema {args.command}: failed: {failure}\n")
        return EXIT_FAILED
    return 0
