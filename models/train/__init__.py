"""Train models (Cunillera et al. 2022): longitudinal train dynamics, the driver, the GNSS receiver."""
