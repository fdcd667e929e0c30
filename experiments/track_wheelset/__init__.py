"""Track irregularity FMU driving the wheelset + suspended-frame lateral model (Muñoz et al., §3.3).

The system is ``SystemStructure.ssd``: the track's alignment under the leading wheelset and
its rate feed the wheelset model; an alignment Kalman filter (railfmu.estimators.track.alignment) observes
the wheelset's noise-free sensor outputs. Variants (``variants/*.ssv``): ``psd`` (ERRI B176
low-level random alignment, the default) and ``harmonic`` (a 1 mm, 20 m alignment wave: the
wheelset responds at V/lambda = 1 Hz).
"""

from railfmu.experiments.engine.study_protocol import Study, output, truth

DEFAULT_VARIANT = "psd"
ROLES = {"alignment": truth("alignment", "xi"), "wheelset_y": output("wheelset", "y")}
PLOTS = {  # file -> (title, one list of (signal, label) per axis)
    "track_input.png": ("Alignment under the leading wheelset and the response",
                        [["lateral position", ("track.alignment_1", "alignment xi"), ("wheelset.y", "wheelset y"),
                          ("wheelset.y_f", "frame y_f")],
                         [("wheelset.psi", "wheelset yaw psi")]]),
    "sensors.png": ("Sensor signals (noise-free)",
                    [[("wheelset.ddy", "wheelset lateral acc.")],
                     [("wheelset.dpsi", "wheelset yaw rate")],
                     [("wheelset.ddy_f", "frame lateral acc.")]]),
}


def table_md(table: dict[str, dict]) -> str:
    """The study table: one row per variant (no published numbers for this system)."""
    L = ["| variant | master | alignment rms [mm] | y rms [mm] | xi: rms error of the raw estimate / rms truth "
         "| wall [s] |", "|---|---|---|---|---|---|"]
    for variant, m in table.items():
        xi = m.get("observers", {}).get("alignment", {}).get("xi", {})
        rel = xi.get("rel_error")
        L.append(f"| {variant} | {m['master']} | {1e3 * m['rms'][m['roles']['alignment']]:.3f} | "
                 f"{1e3 * m['rms'][m['roles']['wheelset_y']]:.3f} | {'-' if rel is None else f'{rel:.3f}'} | "
                 f"{m['wall_time_s']:.2f} |")
    return "\n".join(L + ["", "The raw estimate: not band-passed, after the first 10 % of the run."])


class TrackWheelset(Study):
    """The wheelset + suspended-frame model (Muñoz et al. §3.3) on one track input."""
    default_variant = DEFAULT_VARIANT
    roles = ROLES
    figures_of_signals = PLOTS

    def table_md(self, table: dict[str, dict]) -> str:
        return table_md(table)


STUDY = TrackWheelset(__doc__.strip().splitlines()[0])
