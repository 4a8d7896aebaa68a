"""The parts' ports: every signal a part reads from another part is declared (a
:class:`~ema_casadi.model.components.Port`: name, unit, meaning), every declared port is
connected and read, and the assembly refuses, naming the part and the port, a read that
is not declared, a port nothing provides and a port whose unit is not its provider's.

Before the ports, 115 (part, signal) reads across part boundaries over the variant
harness's combinations were declared nowhere; the assembly's check now finds none."""

from __future__ import annotations

import pytest
from test_variant_harness import CASES

import ema_casadi as ema
from ema_casadi.cli import main
from ema_casadi.model.components import PART_CLASSES, AssemblyError, Bus, Port, load, monitors
from ema_casadi.model.components._ports import own_names


def test_every_read_across_parts_is_a_declared_port_and_every_port_is_read(monkeypatch):
    """Builds every combination of the variant harness with the reads recorded: the
    assembly's check lets none through undeclared (it raises), the recorded reads agree,
    and no part class declares a port that no combination reads (a stale declaration)."""
    reads: dict = {}
    seen: dict = {}
    check = Bus._check

    def record(self, name):
        part = self._who[-1] if self._who else None
        if part is not None:
            reads.setdefault(id(part), set()).add(name)
        return check(self, name)

    monkeypatch.setattr(Bus, "_check", record)
    params = ema.load_parameters()
    undeclared = []
    for case in CASES:
        reads.clear()
        model = ema.build_model(params, case.values[0])
        for part in model.parts:
            cross = reads.get(id(part), set()) - own_names(part)
            undeclared += [(type(part).__name__, n) for n in cross - {p.name for p in part.reads}]
            seen.setdefault(type(part), set()).update(cross)
    assert undeclared == []
    stale = [(cls.__name__, p.name) for cls in PART_CLASSES for p in cls.reads if p.name not in seen.get(cls, ())]
    assert stale == []
    n_ports = len({(cls, p.name) for cls in PART_CLASSES for p in cls.reads})
    assert n_ports >= 100  # the reads that were declared nowhere before


def test_an_undeclared_read_is_refused_naming_the_part_and_the_signal(monkeypatch):
    monkeypatch.setattr(load.AeroSpring, "reads", ())
    with pytest.raises(AssemblyError, match=r"load = aero_spring reads 'x_rod_mech' without declaring it"):
        ema.build_model(ema.load_parameters(), {"load": "aero_spring"})


def test_a_port_nothing_provides_is_refused_naming_it(monkeypatch):
    monkeypatch.setattr(load.AeroSpring, "reads", load.AeroSpring.reads + (Port("F_nowhere", "N"),))
    with pytest.raises(AssemblyError, match=r"port 'F_nowhere' of load = aero_spring is connected to nothing"):
        ema.build_model(ema.load_parameters(), {"load": "aero_spring"})


def test_a_port_whose_unit_is_not_its_providers_is_refused(monkeypatch):
    monkeypatch.setattr(load.AeroSpring, "reads", (Port("x_rod", "N"),))
    with pytest.raises(AssemblyError, match=r"port 'x_rod' of load = aero_spring reads N, its provider .* gives m"):
        ema.build_model(ema.load_parameters(), {"load": "aero_spring"})


def test_the_connection_table_names_each_ports_provider():
    params = ema.load_parameters()
    ref = {(c.reader, c.port): c for c in ema.build_model(params).connections}
    assert ref[("friction = smooth", "v_contact")].provider == "screw = elastic"
    assert ref[("screw = elastic", "F_load_rod")].provider == "assembly"
    assert ref[("controller = P", "x_s")].unit == "m"
    rigid = {(c.reader, c.port): c for c in ema.build_model(params, {"screw": "rigid"}).connections}
    assert rigid[("friction = smooth", "v_contact")].provider == "screw = rigid"
    # an optional port: the winding temperature a monitor compares only with the thermal network
    port = next(p for p in monitors.On.reads if p.name == "T_w")
    assert port.optional
    off = {(c.reader, c.port): c for c in ema.build_model(params, {"monitors": "on"}).connections}
    on = {(c.reader, c.port): c
          for c in ema.build_model(params, {"monitors": "on", "thermal": "lumped"}).connections}
    assert off[("monitors = on", "T_w")].provider == "(unconnected, optional)"
    assert on[("monitors = on", "T_w")].provider == "thermal = lumped"


def test_ema_model_prints_the_connections(capsys):
    assert main(["model", "--connections"]) == 0
    out = capsys.readouterr().out
    line = next(row for row in out.splitlines() if row.startswith("friction = smooth") and " v_contact " in row)
    assert line.split()[-3:] == ["screw", "=", "elastic"]
