"""A remote Dask scheduler that does not answer (the reliability contract, docs: reliability) is not waited for forever:
the handshake and the wait for a worker are bounded, and the error names the address.
The bounds are 10 s and 30 s; the tests set them to 1 s through the environment."""

import socket
import threading
import time

import pytest

from conftest import REFERENCE
from ema_casadi.cli import main

ARGS = ["freqresp", str(REFERENCE), "--freqs", "1", "--amplitudes", "1mm"]


@pytest.fixture
def silent_server():
    """A TCP server that accepts connections and never answers; its address."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    held = []

    def accept():
        while True:
            try:
                held.append(srv.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    srv.close()
    for c in held:
        c.close()


def test_a_scheduler_that_never_answers_times_out(silent_server, monkeypatch, capsys):
    pytest.importorskip("dask.distributed")
    monkeypatch.setenv("EMA_CASADI_SCHEDULER_TIMEOUT", "1")
    t0 = time.perf_counter()
    status = main([*ARGS, "--scheduler", silent_server])
    took = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert f"scheduler {silent_server}: no answer within 1 s" in err
    assert took < 15


def test_a_scheduler_without_workers_times_out(monkeypatch, capsys):
    distributed = pytest.importorskip("dask.distributed")
    monkeypatch.setenv("EMA_CASADI_WORKERS_TIMEOUT", "1")
    with distributed.LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as cluster:
        t0 = time.perf_counter()
        status = main([*ARGS, "--scheduler", cluster.scheduler_address])
        took = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert status == 2, err
    assert err.count("\n") == 1 and f"scheduler {cluster.scheduler_address}: no worker joined within 1 s" in err
    assert took < 15
