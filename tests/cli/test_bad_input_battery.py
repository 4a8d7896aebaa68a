"""The bad-input battery (docs: reliability): every command, the parameter file, signals, signal
files and the Python API, each given one mistake.

Every CLI case asserts exit status 2, exactly one line on stderr that names the
offender (the flag, key or file), no traceback, nothing on stdout, and that the test's
tmp folder holds exactly the files the case put there (no output, no temporary file).
The cases run in-process through ``ema_casadi.cli.main`` (fast); a handful run as real
processes to prove that no traceback reaches stderr. Every case fails before any heavy
work (tiny --t-end and grids where a run would follow). API cases assert the exception
type (the toolkit's own, or TypeError for an unknown keyword) and a one-line message
naming the argument.
"""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import dataclass, field

import numpy as np
import pytest

import ema_casadi as ema
from conftest import REFERENCE, SMALL_SWEEP
from ema_casadi.cli import main

REF = str(REFERENCE)
TEXT = REFERENCE.read_text(encoding="utf-8")
#: The minimal valid command line of each command (outputs inside the tmp folder).
BASE = {
    "simulate": ["simulate", "{model}", "--t-end", "0.001"],
    "linearize": ["linearize", "{model}"],
    "margins": ["margins", "{model}"],
    "bode": ["bode", "{model}", "--points", "5"],
    "freqresp": ["freqresp", "{model}", "--amplitudes", "1mm", "--freqs", "1", "--max-periods", "3"],
    "export": ["export", "{model}", "--format", "json", "--out", "{tmp}/lin.json"],
    "tune": ["tune", "{model}", "--out", "{tmp}/tuned.toml", "--max-iter", "1"],
    "demo": ["demo", "{model}", "--out", "{tmp}/out", "--no-progress"],
    "sweep": ["sweep", "{model}", "{tmp}/s.toml", "--jobs", "1", "--out", "{tmp}/s.csv"],
    "aircraft": ["aircraft", "{model}", "--no-responses", "--condition", "cruise_sl"],
    "limit-cycle": ["limit-cycle", "{model}", "--amplitudes", "1um,2um", "--freqs", "5,6", "--t-end", "0",
                    "--periods", "4"],
}
COMMANDS = list(BASE)


@dataclass
class Case:
    command: str
    args: list
    offender: str | list
    files: dict = field(default_factory=dict)  # name -> str (UTF-8) or bytes; a name ending in / is a folder
    model: str = REF
    raw: list | None = None  # the whole command line instead of BASE + args

    def argv(self, tmp):
        if self.raw is not None:
            return list(self.raw)
        base = [a.format(model=self.model.format(tmp=tmp), tmp=tmp) for a in BASE[self.command]]
        return _without(base, self.args) + [a.format(tmp=tmp) for a in self.args]


def _without(base: list, args: list) -> list:
    """``base`` without the flags (and their values) that ``args`` gives again: a
    single-valued flag is given once (a second occurrence is refused)."""
    given = {a.split("=", 1)[0] for a in args if a.startswith("--")}
    out, i = [], 0
    while i < len(base):
        if base[i] in given:
            i += 2 if i + 1 < len(base) and not base[i + 1].startswith("--") else 1
            continue
        out.append(base[i])
        i += 1
    return out


def edit(old: str, new: str) -> str:
    assert old in TEXT, old
    return TEXT.replace(old, new, 1)


def without_table(name: str) -> str:
    return re.sub(rf"(?ms)^\[{name}\].*?(?=^\[|\Z)", "", TEXT)


M_LINE = 'M = { value = 3.0, unit = "kg" }'
CASES: dict[str, Case] = {}


def add(case_id: str, case: Case):
    assert case_id not in CASES, case_id
    CASES[case_id] = case


# -- the parameter file -----------------------------------------------------------------
PARAM_FILES = {
    "toml-syntax-brace": (edit(M_LINE, M_LINE[:-1]), "not valid TOML"),
    "toml-syntax-header": (edit("[screw]", "[screw"), "not valid TOML"),
    "toml-duplicate-key": (edit(M_LINE, M_LINE + "\n" + M_LINE), "not valid TOML"),
    "toml-nul-byte": (edit(M_LINE, M_LINE + "\x00"), "not valid TOML"),
    "unit-wrong": (edit('value = 3.0, unit = "kg"', 'value = 3.0, unit = "g"'), "[screw] M: unit 'g'"),
    "unit-missing": (edit(M_LINE, "M = { value = 3.0 }"), "[screw] M: expected a table"),
    "plain-number": (edit(M_LINE, "M = 3.0"), "[screw] M: expected a table"),
    "extra-field": (edit(M_LINE, 'M = { value = 3.0, unit = "kg", tol = 1 }'), "[screw] M: unexpected field"),
    "type-string": (edit('value = 3.0, unit = "kg"', 'value = "3.0", unit = "kg"'), "[screw] M: expected a number"),
    "type-bool": (edit('value = 3.0, unit = "kg"', 'value = true, unit = "kg"'), "[screw] M: expected a number"),
    "type-array": (edit('value = 3.0, unit = "kg"', 'value = [3.0], unit = "kg"'), "[screw] M: expected a number"),
    "type-date": (edit('value = 3.0, unit = "kg"', 'value = 1979-05-27, unit = "kg"'), "[screw] M: expected a number"),
    "type-table": (edit('value = 3.0, unit = "kg"', 'value = { a = 1 }, unit = "kg"'), "[screw] M: expected a number"),
    "nan": (edit('value = 3.0, unit = "kg"', 'value = nan, unit = "kg"'), "[screw] M: expected a finite number"),
    "inf": (edit('value = 3.0, unit = "kg"', 'value = inf, unit = "kg"'), "[screw] M: expected a finite number"),
    "huge-int": (edit('value = 3.0, unit = "kg"', f'value = {10**400}, unit = "kg"'), "[screw] M: expected a finite"),
    "negative": (edit('value = 3.0, unit = "kg"', 'value = -3.0, unit = "kg"'), "[screw] M: must be positive"),
    "zero": (edit('value = 3.0, unit = "kg"', 'value = 0, unit = "kg"'), "[screw] M: must be positive"),
    "fraction-above-1": (edit('eta = { value = 0.90', 'eta = { value = 1.2'), "[screw] eta: must be in (0, 1]"),
    "non-integer": (re.sub(r"pp = \{ value = [0-9.]+", "pp = { value = 4.5", TEXT, count=1),
                    "[motor] pp: must be a positive integer"),
    "nonneg-negative": (re.sub(r"B = \{ value = [0-9.e-]+", "B = { value = -1e-5", TEXT, count=1),
                        "[screw] B: must be non-negative"),
    "missing-key": (edit(M_LINE, ""), "[screw] missing key 'M'"),
    "unknown-key": (edit("M = { value", "Mass = { value"), "[screw] unknown key 'Mass'"),
    "key-in-wrong-table": (edit("[screw]\n", '[screw]\nK_x = { value = 1.0, unit = "1/s" }\n'),
                           "[screw] unknown key 'K_x'"),
    "missing-table": (without_table("motor"), "missing table [motor]"),  # read by every motor variant
    "unknown-table": (TEXT + '\n[gearbox]\nratio = { value = 2.0, unit = "1" }\n', "unknown table [gearbox]"),
    "misspelt-table": (edit("[endstop]", "[end_stop]"), "unknown table [end_stop]"),
    "model-not-a-table": ('model = 3\n' + without_table("model"), "[model] must be a table"),
    "group-not-a-table": ('thermal = 3\n' + without_table("thermal"), "[thermal] must be a table"),
    "variant-value": (edit('motor = "pmsm"', 'motor = "bldc"'), "unknown motor variant 'bldc'"),
    "variant-key": (edit('motor = "pmsm"', 'motr = "pmsm"'), "unknown variant key 'motr'"),
    "variant-not-a-string": (edit('motor = "pmsm"', "motor = 3"), "[model] motor must be a variant name"),
    "variant-option-value": (edit('friction_shape = "tanh"', 'friction_shape = "round"'), "friction_shape"),
    "empty-file": ("", "missing table"),
    "latin-1": (edit("# CESA", "# CÉSA").encode("latin-1"), "not UTF-8"),
    "utf-16": (TEXT.encode("utf-16"), "UTF-16"),
    "binary": (bytes(range(256)) * 4, "not UTF-8"),
}
for i, (case_id, (content, message)) in enumerate(PARAM_FILES.items()):
    name = f"bad-{case_id}.toml"
    add(f"param-{case_id}", Case(COMMANDS[i % len(COMMANDS)], [], [name, message], {name: content},
                                 model="{tmp}/" + name))
# every command reports the file problems the same way
for cmd in COMMANDS:
    add(f"{cmd}-param-missing-file", Case(cmd, [], ["none.toml", "no such parameter file"], model="{tmp}/none.toml"))
    add(f"{cmd}-param-folder", Case(cmd, [], ["adir", "is a folder"], {"adir/": None}, model="{tmp}/adir"))
    add(f"{cmd}-param-latin-1", Case(cmd, [], ["enc.toml", "not UTF-8"],
                                     {"enc.toml": edit("# CESA", "# CÉSA").encode("latin-1")}, model="{tmp}/enc.toml"))
    add(f"{cmd}-variant-value", Case(cmd, ["--variant", "screw=spring"], "unknown screw variant 'spring'"))
    add(f"{cmd}-variant-key", Case(cmd, ["--variant", "motr=dc"], "unknown variant key 'motr'"))
    add(f"{cmd}-variant-syntax", Case(cmd, ["--variant", "screw"], "--variant expects KEY=VALUE"))
    add(f"{cmd}-unknown-flag", Case(cmd, ["--bogus-flag", "1"], "--bogus-flag"))

# -- simulate: signal strings -----------------------------------------------------------
SIGNALS = {
    "x-cmd-unknown-form": ("--x-cmd", "stp:1mm", "--x-cmd 'stp:1mm'"),
    "x-cmd-no-amplitude": ("--x-cmd", "step:", "--x-cmd"),
    "x-cmd-unit": ("--x-cmd", "step:1furlong", "unknown length unit 'furlong'"),
    "x-cmd-force-unit": ("--x-cmd", "10kN", "--x-cmd '10kN': unknown length unit 'kN'"),
    "x-cmd-bad-time": ("--x-cmd", "step:1mm@abc", "--x-cmd"),
    "x-cmd-empty-time": ("--x-cmd", "step:1mm@", "--x-cmd"),
    "x-cmd-sine-no-freq": ("--x-cmd", "sine:1mm", "--x-cmd 'sine:1mm'"),
    "x-cmd-sine-negative-freq": ("--x-cmd", "sine:1mm@-2", "frequency must be positive"),
    "x-cmd-sine-zero-freq": ("--x-cmd", "sine:1mm@0", "frequency must be positive"),
    "x-cmd-chirp-no-range": ("--x-cmd", "chirp:1mm@5", "expected chirp:AMP@F0-F1"),
    "x-cmd-chirp-bad-range": ("--x-cmd", "chirp:1mm@a-b", "--x-cmd"),
    "x-cmd-inf": ("--x-cmd", "1e400", "--x-cmd"),
    "x-cmd-nan": ("--x-cmd", "nan", "--x-cmd 'nan'"),
    "x-cmd-empty": ("--x-cmd", "", "--x-cmd"),
    "x-cmd-empty-term": ("--x-cmd", "step:1mm++sine:1mm@1", "empty term"),
    "x-cmd-percent-unit-twice": ("--x-cmd", "step:1%%", "--x-cmd"),
    "f-ext-length-unit": ("--f-ext", "1mm", "--f-ext '1mm': unknown force unit 'mm'"),
    "f-ext-kg": ("--f-ext", "10kg", "--f-ext '10kg': unknown force unit 'kg'"),
    "f-ext-percent": ("--f-ext", "5%", "--f-ext"),
    "f-ext-ramp": ("--f-ext", "ramp:1", "a ramp of force is not supported"),
    "f-ext-negative-unit": ("--f-ext", "-30kg", "--f-ext '-30kg'"),
    "f-ext-words": ("--f-ext", "thirty", "--f-ext 'thirty'"),
}
for case_id, (flag, value, message) in SIGNALS.items():
    add(f"signal-{case_id}", Case("simulate", [f"{flag}={value}"], message))
INPUTS = {
    "kind": ("eta=900mm", "--input eta: '900mm': unknown dimensionless unit 'mm'"),
    "unknown": ("T_cab=20", "--input 'T_cab': unknown input"),
    "no-value": ("eta", "--input 'eta': expected NAME=SIGNAL"),
    "empty-value": ("eta=", "--input 'eta=': expected NAME=SIGNAL"),
    "x-cmd-by-name": ("x_cmd=1", "--input x_cmd: use --x-cmd"),
    "injection-unit": ("d_x=step:1kN", "--input d_x"),
    "injection-form": ("d_i=sine:1", "--input d_i"),
}
for case_id, (value, message) in INPUTS.items():
    add(f"input-{case_id}", Case("simulate", ["--input", value], message))

# -- simulate: signal files -------------------------------------------------------------
SIGNAL_FILES = {
    "first-column-not-time": ("x,value\n0,0\n1,1\n", "the first column must be the time"),
    "duplicate-column": ("time,a,a\n0,0,0\n1,1,1\n", "column 'a' appears twice"),
    "second-time-column": ("time,x,t\n0,0,0\n1,1,1\n", "a second time column"),
    "empty-header-cell": ("time,,x\n0,0,0\n1,1,1\n", "column 2 of the header has no name"),
    "empty": ("", "empty table"),
    "only-comments": ("# nothing here\n\n", "empty table"),
    "header-only": ("time,x_cmd\n", "at least two rows"),
    "one-row": ("time,x_cmd\n0,0\n", "at least two rows"),
    "non-numeric": ("time,x_cmd\n0,0\n1,abc\n", "line 3, column 'x_cmd': 'abc' is not a number"),
    "non-numeric-time": ("time,x_cmd\n0,0\none,1\n", "line 3, column 'time'"),
    "empty-cell": ("time,x_cmd\n0,0\n1,\n", "line 3, column 'x_cmd'"),
    "nan-cell": ("time,x_cmd\n0,0\n1,nan\n", "non-finite value 'nan'"),
    "inf-time": ("time,x_cmd\n0,0\ninf,1\n", "non-finite value 'inf'"),
    "time-repeats": ("time,x_cmd\n0,0\n1,1\n1,2\n", "line 4: the time must increase strictly"),
    "time-decreases": ("time,x_cmd\n0,0\n2,1\n1,2\n", "the time must increase strictly"),
    "row-short": ("time,x_cmd\n0,0\n1\n", "line 3 has 1 cells, the header 2"),
    "row-long": ("time,x_cmd\n0,0\n1,1,1\n", "line 3 has 3 cells, the header 2"),
    "unit-not-length": ("time,x_cmd [N]\n0,0\n1,1\n", "unit 'N' is not a length unit"),
    "unit-unknown": ("time,x_cmd [furlong]\n0,0\n1,1\n", "unit 'furlong' is not a length unit"),
    "unit-row-not-length": ("time,x_cmd\nUnit:,N\n0,0\n1,1\n", "unit 'N' is not a length unit"),
    "unit-conflict": ("time,x_cmd [mm]\nUnit:,m\n0,0\n1,1\n", "unit [mm] in the header but 'm' in the Unit: row"),
    "unit-two-rows": ("time,x_cmd\nUnit:,m\nUnit:,m\n0,0\n1,1\n", "a second 'Unit:' row"),
    "unit-row-long": ("time,x_cmd\nUnit:,m,m\n0,0\n1,1\n", "the 'Unit:' row has 3 cells"),
    "time-unit": ("time [min],x_cmd\n0,0\n1,1\n", "unit 'min' is not a time unit"),
    "multi-column": ("time,x_cmd,f_ext\n0,0,0\n1,1,1\n", "2 signal columns (x_cmd, f_ext); pick one"),
    "latin-1": ("time,x_cmd [µm]\n0,0\n1,1\n".encode("latin-1"), "not UTF-8 text (byte 0xb5 on line 1)"),
    "utf-16": ("time,x_cmd\n0,0\n1,1\n".encode("utf-16"), "UTF-16"),
    "nul-byte": (b"time,x_cmd\n0,0\x00\n1,1\n", "sig.csv"),
}
for i, (case_id, (content, message)) in enumerate(SIGNAL_FILES.items()):
    flag = ("--x-cmd", "--f-ext")[i % 2]
    if "length unit" in message or "µm" in str(content):
        flag = "--x-cmd"
    add(f"csv-{case_id}", Case("simulate", [flag, "{tmp}/sig.csv"], [flag, "sig.csv", message],
                               {"sig.csv": content}))
RUN = "time,x_cmd,f_ext,x_rod\nUnit:,m,N,m\n0,0,0,0\n1,0.001,10,0.0009\n"
add("csv-selector-missing-column", Case("simulate", ["--x-cmd", "{tmp}/run.csv:x_rood"],
                                        ["--x-cmd", "run.csv", "no column 'x_rood' (did you mean 'x_rod'?)"],
                                        {"run.csv": RUN}))
add("csv-selector-wrong-kind", Case("simulate", ["--x-cmd", "{tmp}/run.csv:f_ext"],
                                    ["--x-cmd", "column 'f_ext': unit 'N' is not a length unit"], {"run.csv": RUN}))
add("csv-selector-force-from-length", Case("simulate", ["--f-ext", "{tmp}/run.csv:x_rod"],
                                           ["--f-ext", "unit 'm' is not a force unit"], {"run.csv": RUN}))
add("csv-percent-force", Case("simulate", ["--f-ext", "{tmp}/f.csv"], ["--f-ext", "unit '%' is not a force unit"],
                              {"f.csv": "time,f [%]\n0,0\n1,1\n"}))
add("csv-missing-file", Case("simulate", ["--x-cmd", "{tmp}/missing.csv"], ["--x-cmd", "missing.csv", "no such"]))
add("csv-folder", Case("simulate", ["--f-ext", "{tmp}/d.csv"], ["--f-ext", "d.csv", "is a folder"], {"d.csv/": None}))
add("csv-input-by-name", Case("simulate", ["--input", "eta={tmp}/eta.csv"], ["--input eta", "eta.csv", "'mm'"],
                              {"eta.csv": "time,eta [mm]\n0,0.9\n1,0.9\n"}))

# -- simulate: time and run-size flags --------------------------------------------------
TIME_FLAGS = {
    "t-end-zero": (["--t-end", "0"], "--t-end must be a positive number of seconds"),
    "t-end-negative": (["--t-end", "-1"], "--t-end must be a positive number of seconds"),
    "t-end-nan": (["--t-end", "nan"], "--t-end"),
    "t-end-inf": (["--t-end", "inf"], "--t-end"),
    "t-end-text": (["--t-end", "abc"], "--t-end"),
    "dt-zero": (["--dt", "0"], "--dt must be"),
    "dt-negative": (["--dt=-1e-5"], "--dt must be"),
    "dt-nan": (["--dt", "nan"], "--dt must be"),
    "dt-inf": (["--dt", "inf"], "--dt must be"),
    "dt-out-zero": (["--dt-out", "0"], "--dt-out must be"),
    "dt-out-negative": (["--dt-out=-1"], "--dt-out must be"),
    "dt-out-negative-spaced": (["--dt-out", "-1"], "--dt-out must be"),
    "dt-out-nan": (["--dt-out", "nan"], "--dt-out must be"),
    "dt-out-inf": (["--dt-out", "inf"], "--dt-out must be"),
    "event-tol-zero": (["--solver", "cvodes", "--event-tol", "0"], "--event-tol must be"),
    "event-tol-nan": (["--solver", "cvodes", "--event-tol", "nan"], "--event-tol must be"),
    "event-tol-inf": (["--solver", "cvodes", "--event-tol", "inf"], "--event-tol must be"),
    "t-end-huge": (["--t-end", "1e9", "--solver", "rk4"], ["--t-end 1e+09 s / --dt 1e-05 s", "RK4 steps", "MAX_STEPS"]),
    "dt-tiny": (["--t-end", "0.2", "--dt", "1e-10", "--solver", "rk4"],
                ["--dt 1e-10 s", "2e+09 RK4 steps", "0.7 us per step"]),
    "dt-not-dividing": (["--t-end", "0.2", "--dt", "3e-6", "--solver", "rk4"],
                        "--t-end 0.2 s is not a whole number of RK4 steps --dt"),
    "dt-out-not-whole-steps": (["--dt-out", "7e-6", "--solver", "rk4"],
                               "--dt-out 7e-06 s is not a whole number of RK4 steps --dt"),
    "dt-out-below-dt": (["--dt-out", "1e-6", "--solver", "rk4"], "--dt-out 1e-06 s is not a whole number"),
    "result-too-big": (["--t-end", "2000", "--dt-out", "5e-6"], ["--dt-out 5e-06 s", "MAX_RESULT_BYTES"]),
    "cvodes-result-too-big": (["--solver", "cvodes", "--t-end", "1e9"], ["--t-end 1e+09 s", "MAX_RESULT_BYTES"]),
    "dt-longer-than-t-end": (["--dt", "0.01", "--solver", "rk4"], "--dt (0.01 s) is longer than --t-end"),
    "zoh-with-cvodes": (["--zoh", "--solver", "cvodes"], "--zoh (sampled ECU) needs solver rk4"),
    "zoh-with-rosenbrock": (["--zoh", "--solver", "rosenbrock"], "--zoh (sampled ECU) needs solver rk4"),
    "rosenbrock-hybrid": (["--solver", "rosenbrock", "--variant", "friction=hybrid"],
                          "--solver rosenbrock does not handle hybrid (stick-slip) friction"),
    "solver-unknown": (["--solver", "euler"], "--solver"),
}
for case_id, (args, message) in TIME_FLAGS.items():
    add(f"time-{case_id}", Case("simulate", args, message))
OUTPUTS = {
    "out-suffix": (["--out", "{tmp}/run.txt"], "--out"),
    "out-folder-missing": (["--out", "{tmp}/nodir/run.csv"], "--out"),
    "plot-suffix": (["--plot", "{tmp}/run.jpg"], "--plot"),
    "out-and-bad-signal": (["--out", "{tmp}/run.csv", "--x-cmd", "stp:1"], "--x-cmd"),
    "out-mat-and-bad-dt-out": (["--out", "{tmp}/run.mat", "--dt-out", "0"], "--dt-out"),
}
for case_id, (args, message) in OUTPUTS.items():
    add(f"simulate-{case_id}", Case("simulate", args, message))
# the switched bridge: rk4 only, whole carrier periods (62.5 us at 16 kHz)
PWM = {
    "pwm-cvodes": (["--variant", "inverter=pwm", "--solver", "cvodes"], ["--solver cvodes", "switches"]),
    "pwm-not-whole-periods": (["--variant", "inverter=pwm", "--t-end", "0.00101", "--dt", "1e-6"],
                              ["--t-end 0.00101 s", "carrier periods"]),
    "pwm-dc-motor": (["--variant", "inverter=pwm", "--variant", "motor=dc"], "inverter=pwm needs motor=pmsm"),
    "supply-unknown": (["--variant", "supply=battery"], "unknown supply variant 'battery'"),
}
for case_id, (args, message) in PWM.items():
    add(f"simulate-{case_id}", Case("simulate", args, message))

# -- linearize, margins, bode, export: operating point and their own flags ---------------
OP_FLAGS = {
    "x-cmd-outside-stroke": (["--x-cmd", "100mm"], "outside the stroke"),
    "x-cmd-force": (["--x-cmd", "1kN"], "--x-cmd '1kN': unknown length unit"),
    "x-cmd-inf": (["--x-cmd", "1e400"], "--x-cmd '1e400': not a finite number"),
    "f-ext-length": (["--f-ext", "1mm"], "--f-ext '1mm': unknown force unit"),
    "f-ext-too-big": (["--f-ext", "100kN"], "current limit"),
    "f-ext-too-big-pulling": (["--f-ext", "-100kN"], "current limit"),
    "v-rod-text": (["--v-rod", "abc"], "--v-rod 'abc'"),
    "v-rod-force": (["--v-rod", "1kN"], "--v-rod '1kN'"),
    "friction-policy": (["--friction", "hard"], "--friction"),
    "backlash-policy": (["--backlash", "on"], "--backlash"),
}
for i, (case_id, (args, message)) in enumerate(OP_FLAGS.items()):
    for cmd in (("linearize", "margins", "bode", "export")[i % 4], ("linearize", "margins", "bode", "export")[
            (i + 1) % 4]):
        add(f"{cmd}-{case_id}", Case(cmd, args, message))
OWN = {
    "linearize": {
        "open-unknown": (["--open", "speed"], "--open"),
        "out-suffix": (["--out", "{tmp}/lin.txt"], "--out"),
        "out-folder-missing": (["--out", "{tmp}/nodir/lin.mat"], "--out"),
    },
    "margins": {
        "loop-unknown": (["--loop", "torque"], "--loop"),
        "outer-unknown": (["--outer", "half"], "--outer"),
        "fmin-zero": (["--fmin", "0"], "--fmin/--fmax"),
        "fmax-nan": (["--fmax", "nan"], "--fmin/--fmax"),
        "window-reversed": (["--fmin", "10", "--fmax", "1"], "--fmin/--fmax"),
        "window-too-wide": (["--fmin", "1e-300", "--fmax", "1e300"], ["--fmin/--fmax", "MAX_FREQ_POINTS"]),
        "plot-suffix": (["--plot", "{tmp}/m.svg"], "--plot"),
    },
    "bode": {
        "points-one": (["--points", "1"], "--points must be at least 2"),
        "points-huge": (["--points", "2e7"], ["--points 20000000", "MAX_FREQ_POINTS", "GB"]),
        "points-text": (["--points", "many"], "--points"),
        "points-fraction": (["--points", "2.5"], "--points"),
        "kind-unknown": (["--kind", "nyquist"], "--kind"),
        "loop-unknown": (["--loop", "torque"], "--loop"),
        "fmin-negative": (["--fmin=-1"], "--fmin/--fmax"),
        "fmax-inf": (["--fmax", "inf"], "--fmin/--fmax"),
        "plot-suffix": (["--plot", "{tmp}/b.txt"], "--plot"),
    },
    "export": {
        "format-unknown": (["--format", "fmu2"], "--format"),
        "out-suffix": (["--out", "{tmp}/lin.txt"], "--out"),
        "out-folder-missing": (["--out", "{tmp}/nodir/lin.json"], "--out"),
        "c-name": (["--format", "c", "--out", "{tmp}/1bad.c"], ["--out", "1bad.c", "C identifier"]),
        "open-unknown": (["--open", "speed"], "--open"),
    },
    "freqresp": {
        "amplitudes-text": (["--amplitudes", "abc"], "--amplitudes 'abc'"),
        "amplitudes-zero": (["--amplitudes", "0"], "--amplitudes: values must be positive"),
        "amplitudes-negative": (["--amplitudes", "-1mm"], "--amplitudes: values must be positive"),
        "amplitudes-force": (["--amplitudes", "1kN"], "--amplitudes '1kN'"),
        "amplitudes-empty-item": (["--amplitudes", "1mm,,2mm"], "--amplitudes"),
        "freqs-text": (["--freqs", "fast"], "--freqs"),
        "freqs-zero": (["--freqs", "0"], "--freqs: values must be positive"),
        "freqs-negative": (["--freqs", "-1"], "--freqs: values must be positive"),
        "freqs-range-one-point": (["--freqs", "0.1-30:1"], "--freqs 0.1-30:1"),
        "freqs-range-reversed": (["--freqs", "30-0.1:10"], "--freqs 30-0.1:10"),
        "freqs-range-huge": (["--freqs", "0.1-30:100000000"], ["--freqs 0.1-30:100000000", "MAX_SINE_STREAM_POINTS"]),
        "grid-too-big": (["--amplitudes", "1mm,2mm,3mm", "--freqs", "0.1-30:50000"],
                         ["--loads/--amplitudes/--freqs", "MAX_SINE_STREAM_POINTS"]),
        "periods-too-many": (["--freqs", "0.1-30:1000", "--max-periods", "100000"],
                             ["--max-periods", "MAX_SINE_STREAM_PERIODS"]),
        "loads-text": (["--loads", "heavy"], "--loads 'heavy'"),
        "loads-unit": (["--loads", "10kg"], "--loads '10kg'"),
        "loads-inf": (["--loads", "1e400"], "--loads: non-finite value"),
        "jobs-zero": (["--jobs", "0"], "--jobs must be a positive integer"),
        "max-periods-two": (["--max-periods", "2"], "--max-periods must be at least 3"),
        "tol-db-zero": (["--tol-db", "0"], "--tol-db must be a positive number"),
        "tol-deg-nan": (["--tol-deg", "nan"], "--tol-deg must be a positive number"),
        "scheduler-address": (["--scheduler", "localhost"], "--scheduler localhost"),
        "out-suffix": (["--out", "{tmp}/fr.txt"], "--out"),
        "plot-suffix": (["--plot", "{tmp}/fr.csv"], "--plot"),
    },
    "tune": {
        "gm-zero": (["--gm", "0"], "--gm must be a positive number of dB"),
        "pm-above-90": (["--pm", "100"], "--pm must be between 0 and 90 deg"),
        "pm-nan": (["--pm", "nan"], "--pm"),
        "overshoot-negative": (["--overshoot=-1"], "--overshoot must be a non-negative percentage"),
        "sigma-negative": (["--sigma", "-1"], "--sigma"),
        "ms-below-1": (["--ms", "0.5"], "--ms must be above 1"),
        "bandwidth-min-zero": (["--bandwidth-min", "0"], "--bandwidth-min"),
        "max-iter-zero": (["--max-iter", "0"], "--max-iter must be at least 1"),
        "loads-text": (["--loads", "abc"], "--loads 'abc'"),
        "loads-empty-item": (["--loads", "0,,1kN"], "--loads '0,,1kN': empty entry"),
        "step-zero": (["--step", "0"], "--step must be a positive length"),
        "step-force": (["--step", "1kN"], "--step '1kN'"),
        "sim-step-text": (["--sim-step", "big"], "--sim-step 'big'"),
        "out-suffix": (["--out", "{tmp}/tuned.txt"], "--out"),
        "plot-dir-parent-missing": (["--plot-dir", "{tmp}/nodir/sub"], "--plot-dir"),
        "start-scale-zero": (["--start-scale", "0"], "--start-scale must be positive"),
        "rate-ratio": (["--rate-ratio", "0.5"], "--rate-ratio must be 0 (off) or at least 1"),
        "objective-unknown": (["--objective", "speed"], "--objective"),
    },
    "demo": {
        "out-is-a-file": (["--out", "{tmp}/afile"], "--out"),
    },
}
OWN["aircraft"] = {  # the aircraft loop
    "condition-unknown": (["--condition", "cruise"], "--condition"),
    "t-end-negative": (["--t-end", "-1"], "--t-end"),
    "gust-time-zero": (["--gust-time", "0"], "--gust-time"),
    "plot-dir-is-a-file": (["--plot-dir", "{tmp}/afile"], "--plot-dir"),
}
OWN["limit-cycle"] = {
    "loop-unknown": (["--loop", "speed"], "--loop"),
    "freqs-bad-range": (["--freqs", "5-1:3"], "--freqs"),
    "amplitudes-unit": (["--amplitudes", "1furlong,2mm"], "furlong"),
    "plot-suffix": (["--plot", "{tmp}/lc.txt"], "--plot"),
    "dt-too-large": (["--dt", "0.1"], "--dt"),
    "harmonics-first": (["--harmonics", "1,3"], "--harmonics"),
    "harmonics-not-whole": (["--harmonics", "3.5"], "--harmonics"),
    "harmonics-text": (["--harmonics", "odd"], "--harmonics"),
}
for cmd, cases in OWN.items():
    for case_id, (args, message) in cases.items():
        # a flag given twice: the last wins
        files = {"afile": "x"} if case_id in ("out-is-a-file", "plot-dir-is-a-file") else {}
        add(f"{cmd}-{case_id}", Case(cmd, args, message, files))
# -- ema sweep: the description file ------------------------------------------------------
SWEEP_OK = SMALL_SWEEP
SWEEP = {
    "not-toml": (SWEEP_OK.replace("[metrics]", "[metrics"), ["s.toml", "not valid TOML"]),
    "unknown-table": (SWEEP_OK + "[plots]\n", ["s.toml", "unknown table 'plots'"]),
    "unknown-parameter": (SWEEP_OK.replace("B = {", "Bx = {"), ["[parameters] Bx", "no parameter 'Bx'"]),
    "invalid-value": (SWEEP_OK.replace("2e-5", "-2e-5"), ["run 0", "B"]),
    "distribution": (SWEEP_OK.replace("values = [2e-5, 1e-4]", 'distribution = "gauss", low = 0, high = 1e-4'),
                     ["[parameters] B distribution", "'gauss' unknown"]),
    "no-seed": (SWEEP_OK.replace("values = [2e-5, 1e-4]", 'distribution = "uniform", low = 0, high = 1e-4'),
                ["[sweep] seed", "needed"]),
    "metric": (SWEEP_OK.replace("peak = {}", "overshoot = {}"), ["[metrics]", "unknown metric 'overshoot'"]),
    "metric-option": (SWEEP_OK.replace("peak = {}", "peak = { signal = 'i_q' }"), ["[metrics] peak", "'signal'"]),
    "dt-not-whole": (SWEEP_OK.replace("dt = 1e-4", "dt = 3e-4"), ["[scenario] duration", "whole number"]),
    "signal": (SWEEP_OK.replace("step:1mm@0.001", "stepp:1mm"), ["[scenario] x_cmd", "stepp"]),
    "variant": (SWEEP_OK.replace('friction = "hybrid"', 'friction = "sticky"'), ["[variants] friction", "'sticky'"]),
    "samples-without-draws": ("[sweep]\nsamples = 3\n" + SWEEP_OK, ["[sweep] samples", "no parameter is drawn"]),
    "jobs-zero": (SWEEP_OK, "--jobs must be a positive integer", ["--jobs", "0"]),
    "out-suffix": (SWEEP_OK, "--out", ["--out", "{tmp}/s.txt"]),
    "journal-exists": (SWEEP_OK, ["s.csv.journal", "--resume"], [], {".s.csv.journal": "{}\n"}),
}
for case_id, (text, message, *more) in SWEEP.items():
    extra = more[0] if more else []
    files = {"s.toml": text, **(more[1] if len(more) > 1 else {})}
    add(f"sweep-{case_id}", Case("sweep", extra, message, files))
add("sweep-spec-missing", Case("sweep", [], ["none.toml", "no such sweep file"],
                               raw=["sweep", REF, "none.toml", "--jobs", "1"]))
add("sweep-scheduler-address", Case("sweep", [], "--scheduler localhost", {"s.toml": SWEEP_OK},
                                    raw=["sweep", REF, "s.toml", "--scheduler", "localhost"]))
add("sweep-resume-without-out", Case("sweep", [], "--resume has no effect without --out", {"s.toml": SWEEP_OK},
                                     raw=["sweep", REF, "s.toml", "--resume"]))
add("top-unknown-command", Case("simulate", [], "unknown command 'simulat' (did you mean 'simulate'?)",
                                raw=["simulat", REF]))
# a bare --sigma is SI: 0.3 m is four times the stroke, refused with the units that read it right
for cmd in ("identify", "design-experiment"):
    add(f"{cmd}-sigma-bare-implausible", Case("simulate", [], ["--sigma x_rod=0.3", "0.3 m", "1.5 x the stroke",
                                                               "x_rod=0.3um"], raw=[cmd, "--sigma", "x_rod=0.3"]))
# the mistyped command is named, not its flags (argparse's order blamed --t-end)
add("top-unknown-command-with-flag", Case("simulate", [], "unknown command 'simulat' (did you mean 'simulate'?)",
                                          raw=["simulat", "--t-end", "0.2"]))
add("top-no-command", Case("simulate", [], "required: COMMAND", raw=[]))


def _files(root):
    return sorted(str(p.relative_to(root)) + ("/" if p.is_dir() else "") for p in root.rglob("*"))


def _setup(case: Case, tmp):
    for name, content in case.files.items():
        path = tmp / name
        if name.endswith("/"):
            path.mkdir()
        elif isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")


def _offenders(case: Case, tmp):
    items = case.offender if isinstance(case.offender, list) else [case.offender]
    return [o.format(tmp=tmp) if "{tmp}" in o else o for o in items]


@pytest.mark.parametrize("case_id", list(CASES))
def test_cli_bad_input(case_id, tmp_path, capsys, monkeypatch):
    case = CASES[case_id]
    monkeypatch.chdir(tmp_path)  # a default output (ema_lin.json, out/) would land here
    _setup(case, tmp_path)
    before = _files(tmp_path)
    try:
        status = main(case.argv(tmp_path))
    except SystemExit as exc:  # argparse's own errors
        status = exc.code
    out, err = capsys.readouterr()
    assert status == 2, err
    assert err.endswith("\n") and err.count("\n") == 1, err
    for offender in _offenders(case, tmp_path):
        assert offender in err, f"{offender!r} not in {err!r}"
    assert "Traceback" not in err
    assert out == ""
    assert _files(tmp_path) == before, "a file was left behind"


def test_the_battery_is_large_and_covers_every_command():
    assert len(CASES) >= 150
    assert {c.command for c in CASES.values()} == set(COMMANDS)


# -- as real processes: nothing but the one line reaches stderr --------------------------
PROCESS_CASES = {
    "param-latin-1": "param-latin-1",
    "dt-out-negative": "time-dt-out-negative-spaced",
    "bode-points": "bode-points-huge",
    "freqresp-amplitudes": "freqresp-amplitudes-text",
    "export-param-folder": "export-param-folder",
}


@pytest.mark.parametrize("name", list(PROCESS_CASES))
def test_as_a_process(name, tmp_path):
    case = CASES[PROCESS_CASES[name]]
    _setup(case, tmp_path)
    before = _files(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "ema_casadi.cli", *case.argv(tmp_path)], capture_output=True,
                          text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.splitlines()) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for offender in _offenders(case, tmp_path):
        assert offender in proc.stderr
    assert _files(tmp_path) == before


# -- the Python API ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def api(params, model_cache):
    model = model_cache()
    op = ema.operating_point(model)
    return {"params": params, "model": model, "op": op, "lin": ema.linear_model(model, op),
            "T": ema.closed_loop(model, op), "L": ema.linearisation.loop_model(model, "position", op)}


nan = float("nan")
E = ema
API_CASES = {
    # parameters and models
    "load_parameters-path-type": (lambda c: E.load_parameters(3), E.ParameterError, "path"),
    "load_parameters-variants-type": (lambda c: E.load_parameters(REF, "pmsm"), E.ParameterError, "variants"),
    "load_parameters-missing": (lambda c: E.load_parameters(c["tmp"] / "none.toml"), E.ParameterError, "none.toml"),
    "build_model-variants-str": (lambda c: E.build_model(c["params"], "pmsm"), E.ParameterError, "variant"),
    "build_model-params-str": (lambda c: E.build_model("x"), E.ParameterError, "params"),
    "build_model-variant-value": (lambda c: E.build_model(c["params"], {"motor": "bldc"}), E.ParameterError, "bldc"),
    "vector-text": (lambda c: c["params"].vector(K_x="abc"), E.ParameterError, "K_x"),
    "vector-nan": (lambda c: c["params"].vector(K_x=nan), E.ParameterError, "K_x"),
    "vector-unknown": (lambda c: c["params"].vector(K_xx=1.0), TypeError, "K_xx"),
    "replace-negative": (lambda c: c["params"].replace(M=-1.0), E.ParameterError, "M"),
    # simulate
    "simulate-model": (lambda c: E.simulate("notamodel", 0.1), E.SimulationError, "model"),
    "simulate-x0-short": (lambda c: E.simulate(c["model"], 0.01, x0=[0, 0]), E.SimulationError, "x0"),
    "simulate-x0-nan": (lambda c: E.simulate(c["model"], 0.01, x0=[nan] * 9), E.SimulationError, "x0"),
    "simulate-x0-text": (lambda c: E.simulate(c["model"], 0.01, x0="zero"), E.SimulationError, "x0"),
    "simulate-x-cmd-nan": (lambda c: E.simulate(c["model"], 0.01, x_cmd=nan), E.SignalError, "x_cmd"),
    "simulate-f-ext-inf": (lambda c: E.simulate(c["model"], 0.01, f_ext=float("inf")), E.SignalError, "f_ext"),
    "simulate-x-cmd-list": (lambda c: E.simulate(c["model"], 0.01, x_cmd=[1, 2]), E.SignalError, "x_cmd"),
    "simulate-f-ext-unit": (lambda c: E.simulate(c["model"], 0.01, f_ext="10kg"), E.SignalError, "f_ext"),
    "simulate-eta-kind": (lambda c: E.simulate(c["model"], 0.01, eta="900mm"), E.SignalError, "eta"),
    "simulate-injection-type": (lambda c: E.simulate(c["model"], 0.01, d_x=object()), E.SignalError, "d_x"),
    "simulate-unknown-keyword": (lambda c: E.simulate(c["model"], 0.01, x_cmdd=1e-3), TypeError, "x_cmdd"),
    "simulate-t-end-text": (lambda c: E.simulate(c["model"], "0.1"), E.SimulationError, "t_end"),
    "simulate-t-end-nan": (lambda c: E.simulate(c["model"], nan), E.SimulationError, "t_end"),
    "simulate-t-end-bool": (lambda c: E.simulate(c["model"], True), E.SimulationError, "t_end"),
    "simulate-dt-zero": (lambda c: E.simulate(c["model"], 0.01, dt=0), E.SimulationError, "dt"),
    "simulate-dt-out-zero": (lambda c: E.simulate(c["model"], 0.01, dt_out=0), E.SimulationError, "dt_out"),
    "simulate-dt-out-negative": (lambda c: E.simulate(c["model"], 0.01, dt_out=-1), E.SimulationError, "dt_out"),
    "simulate-dt-out-inf": (lambda c: E.simulate(c["model"], 0.01, dt_out=float("inf")), E.SimulationError,
                            "dt_out"),
    "simulate-dt-out-not-steps": (lambda c: E.simulate(c["model"], 0.01, dt=1e-5, dt_out=1.5e-5, solver="rk4"),
                                  E.SimulationError, "dt_out"),
    "simulate-t-end-not-steps": (lambda c: E.simulate(c["model"], 0.2, dt=3e-6, solver="rk4"), E.SimulationError,
                                 "t_end"),
    "simulate-decimate-zero": (lambda c: E.simulate(c["model"], 0.01, decimate=0), E.SimulationError, "decimate"),
    "simulate-decimate-fraction": (lambda c: E.simulate(c["model"], 0.01, decimate=2.5), E.SimulationError,
                                   "decimate"),
    "simulate-decimate-and-dt-out": (lambda c: E.simulate(c["model"], 0.01, decimate=2, dt_out=1e-4),
                                     E.SimulationError, "decimate"),
    "simulate-event-tol": (lambda c: E.simulate(c["model"], 0.01, event_tol=-1), E.SimulationError, "event_tol"),
    "simulate-rtol": (lambda c: E.simulate(c["model"], 0.01, solver="cvodes", rtol=0), E.SimulationError, "rtol"),
    "simulate-solver": (lambda c: E.simulate(c["model"], 0.01, solver="euler"), E.SimulationError, "solver"),
    "simulate-zoh-cvodes": (lambda c: E.simulate(c["model"], 0.01, zoh=True, solver="cvodes"), E.SimulationError,
                            "zoh"),
    "simulate-rosenbrock-rtol": (lambda c: E.simulate(c["model"], 0.01, solver="rosenbrock", rtol=-1),
                                 E.SimulationError, "rtol"),
    "simulate-params-type": (lambda c: E.simulate(c["model"], 0.01, params="ref"), E.SimulationError, "params"),
    "simulate-p-short": (lambda c: E.simulate(c["model"], 0.01, p=[1.0, 2.0]), E.SimulationError, "p"),
    "simulate-steps-limit": (lambda c: E.simulate(c["model"], 1e9, solver="rk4"), E.SimulationError, "MAX_STEPS"),
    "simulate-memory-limit": (lambda c: E.simulate(c["model"], 1e6, solver="cvodes", dt_out=1e-5),
                              E.SimulationError, "MAX_RESULT_BYTES"),
    # signals
    "signal-step-text": (lambda c: E.Signal.step("1mm"), E.SignalError, "amp"),
    "signal-step-nan-time": (lambda c: E.Signal.step(1e-3, nan), E.SignalError, "t0"),
    "signal-sine-zero-freq": (lambda c: E.Signal.sine(1e-3, 0), E.SignalError, "freq"),
    "signal-chirp-duration": (lambda c: E.Signal.chirp(1e-3, 1, 5, 0), E.SignalError, "duration"),
    "signal-table-shapes": (lambda c: E.Signal.table([0, 1], [0]), E.SignalError, "Signal.table"),
    "signal-table-text": (lambda c: E.Signal.table(["a", "b"], [0, 1]), E.SignalError, "Signal.table"),
    "signal-constant-nan": (lambda c: ema.signals.constant(nan), E.SignalError, "value"),
    "parse-signal-list": (lambda c: E.parse_signal([1, 2]), E.SignalError, "list"),
    "parse-signal-kind": (lambda c: E.parse_signal("1", "pressure"), E.SignalError, "pressure"),
    # operating point and linearisation
    "op-f-ext-text": (lambda c: E.operating_point(c["model"], f_ext="30kN"), E.OperatingPointError, "f_ext"),
    "op-x-cmd-nan": (lambda c: E.operating_point(c["model"], x_cmd=nan), E.OperatingPointError, "x_cmd"),
    "op-v-rod-list": (lambda c: E.operating_point(c["model"], v_rod=[0.0]), E.OperatingPointError, "v_rod"),
    "op-model": (lambda c: E.operating_point("model"), E.OperatingPointError, "model"),
    "op-outside-stroke": (lambda c: E.operating_point(c["model"], x_cmd=1.0), E.OperatingPointError, "x_cmd"),
    "op-friction-policy": (lambda c: E.operating_point(c["model"], friction="hard"), E.LinearizationError,
                           "friction"),
    "op-eta-text": (lambda c: E.operating_point(c["model"], eta="high"), E.OperatingPointError, "eta"),
    "op-tol": (lambda c: E.operating_point(c["model"], tol=0), E.OperatingPointError, "tol"),
    "op-max-iter": (lambda c: E.operating_point(c["model"], max_iter=0), E.OperatingPointError, "max_iter"),
    "op-p-short": (lambda c: E.operating_point(c["model"], p=[1.0]), E.OperatingPointError, "p"),
    "op-params-type": (lambda c: E.operating_point(c["model"], params=3), E.OperatingPointError, "params"),
    "op-unknown-keyword": (lambda c: E.operating_point(c["model"], f_ex=1.0), TypeError, "f_ex"),
    "op-load-too-big": (lambda c: E.operating_point(c["model"], f_ext=100e3), E.OperatingPointError, "current"),
    "linear_model-op-text": (lambda c: E.linear_model(c["model"], "op"), E.LinearizationError, "op"),
    "linear_model-model": (lambda c: E.linear_model("model", c["op"]), E.LinearizationError, "model"),
    "linear_model-loops-type": (lambda c: E.linear_model(c["model"], c["op"], open_loops=5), E.LinearizationError,
                                "loops"),
    "linear_model-outputs-str": (lambda c: E.linear_model(c["model"], c["op"], outputs="x_rod"),
                                 E.LinearizationError, "outputs"),
    "linear_model-output-unknown": (lambda c: E.linear_model(c["model"], c["op"], outputs=["x_rood"]),
                                    E.LinearizationError, "x_rood"),
    "linearize-op-number": (lambda c: E.linearize(c["model"], 3), E.LinearizationError, "op"),
    "loop_model-loop-type": (lambda c: ema.linearisation.loop_model(c["model"], 3), E.LinearizationError, "loop"),
    "loop_transfer-unknown": (lambda c: E.loop_transfer(c["model"], "torque"), E.LinearizationError, "torque"),
    "select-unknown": (lambda c: c["lin"].select(["x_cmdd"]), E.LinearizationError, "x_cmdd"),
    # frequency response and margins
    "loop_margins-model": (lambda c: E.loop_margins("model"), E.LinearizationError, "model"),
    "loop_margins-op": (lambda c: E.loop_margins(c["model"], "op"), E.LinearizationError, "op"),
    "loop_margins-loops-type": (lambda c: E.loop_margins(c["model"], c["op"], loops=3), E.LinearizationError,
                                "loops"),
    "loop_margins-loop-unknown": (lambda c: E.loop_margins(c["model"], c["op"], loops="pos"), E.LinearizationError,
                                  "pos"),
    "loop_margins-outer": (lambda c: E.loop_margins(c["model"], c["op"], outer="half"), E.LinearizationError,
                           "outer"),
    "loop_margins-f-min": (lambda c: E.loop_margins(c["model"], c["op"], f_min=0), E.LinearizationError, "f_min"),
    "loop_margins-window": (lambda c: E.loop_margins(c["model"], c["op"], f_min=1e-300, f_max=1e300),
                            E.LinearizationError, "MAX_FREQ_POINTS"),
    "closed_loop-model": (lambda c: E.closed_loop("model"), E.LinearizationError, "model"),
    "dynamic_stiffness-f": (lambda c: E.dynamic_stiffness(c["model"], c["op"], f_hz=[0.0]), E.LinearizationError,
                            "f_hz"),
    "bode-sys": (lambda c: E.bode("x"), E.LinearizationError, "sys"),
    "bode-negative-f": (lambda c: E.bode(c["T"], [-1.0]), E.LinearizationError, "f_hz"),
    "bode-text-f": (lambda c: E.bode(c["T"], "abc"), E.LinearizationError, "f_hz"),
    "bode-too-many-f": (lambda c: E.bode(c["T"], np.logspace(0, 1, 200_001)), E.LinearizationError,
                        "MAX_FREQ_POINTS"),
    "bode-mimo": (lambda c: E.bode(c["lin"]), E.LinearizationError, "SISO"),
    "bode-input-unknown": (lambda c: E.bode(c["lin"], input="x_cmdd", output="x_rod"), E.LinearizationError,
                           "x_cmdd"),
    "margins-L": (lambda c: E.margins("x"), E.LinearizationError, "L"),
    "margins-per-decade": (lambda c: E.margins(c["L"], per_decade=0), E.LinearizationError, "per_decade"),
    "frequency_grid-reversed": (lambda c: ema.frequency.frequency_grid(10, 1), E.LinearizationError, "f_min"),
    "freqresp-sys": (lambda c: ema.frequency.freqresp(None, [1.0]), E.LinearizationError, "sys"),
    "bandwidth-level": (lambda c: ema.frequency.bandwidth(c["T"], level_db="x"), E.LinearizationError, "level_db"),
    # sine stream
    "sine_stream-model": (lambda c: E.sine_stream(c["model"], [1e-3], [1.0]), E.FreqRespError, "params"),
    "sine_stream-amplitudes-text": (lambda c: E.sine_stream(c["params"], "1mm", [1.0]), E.FreqRespError,
                                    "amplitudes"),
    "sine_stream-amplitudes-words": (lambda c: E.sine_stream(c["params"], ["a"], [1.0]), E.FreqRespError,
                                     "amplitudes"),
    "sine_stream-freqs-zero": (lambda c: E.sine_stream(c["params"], [1e-3], [0.0]), E.FreqRespError, "freqs"),
    "sine_stream-loads-nan": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], [nan]), E.FreqRespError, "loads"),
    "sine_stream-samples": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], samples=7), E.FreqRespError,
                            "samples"),
    "sine_stream-tol": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], tol_db="x"), E.FreqRespError, "tol_db"),
    "sine_stream-grid": (lambda c: E.sine_stream(c["params"], [1e-3], np.geomspace(0.1, 30, 200_000)),
                         E.FreqRespError, "MAX_SINE_STREAM_POINTS"),
    "sine_stream-periods": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0, 2.0], max_periods=10**8),
                            E.FreqRespError, "MAX_SINE_STREAM_PERIODS"),
    "sine_stream-variants-str": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], variants="pmsm"),
                                 E.FreqRespError, "variants"),
    "sine_stream-variant-entry": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], variants={"a": "pmsm"}),
                                  E.ParameterError, "unknown variant key 'a'"),
    "sine_stream-p-short": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], p=[1.0]), E.FreqRespError, "p"),
    "sine_stream-jobs": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], jobs=0), E.FreqRespError, "jobs"),
    "sine_stream-scheduler": (lambda c: E.sine_stream(c["params"], [1e-3], [1.0], scheduler=3), E.FreqRespError,
                              "scheduler"),
    # export
    "save_linear-lin": (lambda c: E.save_linear("x", c["tmp"] / "a.mat"), E.ExportError, "lin"),
    "save_linear-path": (lambda c: E.save_linear(c["lin"], 3), E.ExportError, "path"),
    "save_linear-format": (lambda c: E.save_linear(c["lin"], c["tmp"] / "a.txt"), E.ExportError, "a.txt"),
    "save_linear-fmt-type": (lambda c: E.save_linear(c["lin"], c["tmp"] / "a.mat", fmt=1), E.ExportError, "fmt"),
    "save_linear-folder": (lambda c: E.save_linear(c["lin"], c["tmp"] / "no" / "a.mat"), E.ExportError, "folder"),
    "save_linear-units": (lambda c: E.save_linear(c["lin"], c["tmp"] / "a.mat", units=["m"]), E.ExportError,
                          "units"),
    "export_function-model": (lambda c: E.export_function("x", c["tmp"] / "f.casadi"), E.ExportError, "model"),
    "export_function-c-name": (lambda c: E.export_function(c["model"], c["tmp"] / "1f.c"), E.ExportError,
                               "C identifier"),
    "load_linear-path": (lambda c: E.load_linear(3), E.ExportError, "path"),
    "load_linear-missing": (lambda c: E.load_linear(c["tmp"] / "none.json"), E.ExportError, "none.json"),
    # tuning (its own package; the entry point's type check)
    "tune-model": (lambda c: E.tune(c["model"]), E.ParameterError, "params"),
}


@pytest.mark.parametrize("case_id", list(API_CASES))
def test_api_bad_input(case_id, api, tmp_path):
    call, error, offender = API_CASES[case_id]
    ctx = dict(api, tmp=tmp_path)
    with pytest.raises(error) as exc:
        call(ctx)
    msg = str(exc.value)
    assert "\n" not in msg and msg.strip(), msg
    assert offender in msg, msg
    assert list(tmp_path.iterdir()) == []


def test_the_api_battery_covers_the_entry_points():
    assert len(API_CASES) >= 80
