"""Train dynamics (Cunillera et al. 2022): running resistance from GNSS with an unscented Kalman
filter, driving-regime recognition and decoding."""
