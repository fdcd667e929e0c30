"""PNG plots of a run: the experiment's own figures (``PLOTS``) and estimates against truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def unit_of(signal: str) -> str:
    """Unit of 'component.variable' from the model definitions (for axis labels)."""
    from models import all_models

    var = signal.split(".", 1)[1]
    for model in all_models():
        try:
            return model.variable(var).unit or "-"
        except KeyError:
            continue
    return "?"


def _figure(fname: str, title: str, time: np.ndarray, axes_spec, out: Path) -> str:
    """One figure, one axis per list of (label, values, unit) curves."""
    plt = _pyplot()
    fig, axes = plt.subplots(len(axes_spec), 1, figsize=(9, 2.4 * len(axes_spec)), sharex=True, squeeze=False)
    for ax, curves in zip(axes[:, 0], axes_spec):
        for label, values, _ in curves:
            ax.plot(time, values, lw=0.8, label=label)
        if len(curves) > 1:
            ax.legend(fontsize=8, loc="upper right")
            ax.set_ylabel(f"[{curves[0][2]}]", fontsize=8)
        else:
            ax.set_ylabel(f"{curves[0][0]} [{curves[0][2]}]", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0, 0].set_title(title)
    axes[-1, 0].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out / fname, dpi=110)
    plt.close(fig)
    return fname


def plot_signals(module, signals: dict[str, np.ndarray], out: Path) -> list[str]:
    """The experiment's PLOTS ({file: (title, [[(signal, label), ...] per axis])}); without
    them, every recorded signal on its own axis (at most 8)."""
    spec = getattr(module, "PLOTS", None)
    if spec is None:
        names = [k for k in signals if k != "time"][:8]
        spec = {"signals.png": ("Recorded signals", [[(n, n)] for n in names])} if names else {}
    files = []
    for fname, (title, axes) in spec.items():
        axes_spec = [[(label, signals[sig], unit_of(sig)) for sig, label in curves if sig in signals]
                     for curves in axes]
        axes_spec = [a for a in axes_spec if a]
        if axes_spec:
            files.append(_figure(fname, title, signals["time"], axes_spec, out))
    return files


def plot_estimates(system, bank, signals: dict[str, np.ndarray], out: Path) -> list[str]:
    """One figure per observer: every estimate that has a truth signal, estimate over truth."""
    t, est = bank.arrays()
    files, col = [], 0
    for spec, obs in zip(bank.specs, bank.observers):
        axes = []
        for j, name in enumerate(obs.outputs):
            if name in spec.truth:
                truth_sig = spec.truth[name]
                unit = obs.units.get(name, unit_of(truth_sig))
                axes.append([(f"truth {truth_sig}", signals[truth_sig][:len(t)], unit),
                             (f"estimate {spec.name}.{name}", est[:, col + j], unit)])
        col += len(obs.outputs)
        if axes:
            files.append(_figure(f"estimates_{spec.name}.png", f"Observer {spec.name}: estimates and truth",
                                 t, axes, out))
    return files
