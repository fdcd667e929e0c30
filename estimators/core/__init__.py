"""The generic estimation core: the observer interface, Kalman and unscented Kalman filter steps,
fixed-interval smoothers, exact discretisation. Domain-free: imports numpy/scipy only."""
