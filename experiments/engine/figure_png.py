"""A figure of :func:`plots.figure <railfmu.experiments.engine.plots.figure>` as a PNG: from
its spec (:func:`plots.figure_spec`: labels and each curve's display envelope) to the file's
bytes, in whatever process draws it (the figure worker's or the run's own).

The layout is computed from the few texts around the axes (:func:`arrange`). matplotlib's
tight layout finds the margins from every artist's extent: it updates each axis's ticks and
lays out every tick label, then ``bbox_inches="tight"`` does it again and the draw a third
time (two thirds of a figure's drawing time). A figure of :func:`plots.figure` is always the
same arrangement: axes stacked under one title, sharing x, y labels left, legends right of the
data, the x label under the last. Its margins follow from the title, the labels, the legends
(measured: a handful of texts) and the tick labels the locators and formatters will print
(their strings measured, no ticks made). The figure is then drawn once; its pixels are cropped
to what was drawn plus ``savefig.pad_inches``, as ``bbox_inches="tight"`` crops. Should
anything reach the canvas's edge (an estimate too small), it is laid out by matplotlib's tight
layout as before.
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

#: PNG text key holding the figure's axis labels (JSON)
LABELS_KEY = "railfmu:axes"
#: PNG resolution
DPI = 110
H_PAD = 1.08  # between stacked axes, in font sizes: tight_layout's default pad


def legend_outside(ax, columns: int = 1) -> None:
    """The axis's legend to the right of it, off the data."""
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, ncol=columns)


def render(spec: dict) -> bytes:
    """The PNG of a :func:`plots.figure_spec <railfmu.experiments.engine.plots.figure_spec>`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.layout_engine import TightLayoutEngine

    # a bare Agg figure: no pyplot (its import and figure manager) for a PNG
    fig = Figure(figsize=spec["size"], dpi=DPI)
    FigureCanvasAgg(fig)
    ax_grid = fig.subplots(len(spec["axes"]), 1, sharex=True, squeeze=False)
    for ax, a in zip(ax_grid[:, 0], spec["axes"]):
        for label, xs, ys, style in a["curves"]:
            ax.plot(xs, ys, label=label, **style)
        ax.set_ylabel(a["y_label"], fontsize=8)
        if a["legend"]:
            legend_outside(ax, spec["legend_columns"])
        ax.grid(alpha=0.3)
    ax_grid[0, 0].set_title(spec["title"])
    ax_grid[-1, 0].set_xlabel(spec["x_label"])
    renderer = fig.canvas.get_renderer()
    arrange(fig, renderer, DPI)  # margins from the texts around the axes: no tick-by-tick layout
    png = draw(fig, DPI, {LABELS_KEY: json.dumps(_labels(fig, renderer))})
    if png is None:  # something reached the canvas's edge: laid out by matplotlib, as before
        # fig.tight_layout()'s layout, run once without leaving a layout engine on the figure (with one,
        # savefig draws the figure twice)
        TightLayoutEngine().execute(fig)
        buf = io.BytesIO()
        save(fig, buf)
        png = buf.getvalue()
    return png


def write_png(path: Path, png: bytes) -> None:
    """The PNG written and renamed into place: a reader never sees half of one."""
    from railfmu.experiments.engine.files import write_atomic

    write_atomic(path, png, sync=False)


def warm_up() -> None:
    """Import matplotlib and load its fonts: what the first figure of a process pays."""
    t = np.linspace(0.0, 1.0, 50)
    render({"title": "warm-up", "x_label": "time [s]", "size": (9.0, 3.6), "legend_columns": 1,
            "axes": [{"y_label": "a [m]", "legend": True,
                      "curves": [("a", t, t, {"lw": 0.8}), ("b", t, -t, {"lw": 0.8})]}]})


def save(fig, path) -> None:
    """Write ``fig`` as a PNG whose text chunk :data:`LABELS_KEY` holds, per axis, its title, x
    and y labels, legend entries and whether the legend covers the axis (read back by
    ``plots.figure_labels``). The extents come from the canvas's renderer without a draw: the
    figure is drawn once, by ``savefig``."""
    fig.set_dpi(DPI)  # the renderer at the PNG's resolution, as savefig's own
    renderer = fig.canvas.get_renderer()
    # savefig's "tight" box from the same renderer, without the extra draw "tight" makes to find it
    box = fig.get_tightbbox(renderer).padded(0.1)  # savefig.pad_inches
    # zlib level 3: a third less time to encode than PIL's default 6, the same pixels in a file 10-20 % larger
    fig.savefig(path, dpi=DPI, bbox_inches=box, metadata={LABELS_KEY: json.dumps(_labels(fig, renderer))},
                pil_kwargs={"compress_level": 3})


def _labels(fig, renderer) -> list[dict]:
    """Per axis: title, x and y labels, legend entries, whether the legend covers the axis."""
    axes = []
    for ax in fig.axes:
        leg = ax.get_legend()
        axes.append({"title": ax.get_title(), "x": ax.get_xlabel(), "y": ax.get_ylabel(),
                     "legend": [t.get_text() for t in leg.get_texts()] if leg else [],
                     "legend_over_data": bool(leg and _overlaps(leg.get_window_extent(renderer),
                                                                ax.get_window_extent(renderer)))})
    return axes


def _overlaps(a, b) -> bool:
    return a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1


def arrange(fig, renderer, dpi: float) -> None:
    """Set the subplot parameters of ``fig`` (axes stacked top to bottom, sharing x) so that
    its title, labels, tick labels and legends fit inside the canvas with a border of
    ``savefig.pad_inches``."""
    import matplotlib as mpl

    rc = mpl.rcParams
    pt = dpi / 72
    axes = fig.axes
    W, H = fig.bbox.width, fig.bbox.height
    border = rc["savefig.pad_inches"] * dpi
    font = mpl.font_manager.FontProperties(size=rc["ytick.labelsize"])
    text_h = _height(renderer, "0", font)  # one line of tick labels
    y_out = (rc["ytick.major.size"] if rc["ytick.direction"] != "in" else 0) + rc["ytick.major.pad"]
    x_out = (rc["xtick.major.size"] if rc["xtick.direction"] != "in" else 0) + rc["xtick.major.pad"]
    ylabels = [ax.yaxis.label.get_window_extent(renderer).height for ax in axes]  # rotated: its length
    title = max(axes[0].title.get_window_extent(renderer).y1 - axes[0].bbox.y1, 0.0)  # above the axis
    top = border + title
    xlabel = axes[-1].xaxis.label.get_window_extent(renderer).height
    bottom = border + (x_out + axes[-1].xaxis.labelpad) * pt + text_h + xlabel

    def vertical(gap: float) -> float:
        h = (H - top - bottom - gap * (len(axes) - 1)) / len(axes)
        fig.subplots_adjust(top=1 - top / H, bottom=bottom / H, hspace=gap / h)
        return h

    gap = H_PAD * rc["font.size"] * pt
    h = vertical(gap)
    ticks = [_ticks(ax.yaxis) for ax in axes]
    # a label longer than its axis reaches past it (half each way), a tick label at an end by half its height
    over = [max((length - h) / 2, 0.0) for length in ylabels]
    ends = [_ends(locs, ax.yaxis, h, text_h) for ax, (locs, _, _) in zip(axes, ticks)]
    offsets = [(_height(renderer, off, font) + 3 * pt) if off else 0.0 for _, _, off in ticks]  # OFFSETTEXTPAD
    top2 = border + max(title, over[0], ends[0][1] + offsets[0])
    bottom2 = max(bottom, border + over[-1])
    pairs = [ends[i][0] + ends[i + 1][1] + offsets[i + 1] for i in range(len(axes) - 1)]
    if top2 != top or bottom2 != bottom or pairs:
        top, bottom = top2, bottom2
        h = vertical(gap + max(pairs + [0.0]))
        ticks = [_ticks(ax.yaxis) for ax in axes]
    widths = [max((renderer.get_text_width_height_descent(s, font, ismath=_math(s))[0] for s in labels), default=0.0)
              for _, labels, _ in ticks]
    left = border + max(y_out * pt + w + ax.yaxis.labelpad * pt + lab
                        for ax, w, lab in zip(axes, widths, (ax.yaxis.label.get_window_extent(renderer).width
                                                              for ax in axes)))
    legends = [ax.get_legend().get_window_extent(renderer).width for ax in axes if ax.get_legend() is not None]
    # a legend sits at 1.01 of the axis's width (plots.legend_outside): right = border + 0.01 (W - left - right) + width
    right = (border + 0.01 * (W - left) + max(legends)) / 1.01 if legends else border
    fig.subplots_adjust(left=left / W, right=1 - right / W)
    # the x tick labels at both ends may reach past the axis by half their width
    locs, labels, _ = _ticks(axes[-1].xaxis)
    lo, hi = sorted(axes[-1].xaxis.get_view_interval())
    w = W - left - right
    reach_l = reach_r = 0.0
    for v, s in zip(locs, labels):
        half = renderer.get_text_width_height_descent(s, font, ismath=_math(s))[0] / 2
        px = (v - lo) / (hi - lo) * w if hi > lo else 0.0
        reach_l, reach_r = max(reach_l, half - px), max(reach_r, px + half - w)
    if reach_l + border > left or reach_r + border > right:
        fig.subplots_adjust(left=max(left, reach_l + border) / W, right=1 - max(right, reach_r + border) / W)


def _height(renderer, text: str, font) -> float:
    """A line's height as matplotlib lays it out: at least that of "lp" (ascent and descent)."""
    return max(renderer.get_text_width_height_descent(text, font, ismath=_math(text))[1],
               renderer.get_text_width_height_descent("lp", font, ismath=False)[1])


def _math(text: str) -> bool | str:
    from matplotlib import cbook

    return cbook.is_math_text(text)


def _ticks(axis) -> tuple[list[float], list[str], str]:
    """The locations and labels of the ticks ``axis`` will draw at its present size (those in
    its view interval), and its offset text."""
    locs = np.asarray(axis.get_majorticklocs())
    fmt = axis.get_major_formatter()
    labels = fmt.format_ticks(locs)
    lo, hi = sorted(axis.get_view_interval())
    tol = 1e-10 * max(abs(hi - lo), 1e-300)
    keep = [(float(v), s) for v, s in zip(locs, labels) if lo - tol <= v <= hi + tol and s]
    return [v for v, _ in keep], [s for _, s in keep], fmt.get_offset()


def _ends(locs: list[float], axis, h: float, text_h: float) -> tuple[float, float]:
    """How far the lowest and the highest y tick label reach past the axis (pixels)."""
    lo, hi = sorted(axis.get_view_interval())
    if not locs or hi <= lo:
        return 0.0, 0.0
    f = (np.asarray(locs) - lo) / (hi - lo) * h
    return max(text_h / 2 - f.min(), 0.0), max(f.max() + text_h / 2 - h, 0.0)


def draw(fig, dpi: float, metadata: dict) -> bytes | None:
    """The PNG of ``fig`` drawn once at its layout, cropped to what was drawn plus
    ``savefig.pad_inches``; None if anything reaches the canvas's edge (clipped)."""
    import matplotlib as mpl
    from PIL import Image, PngImagePlugin

    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    pixels = rgba.view(np.uint32)[..., 0]  # one compare per pixel, not per channel
    ink = pixels != pixels[0, 0]
    if ink[0].any() or ink[-1].any() or ink[:, 0].any() or ink[:, -1].any():
        return None
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    if not len(rows):
        return None
    pad = round(mpl.rcParams["savefig.pad_inches"] * dpi)
    r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, rgba.shape[0])
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, rgba.shape[1])
    info = PngImagePlugin.PngInfo()
    for key, value in {"Software": f"Matplotlib version{mpl.__version__}, https://matplotlib.org/", **metadata}.items():
        info.add_text(key, value)
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgba[r0:r1, c0:c1])).save(
        buf, format="png", pnginfo=info, dpi=(dpi, dpi), compress_level=3)
    return buf.getvalue()
