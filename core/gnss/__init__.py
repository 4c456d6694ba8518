"""GPS fusion: GPS-assisted calibration and the PDR Kalman filter (Chen et al. 2010); see :mod:`core` for conventions.

``heading_model`` (the unified heading error model, eq. 12), ``ekf`` (the
PDR EKF of eq. 13 with GPS position and course updates), ``training``
(online stride and heading training with the safeguards against noisy GPS),
``fusion`` (the stage the pipeline runs: fix screening, anchoring, outages).
"""

#: the GPS fusion filters by name (``pdr replay --gps``, the app's setting, the benchmark)
FUSIONS = ("chen", "kubrak")

#: the filter ``--gps auto`` and the app's default use, and why.  Both filters compared with the same relock
#: settings (20 s, drift limit 0.15) and the usability judge of issue #26, on the tuning split only
#: (benchmarks/splits.py): IPIN routes 01, 02, 21, 22 median landmark error 2.90 m Kubrak, 3.12 m Chen
#: (dead reckoning alone 2.93: only Kubrak's is no worse); the simulator's fault walks (seeds 0-9): fixes more
#: than 30 m off taken 5 and 5 of 1840, the 2-minute outage after a noisy minute 9.2 m against 12.3 m (median);
#: against it, on the outdoor tuning walk thomasdingemanse_lopen Chen's track lies nearer the left-out fixes
#: (every 10th left out: median 3.1 m against 10.8 m).
AUTO_FUSION = "kubrak"
AUTO_FUSION_WHY = ("on the tuning split, with the same relock settings and the GPS judge: IPIN indoor loops 2.90 m "
                   "against Chen's 3.12 m (dead reckoning alone 2.93 m), 2-minute outage after a noisy minute "
                   "9.2 m against 12.3 m, bad fixes taken 5 and 5 of 1840; Chen is nearer the fixes on the one "
                   "outdoor tuning walk (3.1 m against 10.8 m)")


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
