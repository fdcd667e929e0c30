"""Track models: irregularity sources (ERRI B176 PSD, harmonic, step, measured profile), the 3-D
track geometry of the trolley survey, and a line's gradient and speed limit by position."""
