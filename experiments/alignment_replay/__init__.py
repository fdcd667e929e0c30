"""A measured axle-box run replayed through an SSP into the alignment observers (Muñoz et al.).

``SystemStructure.ssd``: a SignalTable FMU plays ``resources/axlebox_run.csv`` (wheelset
lateral acceleration ``ddy``, yaw rate ``dpsi``, frame lateral acceleration ``ddy_f`` and the
true alignment, as ``track_wheelset`` recorded them; ``record.py`` writes it) into the same
alignment Kalman filter as ``track_wheelset``, and its RTS smoother offline. The table's end
ends the run. A measured run replayed so gives the estimates of the simulated run bit for bit
(``tests/test_replay.py``); swap in your own table as the SSD's description says. Variants
(``variants/*.ssv``) change the observers, never the measured run: ``measured`` (the SSD as it
is, the default) and ``conicity_minus10`` (the observers' conicity 10 % low, Muñoz et al.,
Table 3).
"""

from railfmu.experiments.engine.study_protocol import Study, setting

# file -> (title, one list of (signal, quantity) per axis); the plots add the file's column
# names and the connectors' units
PLOTS = {
    "sensors.png": ("Replayed sensor signals",
                    [[("replay.y_1", "wheelset lateral acceleration")],
                     [("replay.y_2", "wheelset yaw rate")],
                     [("replay.y_3", "frame lateral acceleration")],
                     [("replay.y_4", "measured lateral alignment [mm]")]]),
}


class AlignmentReplay(Study):
    """The alignment observers on a replayed measured run; the study table is the default one
    (each observer's raw error against the measured alignment, per variant). Figures along the
    track: the distance is the run's speed (run.V) times the time."""
    default_variant = "measured"
    roles = {"speed": setting("alignment", "V")}
    figures_of_signals = PLOTS
    x_axis = "speed"
    quantities = {"xi": "lateral alignment [mm]"}


STUDY = AlignmentReplay(__doc__.strip().splitlines()[0])
