"""Track irregularity FMU driving the wheelset + suspended-frame FMU (seed 000 §3.3).

The leading wheelset's alignment and its rate feed the wheelset model's inputs. Variants:
``psd`` (ERRI B176 low-level random alignment, the default) and ``harmonic`` (a 1 mm, 20 m
alignment wave: the wheelset responds at V/lambda = 1 Hz). Until the SSP reader lands, the
system is declared here in Python; it becomes SystemStructure.ssd + .ssv files.
"""

from fmus.cosim import Component, Connection

DESCRIPTION = "Track irregularity FMU driving the wheelset + suspended-frame lateral model"
STOP_TIME = 20.0  # s: 400 m at 20 m/s, as seed 000 §5
STEP_SIZE = 1e-3  # s: 1 kHz, the seed's sensor rate
VARIANTS = {
    "psd": {"track": {"psd_level": 1}},
    "harmonic": {"track": {"psd_level": 0, "harmonic_lateral_amplitude": 1e-3, "harmonic_wavelength": 20.0}},
}
DEFAULT_VARIANT = "psd"
PLOTS = {  # file -> (title, one list of (signal, label) per axis)
    "track_input.png": ("Alignment under the leading wheelset and the response",
                        [[("track.alignment_1", "alignment xi"), ("wheelset.y", "wheelset y"),
                          ("wheelset.y_f", "frame y_f")],
                         [("wheelset.psi", "wheelset yaw psi [rad]")]]),
    "sensors.png": ("Sensor signals (noise-free)",
                    [[("wheelset.ddy", "wheelset lateral acc. [m/s2]")],
                     [("wheelset.dpsi", "wheelset yaw rate [rad/s]")],
                     [("wheelset.ddy_f", "frame lateral acc. [m/s2]")]]),
}


def system(fmu_dir, variant: str):
    params = VARIANTS[variant]
    components = [Component("track", fmu_dir / "TrackIrregularity.fmu", dict(params.get("track", {}))),
                  Component("wheelset", fmu_dir / "WheelsetLateral.fmu", dict(params.get("wheelset", {})))]
    connections = [Connection("track", "alignment_1", "wheelset", "xi"),
                   Connection("track", "alignment_rate_1", "wheelset", "xi_rate")]
    record = [("track", "position"), ("track", "alignment_1"), ("track", "alignment_rate_1"),
              *[("wheelset", n) for n in ("y", "psi", "y_f", "dy", "dpsi", "dy_f", "ddy", "ddy_f")]]
    return components, connections, record
