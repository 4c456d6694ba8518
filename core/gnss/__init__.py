"""GPS fusion: GPS-assisted calibration and the PDR Kalman filter (Chen et al. 2010); see :mod:`core` for conventions.

``heading_model`` (the unified heading error model, eq. 12), ``ekf`` (the
PDR EKF of eq. 13 with GPS position and course updates), ``training``
(online stride and heading training with the safeguards against noisy GPS),
``fusion`` (the stage the pipeline runs: fix screening, anchoring, outages).
"""
