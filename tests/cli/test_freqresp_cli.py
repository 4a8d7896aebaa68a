"""`ema freqresp`: JSON per (load, amplitude, frequency), CSV/PNG output, one-line errors."""

import csv
import json

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main


def test_json_points_and_files(tmp_path, capsys):
    out, png = tmp_path / "fr.csv", tmp_path / "fr.png"
    status = main(["freqresp", str(REFERENCE), "--amplitudes", "0.5%,2mm", "--freqs", "1,5",
                   "--loads", "0,10kN", "--jobs", "2", "--out", str(out), "--plot", str(png), "--json"])
    assert status == 0
    r = json.loads(capsys.readouterr().out)
    assert len(r["points"]) == 2 * 2 * 2
    assert r["axes"]["amplitude"] == pytest.approx([0.375e-3, 2e-3])
    assert r["axes"]["load"] == [0.0, 1e4]
    pt = next(p for p in r["points"] if p["load_N"] == 0 and p["freq_Hz"] == 1.0 and p["amplitude_m"] == 2e-3)
    # the reference set's predictions: flat to ~6 Hz at small amplitude, ~ -5 deg at 1 Hz
    assert abs(pt["gain_db"]) < 0.2 and -7 < pt["phase_deg"] < -3 and pt["converged"]
    assert {"distortion", "i_q_amp", "i_q_phase_deg"} <= set(pt)
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert len(rows) == 8 and float(rows[0]["amplitude_m"]) == pytest.approx(0.375e-3)
    assert png.stat().st_size > 10_000
    assert str(out) in r["written"] and str(png) in r["written"]


def test_human_report(capsys):
    assert main(["freqresp", str(REFERENCE), "--amplitudes", "1mm", "--freqs", "2"]) == 0
    text = capsys.readouterr().out
    assert "gain (dB) / phase (deg)" in text and "1 points" in text


@pytest.mark.parametrize("args, flag", [
    (["--freqs", "0.1-30"], "--freqs"),
    (["--freqs", "0,1"], "--freqs"),
    (["--amplitudes", "1kg"], "--amplitudes"),
    (["--loads", "5mm"], "--loads"),
    (["--jobs", "0"], "--jobs"),
    (["--scheduler", "localhost"], "--scheduler"),
    (["--out", "fr.txt"], "--out"),
    (["--plot", "nodir/fr.png"], "--plot"),
    (["--max-periods", "2"], "--max-periods"),
])
def test_bad_flags_give_one_line(tmp_path, capsys, args, flag):
    base = [] if "--freqs" in args else ["--freqs", "1"]  # a flag given once (twice is refused)
    status = main(["freqresp", str(REFERENCE), *base, *args])
    err = capsys.readouterr().err
    assert status == 2
    assert len(err.strip().splitlines()) == 1 and flag in err, err
