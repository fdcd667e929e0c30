"""PNG figures of a run, in one place: the figure boilerplate (:func:`figure`), the study's
signal figures and each observer's estimates over their truth.

Only the runner imports this module, and only when a run writes figures: a Monte Carlo
member does not load matplotlib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

# one curve: (label, values, unit) or (label, values, unit, matplotlib line style kwargs)
Curve = tuple


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def units_of(system) -> dict[str, str]:
    """``{"component.variable": unit}`` of every variable of the system's FMUs (for axis
    labels), from the model descriptions the system already holds: deriving the models would
    take seconds."""
    units = {}
    for c in system.components:
        for v in c.variables.values():
            unit = v.unit or (v.declaredType.unit if v.declaredType is not None else None)
            units[f"{c.name}.{v.name}"] = unit or "-"
    return units


def x_axis(signals: dict[str, np.ndarray], position: str | None = None) -> tuple[np.ndarray, str]:
    """The x-axis of a run's figures: time, or the distance along the track when ``position``
    names the recorded signal that holds it."""
    if position is None:
        return np.asarray(signals["time"]), "time [s]"
    return np.asarray(signals[position]), "track position [m]"


def figure(out: Path, fname: str, title: str, x: np.ndarray, x_label: str, axes: list[list[Curve]],
           height: float = 2.4, width: float = 9.0, legend_columns: int = 1) -> str:
    """One PNG, one axis per list of curves sharing x; returns the file name. An axis of one
    curve is labelled with it; an axis of several gets a legend and its unit."""
    plt = _pyplot()
    fig, ax_grid = plt.subplots(len(axes), 1, figsize=(width, max(3.6, height * len(axes))), sharex=True,
                                squeeze=False)
    for ax, curves in zip(ax_grid[:, 0], axes):
        for label, values, _, *style in curves:
            n = min(len(x), len(values))  # estimates may stop short of the signals
            ax.plot(x[:n], np.asarray(values)[:n], label=label, **({"lw": 0.8} | (style[0] if style else {})))
        if len(curves) > 1:
            ax.legend(fontsize=8, loc="upper right", ncol=legend_columns)
            # a sensor channel may be unitless ("-") where the physical signal beside it is not
            ax.set_ylabel(f"[{next((c[2] for c in curves if c[2] not in ('-', '?')), curves[0][2])}]", fontsize=8)
        else:
            ax.set_ylabel(f"{curves[0][0]} [{curves[0][2]}]", fontsize=8)
        ax.grid(alpha=0.3)
    ax_grid[0, 0].set_title(title)
    ax_grid[-1, 0].set_xlabel(x_label)
    fig.tight_layout()
    fig.savefig(out / fname, dpi=110)
    plt.close(fig)
    return fname


def plot_signals(spec: dict | None, signals: dict[str, np.ndarray], roles: dict, units: dict[str, str], out: Path,
                 position: str | None = None) -> list[str]:
    """The study's signal figures (``{file: (title, [[(signal or role, label), ...] per axis])}``);
    without them, every recorded signal on its own axis (at most 8)."""
    if spec is None:
        names = [k for k in signals if k != "time"][:8]
        spec = {"signals.png": ("Recorded signals", [[(n, n)] for n in names])} if names else {}
    x, x_label = x_axis(signals, position)
    files = []
    for fname, (title, axes) in spec.items():
        axes_spec = [[(label, signals[sig], units.get(sig, "?")) for sig, label in
                      ((roles.get(s, s), label) for s, label in curves) if sig in signals] for curves in axes]
        axes_spec = [a for a in axes_spec if a]
        if axes_spec:
            files.append(figure(out, fname, title, x, x_label, axes_spec))
    return files


def plot_estimates(bank, signals: dict[str, np.ndarray], units: dict[str, str], out: Path) -> list[str]:
    """One figure per observer: every estimate that has a truth signal, estimate over truth."""
    t, est = bank.arrays()
    files, col = [], 0
    for spec, obs in zip(bank.specs, bank.observers):
        axes = []
        for j, name in enumerate(obs.outputs):
            if name in spec.truth:
                truth_sig = spec.truth[name]
                unit = obs.units.get(name, units.get(truth_sig, "?"))
                axes.append([(f"truth {truth_sig}", signals[truth_sig][:len(t)], unit),
                             (f"estimate {spec.name}.{name}", est[:, col + j], unit)])
        col += len(obs.outputs)
        if axes:
            files.append(figure(out, f"estimates_{spec.name}.png", f"Observer {spec.name}: estimates and truth",
                                t, "time [s]", axes))
    return files
