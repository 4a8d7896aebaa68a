"""The ``ema`` command line (docs: cli).

Each subcommand lives in its own module of this package and defines ``COMMAND``
(name), ``ORDER`` (position in ``--help``), ``HELP`` (one line), ``add_arguments(parser)``
and ``run(args) -> dict`` (the ``--json`` result) plus optionally ``report(result)``
(the human-readable text). Modules are discovered, so adding a command is adding a
file. Every command takes the model file as first argument, ``--variant KEY=VALUE``
(repeatable) and ``--json``; :func:`load` gives its parameters and model, built once.
This module dispatches; the parser is in ``_parser``, the run in ``_run``, what the
commands share in ``_common`` and ``_options``.

Exit status and stderr (the reliability contract, docs: reliability), always one line, never a traceback:

- 0: done;
- 2: a mistake in a file, key, flag or value (checked before any work, outputs
  included: a path that cannot be written is refused up front);
- 3: a run failed (left the physical envelope, went non-finite, its integrator gave
  up: :class:`~ema_casadi.simulation.RunFailed`), or, for ``ema freqresp``, a
  requested point failed (the table is still written, with its status column);
- 130 / 143: interrupted by SIGINT (Ctrl-C) / SIGTERM, within about a second.

Outputs are written atomically and committed together at the end of the command
(:func:`ema_casadi._util._files.transaction`): an error, a failed run or an interrupt leaves
no output and no temporary file.

Importing this package costs next to nothing (``sys`` and the signal module): what
else the command line needs, the standard library's argparse included, loads after
:func:`main` has installed its signal handlers, so an interrupt during start-up is an
interrupt, not a traceback.
"""

from __future__ import annotations

import sys

from .._util import _interrupts

_interrupts.record_early()  # the ema process: a signal during the imports below is kept for main

from ._common import EXIT_FAILED, UserError, check_output_dir, check_output_path, jsonable, load, second_file  # noqa: E402
from ._options import DEFAULT_MODEL, add_progress, model_path, progress_of, stage  # noqa: E402

__all__ = ["main", "UserError", "DEFAULT_MODEL", "EXIT_FAILED", "check_output_path", "check_output_dir",
           "add_progress", "progress_of", "stage", "second_file", "model_path", "load", "jsonable", "add_common",
           "build_parser", "get_parser", "join_values"]

_PARSER_NAMES = ("add_common", "build_parser", "get_parser", "join_values")


def __getattr__(name):  # the parser's names load argparse: only when asked for
    if name in _PARSER_NAMES:
        from . import _parser

        return getattr(_parser, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def main(argv=None) -> int:
    """Run the ``ema`` command line and return its exit status.

    SIGINT and SIGTERM are handled from the first statement on (exit status 130 /
    143, one line on stderr, no output left). With ``argv`` None — the ``ema`` process
    itself — an interrupt ends the process at once after the cleanup (no wait for
    worker threads), and a run that cannot unwind within a second (IPOPT) is ended by
    a watchdog the same way.

    Parameters
    ----------
    argv : list of str, optional
        Arguments after the program name (default ``sys.argv[1:]``).
    """
    from ._run import _reader_gone, _run, _Stop

    process = argv is None
    stop = _Stop(sys.argv[1:] if process else list(argv))
    with _interrupts.handling(stop.force_exit if process else None, on_signal=stop.silence):
        try:
            _interrupts.replay_early()  # a signal that came during start-up
            status = _run(argv, stop)
            if process:  # done and reported: a late signal must not kill the process silently
                _interrupts.finished()
        except _interrupts.Interrupted as exc:
            status = stop.report(exc.signum)
        except BrokenPipeError:
            status = _reader_gone()
        except KeyboardInterrupt:
            status = stop.report(2)
        except BaseException:
            if _interrupts.requested() is None:
                raise
            status = stop.report(_interrupts.requested())  # an interrupt CasADi turned into an error
        finally:
            stop.unsilence()
        if stop.reported and process:
            stop.exit(status)
        return status


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
