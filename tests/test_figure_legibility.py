"""Figures a reader can read (issue 58): a note in a panel sits inside its frame and over
no data after the transient; every shaded band has its legend entry; a series that
chatters every sample is drawn as a band between two edges, not a solid block; a
sweep's category labels never overlap, horizontal where they fit.  Each check is shown
failing on the drawing it replaced."""
from types import SimpleNamespace

import numpy as np
import pytest

from validation.report import figures
from validation.report.sweep_figures import fit_tick_labels
from validation.run.plotting import BOUND_STYLE, NOTE_PT, fit_ylim
from validation.run.results import RunResult

TRUTH = SimpleNamespace(role="truth", plant_label="truth plant (Exudyn)")
REDUCED = SimpleNamespace(role="reduced", plant_label="reduced plant")
T = np.arange(0.0, 20.0, 1e-3)  # 20 s at Ts = 1 ms: 20,000 samples, dense in any panel
TRANSIENT = 2.0
BOUND = 0.02  # the angle-estimation claim's [rad]: far off a ~1 mrad error's scale


def _run(seed: int) -> RunResult:
    """θ₁ estimated within ~1 mrad, q₂₂ with the sign observer's chatter: its error
    flips between ±0.25 mm every sample (the paper's arm, Fig. 7)."""
    rng = np.random.default_rng(seed)
    theta = np.sin(0.3 * T)
    q22 = 1e-6 * np.sin(7 * T)
    flip = np.where(np.arange(T.size) % 2, 1.0, -1.0)
    signals = {"theta1": theta, "xhat_theta1": theta + 1e-3 * np.sin(3 * T) * flip,
               "y_theta1": theta + 1e-4 * rng.standard_normal(T.size),
               "q22": q22, "xhat_q22": q22 + 2.5e-4 * flip,
               "y_q22": q22 + 1e-5 * rng.standard_normal(T.size)}
    return RunResult(T, tuple(signals), np.array(list(signals.values())))


@pytest.fixture
def fig7(monkeypatch):
    """Fig. 7 of both plants, laid out as saved (the figure kept open)."""
    kept = []
    monkeypatch.setattr(figures, "png", lambda fig: kept.append(fig) or b"")
    figures.estimation_errors([(TRUTH, _run(1)), (REDUCED, _run(2))], "test", TRANSIENT, BOUND)
    (fig,) = kept
    fig.canvas.draw()
    yield fig
    figures.plt.close(fig)


def _panel(fig, title: str):
    return next(ax for ax in fig.axes if ax.get_title() == title)


def notes_clear(ax) -> list[str]:
    """The notes of ``ax`` (texts in the bound's colour) that leave its frame or lie
    over a line's sample after the transient: [] where every note is clear."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    bad = []
    for note in [t for t in ax.texts if t.get_color() == BOUND_STYLE["color"]]:
        box = note.get_window_extent(renderer)
        inside = (frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0
                  and box.y1 <= frame.y1)
        series = [np.column_stack([line.get_xdata(), line.get_ydata()]) for line in ax.lines
                  if np.size(line.get_xdata()) > 2]  # not the spans' and bounds' lines
        highest = max(ax.transData.transform(xy[xy[:, 0] >= TRANSIENT])[:, 1].max()
                      for xy in series)
        if not inside or highest >= box.y0:
            bad.append(note.get_text())
    return bad


def test_the_off_scale_note_sits_in_its_frame_over_no_data(fig7):
    ax = _panel(fig7, "θ₁ error")
    assert [t.get_text().replace("\n", " ") for t in ax.texts] == ["bound ±20 mrad off scale"]
    assert notes_clear(ax) == []
    # Known-bad: the note as it was (one line, 3 % under the top, no headroom kept)
    # runs past the frame of a Fig. 7 panel and over the errors.
    ax.texts[0].remove()
    ax.set_ylim(*_late_range(ax))
    ax.text(0.99, 0.97, "bound ±20 mrad off scale", ha="right", va="top",
            transform=ax.transAxes, fontsize=NOTE_PT, color=BOUND_STYLE["color"])
    fig7.canvas.draw()
    assert notes_clear(ax) == ["bound ±20 mrad off scale"]


def _late_range(ax):
    """The y-range `fit_ylim` had before it kept headroom for a note."""
    late = [(np.asarray(line.get_xdata()), np.asarray(line.get_ydata())) for line in ax.lines
            if np.size(line.get_xdata()) > 2]
    lo = min(y[t >= TRANSIENT].min() for t, y in late)
    hi = max(y[t >= TRANSIENT].max() for t, y in late)
    pad = 0.08 * (hi - lo)
    return lo - pad, hi + pad


def unlisted_bands(fig) -> list[str]:
    """The shaded areas of the figure's panels (fills, spans) whose label the figure's
    legend does not list: [] where every band is explained."""
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Polygon, Rectangle
    listed = {t.get_text() for legend in fig.legends for t in legend.get_texts()}
    bands = [a for ax in fig.axes for a in (*ax.collections, *ax.patches)
             if isinstance(a, (PolyCollection, Polygon, Rectangle)) and a.get_visible()]
    return sorted({a.get_label() for a in bands if a.get_label() not in listed})


def test_every_shaded_band_is_in_the_legend(fig7):
    assert unlisted_bands(fig7) == []
    labels = [t.get_text() for t in fig7.legends[0].get_texts()]
    assert "shaded: min–max per pixel column" in labels
    assert "measurement error, ±1 RMS (grey band)" in labels
    # Known-bad: a band drawn without a label, as the envelopes and the measurement
    # error's span were.
    _panel(fig7, "q₂₂ error").axhspan(-0.1, 0.1, color="0.85")
    assert len(unlisted_bands(fig7)) == 1  # the span's label: none ("" or "_child…")


def block_share(ax, fig) -> float:
    """The share of the panel's pixels, between the first quarter and the end of the
    run and inside the middle half of its height, that are darker than 80 % white:
    a solid block of colour fills them all, a band between two edges only its edges
    and lines."""
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba())[..., :3] / 255.0
    box = ax.get_window_extent()
    height = image.shape[0]
    x0, x1 = int(box.x0 + 0.25 * box.width), int(box.x1 - 0.05 * box.width)
    y0, y1 = int(height - box.y1 + 0.25 * box.height), int(height - box.y0 - 0.25 * box.height)
    return float(np.mean(image[y0:y1, x0:x1].mean(axis=2) < 0.8))


def test_a_chatter_every_sample_is_a_band_between_edges_not_a_block(fig7):
    """The q₂₂ error flips ±0.25 mm every sample on both plants: its envelope is as
    wide as the chatter in every pixel column.  Drawn faint between thin edges, the
    panel's middle is mostly background, the mean lines in it readable; the opaque
    fill it had (alpha 0.25 and 0.225 of two plants overlapping) darkened all of it."""
    ax = _panel(fig7, "q₂₂ error")
    edges = [line for line in ax.lines if np.size(line.get_ydata()) > 2
             and abs(np.median(line.get_ydata()) - 0.25) < 0.01]
    assert len(edges) == 2  # the upper edge of each plant's band, at +0.25 mm
    assert block_share(ax, fig7) < 0.2
    # Known-bad: the same envelopes filled as before.
    for band in ax.collections:
        band.set_alpha(0.25)
    assert block_share(ax, fig7) > 0.8


def overlapping_labels(ax, gap: float = 4.0) -> int:
    """How many neighbouring x tick labels of ``ax`` overlap (``gap`` points apart)."""
    fig = ax.figure
    fig.canvas.draw()
    boxes = sorted((t.get_window_extent() for t in ax.get_xticklabels() if t.get_text()),
                   key=lambda b: b.x0)
    return sum(b.x0 < a.x1 + gap * fig.dpi / 72 for a, b in zip(boxes, boxes[1:]))


NAMES = ["ct", "lqr", "lqr+ekf", "pbc", "pbc+ekf", "pbc+ekf-pos", "pbc+smo-bl",
         "pbc+smo-paper", "pbc+smo-pos", "pd"]  # the paper campaign's 'cases' sweep


@pytest.mark.parametrize("width, wrapped, tilted", [(12.0, False, False), (8.5, True, False),
                                                      (4.0, False, True)])
def test_category_labels_never_overlap_and_are_horizontal_where_they_fit(width, wrapped,
                                                                         tilted):
    """The cases sweep's ten names under a panel: on one line where it is wide enough,
    broken before each "+" where it is narrower (a report's sweep panel, 8.5 in beside
    the strip's names), tilted only in a panel too narrow even for those.  Known-bad:
    the names set as they are in the 8.5 in panel overlap."""
    fig, ax = figures.plt.subplots(figsize=(width, 2.0), layout="constrained")
    ax.set_xticks(range(len(NAMES)))
    ax.set_xlim(-0.5, len(NAMES) - 0.5)
    fit_tick_labels(ax, NAMES)
    labels = ax.get_xticklabels()
    assert any("\n" in t.get_text() for t in labels) == wrapped
    assert all(t.get_rotation() == (40.0 if tilted else 0.0) for t in labels)
    if not tilted:  # a tilted label's box spans its neighbours' by design
        assert overlapping_labels(ax) == 0
    if wrapped:
        assert "pbc\n+smo-paper" in [t.get_text() for t in labels]
        ax.set_xticks(range(len(NAMES)), NAMES, fontsize=8)
        assert overlapping_labels(ax) > 0
    figures.plt.close(fig)
