"""The hand-held step-and-heading chain (Tian et al. 2014, Fig. 2); see :mod:`core` for the conventions.

``steps`` (eqs. 2-3) -> ``stride`` / ``stride_models`` (eq. 4) and ``attitude`` (EKF)
-> ``heading`` (rotation-matrix smoothing) -> ``deadreckoning`` (eq. 1), composed
in ``pipeline`` with a streaming ``update()`` and a batch ``run()``.
"""
