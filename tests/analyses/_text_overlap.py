"""Overlapping text in a rendered figure: the boxes of the text matplotlib draws.

Every :class:`matplotlib.text.Text` drawn while the canvas renders (titles, labels,
tick labels, legends, annotations; not an empty or hidden one, and clipped to its axes
where it is clipped) is recorded with its window extent; two whose boxes share more
than :data:`SLACK` pixels each way overlap. Two texts that are neither an axis's label
nor a tick label (titles, annotations, legend entries) must moreover keep :data:`GAP`
each side: side by side, two titles closer than that read as one line (the demo's
``margins.png`` had its loop titles 4 px apart at 110 dpi). An axis keeps its labels
at its own pads (a few points from its tick labels), which this leaves alone.
"""

from __future__ import annotations

import contextlib
from itertools import combinations

import matplotlib.text

#: Pixels two boxes may share each way (anti-aliasing, a glyph's side bearing).
SLACK = 1.0
#: Points each free text's box is widened by, left and right: two of them side by side
#: keep 2 x GAP between them (6 pt: two thirds of an em of the figures' 9 pt titles).
GAP = 3.0


@contextlib.contextmanager
def _recording(drawn: list):
    original = matplotlib.text.Text.draw

    def draw(self, renderer):
        original(self, renderer)
        if not self.get_visible() or not self.get_text().strip():
            return
        box = self.get_window_extent(renderer)
        clip = self.get_clip_box() if self.get_clip_on() else None
        if clip is not None:
            box = box.intersection(box, clip)  # None: clipped away entirely
        if box is not None and box.width > 0 and box.height > 0:
            drawn.append((self, box))

    matplotlib.text.Text.draw = draw
    try:
        yield
    finally:
        matplotlib.text.Text.draw = original


def drawn_texts(fig) -> list:
    """(Text, its box in pixels) of every text the figure draws."""
    drawn: list = []
    with _recording(drawn):
        fig.canvas.draw()
    return drawn


def _axis_texts(fig) -> set:
    """The ids of the axes' labels, tick labels and offset texts."""
    out = set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            out |= {id(axis.label), id(axis.get_offset_text())}
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                out |= {id(tick.label1), id(tick.label2)}
    return out


def overlaps(fig) -> list[str]:
    """The pairs of drawn texts whose boxes overlap, as ``'a' / 'b'`` lines."""
    out, pad, axis_texts = [], GAP * fig.dpi / 72.0, _axis_texts(fig)
    for (a, ba), (b, bb) in combinations(drawn_texts(fig), 2):
        free = id(a) not in axis_texts and id(b) not in axis_texts
        w = min(ba.x1, bb.x1) - max(ba.x0, bb.x0) + (2 * pad if free else 0.0)
        h = min(ba.y1, bb.y1) - max(ba.y0, bb.y0)
        if w > SLACK and h > SLACK:
            out.append(f"{a.get_text()!r} / {b.get_text()!r}")
    return out
