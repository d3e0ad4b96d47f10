"""Figures a person reads: the legend stays inside the figure and off the axes with ten long model names."""

import matplotlib.figure
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

from nnfmu.cosim import Evaluation
from nnfmu.data import Channel, from_arrays
from nnfmu.metrics import nrmse
from nnfmu.plots import plot_trajectory


def test_legend_of_ten_fmus_with_long_names_is_readable(tmp_path, monkeypatch):
    rng = np.random.default_rng(0)
    u = rng.normal(size=(300, 2))
    y = np.cumsum(rng.normal(size=(300, 2)), axis=0)
    ds = from_arrays(Ts=0.01, u_train=u, y_train=y, u_test=u, y_test=y, input_names=["u1", "u2"],
                     output_names=[Channel("s", "m"), Channel("p", "Pa")])
    names = [f"valve_{arch}_{strategy}_hidden{h}_truncate100_seed{s}"
             for arch, strategy, h, s in zip(["mlp", "rnn", "lstm", "gru", "tcn"] * 2,
                                             ["parallel"] * 5 + ["series_parallel"] * 5, [16, 32] * 5, range(10))]
    names[-1] += "_with_a_name_long_enough_to_wrap_onto_a_second_line_of_the_legend"
    evs = [Evaluation(n, tmp_path / f"{n}.fmu", nrmse(y, y + 0.01 * k), [y + 0.01 * k])
           for k, n in enumerate(names, 1)]
    saved = []
    real = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, *a, **k: (saved.append(fig), real(fig, *a, **k))[1])
    png = plot_trajectory(ds, evs, tmp_path / "fig.png", index=0)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    (fig,) = saved
    canvas = FigureCanvasAgg(fig)  # the figure was closed after saving: draw it again as it was saved
    canvas.draw()
    renderer = canvas.get_renderer()
    (legend,) = fig.legends
    texts = [t.get_text().replace("\n", " ") for t in legend.get_texts()]
    assert len(texts) == 11 and all(any(t.startswith(n[:40]) for t in texts) for n in names)  # every entry, whole
    box = legend.get_window_extent(renderer)
    assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= fig.bbox.width and box.y1 <= fig.bbox.height
    for text in legend.get_texts():  # no label runs out of the figure
        ext = text.get_window_extent(renderer)
        assert 0 <= ext.x0 and ext.x1 <= fig.bbox.width
    for ax in fig.axes:  # and none covers a plot (tick labels included)
        assert not box.overlaps(ax.get_tightbbox(renderer))
