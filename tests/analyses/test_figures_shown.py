"""Figures as a user meets them: ``fig = res.plot(); plt.show()`` shows the figure (it is
managed by pyplot), an assigned figure displays in a notebook (the inline backend shows
pyplot's figures at the end of the cell) and a bare ``res.plot()`` as the cell's value
displays once, not twice; an example script run from any folder writes its figure."""

import subprocess
import sys
import types
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import pytest

import ema_casadi as ema

ROOT = Path(__file__).resolve().parents[2]

#: A pyplot backend that records what plt.show() shows (the Agg canvas draws; its manager
#: keeps the figures instead of opening windows).
BACKEND = '''
from matplotlib.backend_bases import FigureManagerBase
from matplotlib.backends.backend_agg import FigureCanvasAgg

SHOWN = []


class Manager(FigureManagerBase):
    def show(self):
        SHOWN.append(self.canvas.figure)


class FigureCanvas(FigureCanvasAgg):
    manager_class = Manager
'''


@pytest.fixture(scope="module")
def run(model_cache):
    return ema.simulate(model_cache(), 0.02, ema.Signal.step(1e-3, 0.005))


@pytest.fixture
def showing(tmp_path, monkeypatch):
    (tmp_path / "recording_backend.py").write_text(BACKEND)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = matplotlib.get_backend()
    plt.switch_backend("module://recording_backend")
    yield sys.modules["recording_backend"].SHOWN
    plt.switch_backend(before)


def test_plt_show_shows_the_returned_figure(run, showing, tmp_path):
    fig = run.plot()
    plt.show()
    assert showing == [fig]
    plt.close(fig)
    assert run.plot(path=tmp_path / "r.png") == tmp_path / "r.png"
    assert plt.get_fignums() == []  # a figure written is released


class _Display:
    """IPython.display as the notebook's display hook uses it: what was published."""

    def __init__(self):
        self.published = []
        self.module = types.SimpleNamespace(display=lambda obj, raw=False: self.published.append(obj))


def test_a_notebook_displays_each_figure_once(run, monkeypatch):
    fig = run.plot()
    shown = _Display()  # the display hook's module, only where the hook calls it
    monkeypatch.setitem(sys.modules, "IPython", types.ModuleType("IPython"))
    monkeypatch.setitem(sys.modules, "IPython.display", shown.module)
    matplotlib.interactive(True)  # a notebook: the inline backend shows pyplot's figures at the cell's end
    try:
        fig._ipython_display_()  # a bare res.plot() as the cell's value: left to the backend
    finally:
        matplotlib.interactive(False)
    assert shown.published == [] and fig.number in plt.get_fignums()
    plt.close(fig)  # the inline backend closes them after the cell; shown again later as a value:
    fig._ipython_display_()
    (data,) = shown.published
    assert data["image/png"].startswith(b"\x89PNG") and len(data["image/png"]) > 10_000


def test_a_script_writes_its_figures_where_it_runs(tmp_path, monkeypatch, capsys):
    """What every example ends with, run as a script from another folder: each figure
    pyplot holds is written there, named after the script, and released."""
    import runpy

    script = tmp_path / "src" / "plot_demo.py"
    script.parent.mkdir()
    script.write_text("import matplotlib.pyplot as plt\nfrom ema_casadi.plots import write_figures\n"
                      "plt.subplots()\nplt.subplots()\nwrite_figures()\n")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setattr(sys, "argv", [str(script)])
    runpy.run_path(str(script), run_name="__main__")
    assert sorted(p.name for p in work.iterdir()) == ["plot_demo.png", "plot_demo_2.png"]
    assert capsys.readouterr().out.count("wrote ") == 2 and plt.get_fignums() == []


@pytest.mark.parametrize("example", sorted((ROOT / "examples").glob("plot_*.py")), ids=lambda p: p.name)
def test_every_example_writes_its_figures(example):
    assert example.read_text().rstrip().splitlines()[-1].startswith("write_figures()"), example.name


@pytest.mark.slow
def test_an_example_script_writes_its_figure_from_any_folder(tmp_path):
    """``python examples/plot_step_response.py`` from an empty folder, as its own process
    (the installed package, no PYTHONPATH but the package's): the figure lands there,
    and nothing comes on stderr (no library warning)."""
    env = {k: v for k, v in __import__("os").environ.items() if k != "PYTHONPATH"}
    env.update(MPLBACKEND="Agg", PYTHONPATH=str(Path(ema.__file__).parents[1]))
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "plot_step_response.py")], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "plot_step_response.png").stat().st_size > 10_000
    assert "wrote" in proc.stdout and proc.stderr == "", proc.stderr
