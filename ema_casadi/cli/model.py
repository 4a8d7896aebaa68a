"""The assembled model: its parts, states, inputs and outputs, and with --connections its
wiring (each port a part reads, its unit and the part that provides it).
Example: ema model --connections
"""

from __future__ import annotations

from . import load

COMMAND = "model"
ORDER = 15
HELP = "the assembled model: parts, states, inputs, outputs; --connections: its wiring"

#: Each flag -> the combinations where it has no effect (refused; docs: cli).
NO_EFFECT = {"--connections": ()}


def add_arguments(p):
    p.add_argument("--connections", action="store_true",
                   help="print the connection table: each port a part reads, its unit and who provides it")


def run(args) -> dict:
    _, model = load(args)
    out = {"parts": [f"{p.family} = {p.value}" for p in model.parts], "states": list(model.states),
           "inputs": list(model.inputs), "outputs": list(model.outputs), "parameters": len(model.param_names)}
    if args.connections:
        out["connections"] = [{"reader": c.reader, "port": c.port, "unit": c.unit, "source": c.source,
                               "provider": c.provider} for c in model.connections]
        out["connections_text"] = model.connections_text()
    return out


def report(r: dict) -> None:
    print("parts:   " + ", ".join(r["parts"]))
    for key in ("states", "inputs", "outputs"):
        print(f"{key + ':':8s} " + " ".join(r[key]))
    print(f"parameters: {r['parameters']}")
    if "connections_text" in r:
        print()
        print(r["connections_text"])
