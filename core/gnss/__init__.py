"""GPS fusion: GPS-assisted calibration and the PDR Kalman filter (Chen et al. 2010); see :mod:`core` for conventions.

``heading_model`` (the unified heading error model, eq. 12), ``ekf`` (the
PDR EKF of eq. 13 with GPS position and course updates), ``training``
(online stride and heading training with the safeguards against noisy GPS),
``fusion`` (the stage the pipeline runs: fix screening, anchoring, outages).
"""

#: the GPS fusion filters by name (``pdr replay --gps``, the app's setting, the benchmark)
FUSIONS = ("chen", "kubrak")

#: the filter ``--gps auto`` and the app's default use, and why (benchmarks/GNSS_FAULTS_RESULTS.md); the tuning
#: split says the same (fixes more than 30 m off taken: 6 against 767; largest track error 21 m against 170 m)
AUTO_FUSION = "kubrak"
#: (Chen's filter is better after a noisy minute, 9.3 m against 16.8 m, and on pocket walks, 22 % against 51 %)
AUTO_FUSION_WHY = ("better on the GPS fault benchmark's report split: 28 fixes more than 30 m off taken against "
                   "Chen's 715, largest track error 24 m against 167 m (median walk), ETH 3-min outages 12 % against 21 %")


def make_fusion(name: str, **settings):
    """A GPS fusion stage by name: ``"chen"`` (:class:`core.gnss.fusion.GpsFusion`, Chen et al. 2010) or
    ``"kubrak"`` (:class:`core.gnss.kubrak.KubrakFusion`, Kubrak et al. 2006), with its keyword settings.

    Both take ``hidden_ns`` (simulated outages) and ``start`` (a known start: ``(lat_deg, lon_deg, sd_m)``),
    stream through ``add_fix``/``add_step``/``finish`` and batch-run with ``run(steps, gps_stream, t0_ns)``.
    """
    if name == "chen":
        from core.gnss.fusion import GpsFusion
        return GpsFusion(**settings)
    if name == "kubrak":
        from core.gnss.kubrak import KubrakFusion
        return KubrakFusion(**settings)
    raise ValueError(f"unknown GPS fusion {name!r}: one of {', '.join(FUSIONS)}")


def settings_from_profile(name: str, profile) -> dict:
    """The keywords of fusion ``name`` that start from what earlier walks with GPS taught (the user's profile)."""
    if name == "chen":
        from core.gnss.training import fusion_settings_from_profile
        return fusion_settings_from_profile(profile)
    from core.gnss.kubrak import settings_from_profile as kubrak_settings
    return kubrak_settings(profile)


def profile_after(profile, fusion):
    """``profile`` with what ``fusion`` learnt from this walk's GPS (the same object if nothing worth keeping)."""
    if getattr(fusion, "name", "") == "chen":
        from core.gnss.training import profile_with_gps_training
        return profile_with_gps_training(profile, fusion.trainer)
    from core.gnss.kubrak import profile_with_learning
    return profile_with_learning(profile, fusion)
