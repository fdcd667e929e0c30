"""PNG figures of a run, in one place: the figure boilerplate (:func:`figure`, :func:`save`), the
study's signal figures and each observer's estimates over their truth.

Axes read like the data: a replayed channel is named by its file's column (:func:`columns_of`)
and carries its SSD connector's unit (:func:`units_of`), every y-axis names its quantity beside
its unit, legends sit outside the data, and a study along the track has the distance on x.
Every PNG carries its axis labels in a text chunk (:func:`figure_labels` reads them back), so
a test or a user's script checks what a figure says without looking at it.

Only the runner imports this module, and only when a run writes figures: a Monte Carlo
member does not load matplotlib.
"""

from __future__ import annotations

import json
import math
import textwrap
from pathlib import Path

import numpy as np

from railfmu.experiments.engine.figure_png import (  # noqa: F401  (the figure boilerplate, here for the studies)
    DPI,
    LABELS_KEY,
    legend_outside,
    render,
    save,
    write_png,
)

# one curve: (label, values, unit) or (label, values, unit, matplotlib line style kwargs)
Curve = tuple
#: display units a label may ask for with ``[unit]``: (unit of the values, display unit) -> factor
DISPLAY = {("m", "mm"): 1e3, ("m/s", "mm/s"): 1e3, ("m/s", "km/h"): 3.6, ("rad", "deg"): 180 / math.pi,
           ("rad/s", "deg/s"): 180 / math.pi, ("N/m", "kN/m"): 1e-3}
NO_UNIT = ("-", "?", "", None)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def units_of(system) -> dict[str, str]:
    """``{"component.variable": unit}`` of every variable of the system's FMUs (for axis
    labels): the FMU's unit, else the SSD connector's (a generic channel, e.g. a replayed
    column), else "-". From the model descriptions the system already holds: deriving the
    models would take seconds."""
    units = {}
    for c in system.components:
        for v in c.variables.values():
            unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
            if not unit and v.name in c.units:
                unit = c.units[v.name].name
            units[f"{c.name}.{v.name}"] = unit or "-"
    return units


def columns_of(system) -> dict[str, str]:
    """``{"component.y_k": column}``: the file column each channel of a table player
    (``column_k``, ``boolean_column_k``, ``integer_column_k`` parameters) plays, as the file's
    header names it."""
    out = {}
    for c in system.components:
        for prefix, channel in (("column_", "y_"), ("boolean_column_", "boolean_"), ("integer_column_", "integer_")):
            for name, v in c.variables.items():
                if name.startswith(prefix) and name[len(prefix):].isdigit():
                    col = c.parameters.get(name, v.start)
                    if col:
                        out[f"{c.name}.{channel}{name[len(prefix):]}"] = str(col)
    return out


def split_label(label: str) -> tuple[str, str | None]:
    """``"lateral alignment [mm]"`` -> ("lateral alignment", "mm"); no brackets: (label, None)."""
    if label.endswith("]") and " [" in label:
        name, unit = label[:-1].rsplit(" [", 1)
        return name, unit
    return label, None


def in_display_unit(values, unit: str, display: str | None) -> tuple[np.ndarray, str]:
    """Values in the display unit a label asks for (:data:`DISPLAY`), else as they are."""
    factor = DISPLAY.get((unit, display))
    if factor is None:
        return np.asarray(values), unit
    return factor * np.asarray(values, dtype=float), display


def unit_text(unit: str | None) -> str:
    return "(unit not given)" if unit in NO_UNIT else f"[{unit}]"


def x_axis(signals: dict[str, np.ndarray], position=None) -> tuple[np.ndarray, str]:
    """The x-axis of a run's figures: time; the distance along the track when ``position``
    names the recorded signal that holds it; or, when ``position`` is a number (the run's
    constant speed, m/s), that speed times the time."""
    t = np.asarray(signals["time"])
    if position is None:
        return t, "time [s]"
    if isinstance(position, (int, float)):
        return float(position) * t, f"distance along the track [m] (at {float(position):g} m/s)"
    return np.asarray(signals[position]), "distance along the track [m]"


def _common_words(labels: list[str]) -> str:
    words = [s.split() for s in labels]
    common = []
    for group in zip(*words):
        if any(w != group[0] for w in group):
            break
        common.append(group[0])
    return " ".join(common).rstrip(",:")


#: columns of a figure's curve envelope (:func:`envelope`): above the ~1100 pixel columns of the
#: widest figure at 110 dpi, so the decimated curve draws the same pixels
ENVELOPE_COLUMNS = 2000


def envelope(x: np.ndarray, y: np.ndarray, columns: int = ENVELOPE_COLUMNS) -> tuple[np.ndarray, np.ndarray]:
    """The curve ``(x, y)`` cut to at most ``2 * columns + 2`` of its own points for display:
    per run of consecutive samples (one column), its minimum and its maximum in their order,
    plus the first and last sample. Every extreme of the data is kept, so the drawn curve
    covers the same envelope; a curve short enough is returned as it is. A NaN in a column is
    kept (it breaks the line there, as in the full curve)."""
    n = len(y)
    if n <= 2 * columns + 2:
        return x, y
    k = -(-n // columns)  # samples per column
    m = n // k
    yk = y[:m * k].reshape(m, k)
    base = np.arange(m) * k
    lo, hi = base + np.argmin(yk, axis=1), base + np.argmax(yk, axis=1)
    if m * k < n:  # the last, shorter column
        tail = y[m * k:]
        lo, hi = np.append(lo, m * k + np.argmin(tail)), np.append(hi, m * k + np.argmax(tail))
    keep = np.concatenate([[0], np.stack([np.minimum(lo, hi), np.maximum(lo, hi)], 1).ravel(), [n - 1]])
    keep = keep[np.concatenate([[True], np.diff(keep) != 0])]
    return x[keep], y[keep]


def figure_labels(png: Path | str) -> list[dict]:
    """The axis labels :func:`save` wrote into a PNG: one dict per axis (``title``, ``x``,
    ``y``, ``legend``, ``legend_over_data``); [] for a PNG written otherwise."""
    from PIL import Image

    with Image.open(png) as im:
        text = im.text.get(LABELS_KEY)
    return json.loads(text) if text else []


def figure(out: Path, fname: str, title: str, x: np.ndarray, x_label: str, axes: list[list[Curve]],
           height: float = 2.4, width: float = 9.0, legend_columns: int = 1,
           quantities: list[str | None] | None = None) -> str:
    """One PNG, one axis per list of curves sharing x; returns the file name. Every y-axis says
    ``quantity [unit]``: ``quantities[i]`` for axis i, else its one curve's label, else the
    words its curves' labels share (else all of them); an axis of several curves gets a legend
    outside the data.

    Inside a :func:`figure_worker.batch <railfmu.experiments.engine.figure_worker.batch>`
    (``Run.save``) the figure worker draws it and the file exists when the batch ends; else
    it is drawn here and exists on return."""
    from railfmu.experiments.engine.figure_worker import current

    spec = figure_spec(title, x, x_label, axes, height, width, legend_columns, quantities)
    batch = current()
    if batch is not None:
        batch.submit(spec, out / fname)
    else:
        write_png(out / fname, render(spec))
    return fname


#: characters of an 8 pt y label per inch of axis height (DejaVu Sans averages ~4.5 pt a
#: character; some room left for the axes' gap)
Y_LABEL_CHARS_PER_INCH = 14


def figure_spec(title: str, x: np.ndarray, x_label: str, axes: list[list[Curve]], height: float = 2.4,
                width: float = 9.0, legend_columns: int = 1, quantities: list[str | None] | None = None) -> dict:
    """What :func:`render` draws, without matplotlib: the labels and each curve's display
    envelope (a few thousand points however long the run: small to send to the worker)."""
    spec_axes = []
    for i, curves in enumerate(axes):
        drawn = []
        for label, values, _, *style in curves:
            n = min(len(x), len(values))  # estimates may stop short of the signals
            xs, ys = envelope(np.asarray(x)[:n], np.asarray(values)[:n])
            drawn.append((label, xs, ys, {"lw": 0.8} | (style[0] if style else {})))
        labels = [c[0] for c in curves]
        quantity = (quantities[i] if quantities and quantities[i] else None) or (
            labels[0] if len(labels) == 1 else _common_words(labels) or " / ".join(labels))
        # a sensor channel may be unitless ("-") where the physical signal beside it is not
        unit = next((c[2] for c in curves if c[2] not in NO_UNIT), curves[0][2])
        # on lines no longer than the axis is high: a longer label runs into its neighbours'
        y_label = textwrap.fill(f"{quantity} {unit_text(unit)}", width=max(12, int(height * Y_LABEL_CHARS_PER_INCH)),
                                break_on_hyphens=False)
        spec_axes.append({"y_label": y_label, "legend": len(curves) > 1, "curves": drawn})
    return {"title": title, "x_label": x_label, "size": (width, max(3.6, height * len(axes))),
            "legend_columns": legend_columns, "axes": spec_axes}


def plot_signals(spec: dict | None, signals: dict[str, np.ndarray], roles: dict, units: dict[str, str], out: Path,
                 position=None, columns: dict[str, str] | None = None) -> list[str]:
    """The study's signal figures (``{file: (title, [[(signal or role, label), ...] per axis])}``;
    a label may end in a display unit, ``"measured alignment [mm]"``; an axis's list may start
    with the quantity its y-axis names, ``["vertical displacement", (...), ...]``); without them, every
    recorded signal on its own axis (at most 8). A replayed channel's label names its file
    column."""
    columns = columns or {}
    if spec is None:
        names = [k for k in signals if k != "time"][:8]
        spec = {"signals.png": ("Recorded signals", [[(n, columns.get(n, n))] for n in names])} if names else {}
    x, x_label = x_axis(signals, position)
    files = []
    for fname, (title, axes) in spec.items():
        axes_spec, quantities = [], []
        for curves in axes:
            quantity = curves[0] if curves and isinstance(curves[0], str) else None
            axis = []
            for s, label in curves[quantity is not None:]:
                sig = roles.get(s, s)
                if sig not in signals:
                    continue
                name, display = split_label(label)
                values, unit = in_display_unit(signals[sig], units.get(sig, "?"), display)
                col = columns.get(sig)
                axis.append((f"{name} ({col})" if col and col not in name else name, values, unit))
            if axis:
                axes_spec.append(axis)
                quantities.append(quantity)
        if axes_spec:
            files.append(figure(out, fname, title, x, x_label, axes_spec, quantities=quantities))
    return files


def plot_estimates(bank, signals: dict[str, np.ndarray], units: dict[str, str], out: Path, position=None,
                   columns: dict[str, str] | None = None, quantities: dict[str, str] | None = None) -> list[str]:
    """One figure per observer: every estimate that has a truth signal, estimate over truth
    (converted to the estimate's unit, as the scores are). ``quantities`` names an estimate
    (``"xi": "lateral alignment [mm]"``, optionally with a display unit); else the truth's file
    column or the estimate's name does."""
    columns, quantities = columns or {}, quantities or {}
    t, est = bank.arrays()
    if position is None:
        x, x_label = t, "time [s]"
    else:  # the distance at the estimates' times
        xs, x_label = x_axis(signals, position)
        x = np.interp(t, np.asarray(signals["time"]), xs)
    files, col = [], 0
    for feed in bank.online:
        spec, obs = feed.spec, feed.obs
        axes, names = [], []
        for j, name in enumerate(obs.outputs):
            if name in spec.truth:
                truth_sig = spec.truth[name]
                unit = obs.units.get(name) or units.get(truth_sig, "?")
                a, b = feed.truth_map.get(name, (1.0, 0.0))
                truth = a * np.asarray(signals[truth_sig][:len(t)], dtype=float) + b
                quantity, display = split_label(quantities.get(name) or columns.get(truth_sig) or name)
                truth, shown = in_display_unit(truth, unit, display)
                estimate, _ = in_display_unit(est[:, col + j], unit, display)
                col_name = columns.get(truth_sig)
                axes.append([(f"truth ({col_name})" if col_name else "truth", truth, shown),
                             (f"{spec.name} estimate", estimate, shown)])
                names.append(quantity)
        col += len(obs.outputs)
        if axes:
            files.append(figure(out, f"estimates_{spec.name}.png", f"Observer {spec.name}: estimates and truth",
                                x, x_label, axes, quantities=names))
    return files
