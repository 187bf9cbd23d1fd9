"""The plan plot (``kesbrdf plan --plot``): no two labels overlap, however the protocols score."""

import itertools

from kesbrdf.plotting.planning import figure_plan


def _plan():
    """Seven protocols, five scoring alike (as on the demo satin, docs/planning.md), a
    three-step recommendation whose last two steps lie 4 samples apart."""
    P = {}
    for name, n, med, used in (("paper", 116, 0.886, 116), ("paper+specular", 132, 0.886, 116),
                               ("paper+line30", 172, 0.886, 116), ("paper+lines", 228, 0.886, 116),
                               ("paper+out-of-plane", 124, 0.733, 124), ("paper+line45", 172, 0.688, 172)):
        P[name] = {"groups": ["paper"], "n_samples": n, "median": med, "rows_used": used, "over_budget": False}
    P["dense"] = {"groups": ["dense"], "n_samples": 900, "over_budget": True}
    rec = [{"add": None, "groups": ["paper"], "n_samples": 116, "median": 0.886},
           {"add": "line:45", "groups": ["paper", "line:45"], "n_samples": 172, "median": 0.688},
           {"add": "specular:36", "groups": ["paper", "line:45", "specular:36"], "n_samples": 176, "median": 0.684}]
    return {"budget": 240, "truths": ["sadeghi-black-satin"], "protocols": P, "recommendation": rec}


def _label_boxes(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    canvas = FigureCanvasAgg(fig)  # the figures are pyplot-free: draw them on Agg, as save_figure does
    canvas.draw()
    renderer = canvas.get_renderer()
    texts = [t for t in fig.findobj(Text) if t.get_visible() and t.get_text().strip()]
    return [(t.get_text(), t.get_window_extent(renderer)) for t in texts]


def test_no_two_labels_overlap():
    fig = figure_plan(_plan())
    boxes = _label_boxes(fig)
    overlapping = [(a, b) for (a, ba), (b, bb) in itertools.combinations(boxes, 2)
                   if ba.width > 0 and bb.width > 0 and ba.overlaps(bb)]
    assert not overlapping
    # and every protocol and every greedy step is named somewhere on the figure
    names = [text for text, _ in boxes]
    for name in ("paper", "paper+specular", "paper+line30", "paper+lines", "paper+out-of-plane", "paper+line45",
                 "+line:45", "+specular:36"):
        assert any(text.startswith(name) or f" {name}" in text for text in names), name


def test_labels_stay_inside_the_figure():
    fig = figure_plan(_plan())
    boxes = _label_boxes(fig)
    w, h = fig.canvas.get_width_height()
    for text, box in boxes:
        assert box.x0 >= -0.5 and box.y0 >= -0.5 and box.x1 <= w + 0.5 and box.y1 <= h + 0.5, text
