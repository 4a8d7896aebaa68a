"""The main job on the reference model: step and sine responses, Bode, margins and the
nonlinear frequency-response map; PNGs plus summary.md and summary.json in --out."""

from __future__ import annotations

from .._util import _files
from ..demo import DEMO_FILES, KEPT_FOLDERS, run_demo
from . import add_progress, load, progress_of

COMMAND = "demo"
ORDER = 1
HELP = "main job: responses, Bode, margins, frequency-response map -> out/"


#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--out": ()}

def add_arguments(p):
    p.add_argument("--out", default="out", metavar="DIR",
                   help="output folder, assembled beside it and moved into place at the end; an existing folder "
                        "is replaced whole (but for out/mission, which ema mission writes), and refused if it holds "
                        "files the demo does not write; default out/")
    add_progress(p)


def run(args) -> dict:
    out = _files.check_folder(args.out, DEMO_FILES, f"--out {args.out}", keep=KEPT_FOLDERS)
    params, _ = load(args)
    return run_demo(params, out, progress=progress_of(args))


def report(r: dict) -> None:
    print(f"demo finished in {r['wall_time_s']:.1f} s")
    from ..frequency import margin_text

    for k, m in r.get("margins", {}).items():
        print(f"  {k:9s} {margin_text(m)}")
    for w in r["written"]:
        print(f"wrote {w}")
