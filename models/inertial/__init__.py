"""Inertial navigation models (Jiang et al. 2017): the survey trolley and its ideal IMU, the IMU's
error grades (the Earth they move on is :mod:`railfmu.models.earth`)."""
