"""Pedestrian dead reckoning (PDR) engine: numpy only, runs on the phone.

Everything in ``core/`` follows the conventions below. Importers and exporters
convert to and from them at the edges; nothing inside converts again.

Conventions
===========

Time
    Every timestamp is an ``int`` (numpy ``int64``) count of **nanoseconds on
    the sensor clock**, named ``t_ns``.  On Android that is
    ``SensorEvent.timestamp`` (``elapsedRealtimeNanos`` base); for files
    from other apps it is whatever monotonic clock the file uses, shifted
    to integer nanoseconds.  Time differences used in filters are seconds
    (``dt_s = (t_ns - t_prev_ns) * 1e-9``) and always come from the
    measured timestamps, never from a nominal rate.  One exception, said where it is made: OxIOD's ``syn``
    files (:mod:`core.importers.oxiod`) carry no usable clock (their time column is one constant), so their
    rows are placed at the dataset's stated 100 Hz.

Units (SI inside ``core/``)
    ==============  ===========================================
    acceleration    m/s^2, gravity included (Android ``TYPE_ACCELEROMETER``)
    angular rate    rad/s
    magnetic field  microtesla (uT), as Android reports it
    angles          radians (degrees only in file headers, UI and exports)
    lengths         metres
    latitude etc.   degrees (WGS-84) -- only in GPS streams and exports
    ==============  ===========================================

Device (body) frame ``b``
    The Android device frame: with the phone lying flat, screen up, in
    portrait, **x points right, y points to the top edge (forward when the
    phone is held in front of the chest), z points out of the screen (up)**.
    Sensor vectors are always expressed in this frame.

Navigation frame ``n``
    Local **East-North-Up** (ENU), origin at the start of the walk.  Gravity
    is ``(0, 0, -9.81)`` in ``n``; an accelerometer at rest reads the
    specific force ``(0, 0, +g)`` rotated into ``b``.  The Earth's magnetic
    field reference is ``h_n = (0, h_north, h_up)`` with ``h_up < 0`` in the
    northern hemisphere (magnetic north = +y before the declination is
    applied).

Attitude quaternion
    ``q = (w, x, y, z)``, scalar first, unit norm, rotating body vectors into
    the navigation frame: ``v_n = R(q) v_b`` (``R`` = ``core.quaternion.to_matrix``).
    This is the paper's ``Q`` (Tian et al. 2014, eq. 5: ``dQ/dt = Q (x) W / 2``
    with ``W`` the body rate); the paper's ``T_n^b`` of eq. 8 is ``R(q).T``.

Heading
    ``heading_rad`` is the direction of walking in the ENU plane, measured
    **counter-clockwise from East** (the mathematical angle), so that one
    step moves ``(d cos(heading), d sin(heading))`` in (East, North) as in
    eq. 1 of the paper.  The compass bearing (clockwise from North, degrees)
    used by GPX and the UI is ``core.conventions.bearing_deg(heading_rad)``.
    The walking direction of a hand-held phone is the horizontal projection
    of the device y axis.

Names
    Vectors carry their frame as a suffix (``acc_b``, ``pos_n``), rotation
    matrices both frames (``mat_nb`` maps ``b`` to ``n``), and parameters
    their unit (``cutoff_hz``, ``min_step_interval_s``, ``gyro_noise_rad_s``).

Layout
======
Everything under ``core/`` runs on the phone (numpy only at run time);
nothing in it imports the desktop tools of ``desktop/``.

Shared, at ``core/``'s top
    ``core.conventions`` (constants, angle wrap, bearings), ``core.quaternion``
    (the one quaternion module), ``core.dsp`` (Butterworth, biquads, uniform
    grid, windowed statistics), ``core.geodesy`` (WGS-84 <-> local ENU,
    distances, magnetic declination), ``core.recording`` (data model and file format),
    ``core.importers`` (other apps' files), ``core.export`` (CSV, GeoJSON, GPX).

``core.pdr`` -- the hand-held step-and-heading chain (Tian et al. 2014, Fig. 2)
    ``steps`` (eqs. 2-3), ``stride`` and ``stride_models`` (eq. 4),
    ``calibration``, ``attitude`` (error-state EKF of attitude and gyro bias),
    ``attitude_qekf`` (the paper's quaternion EKF, for comparison), ``magcal``
    (magnetometer calibration, quasi-static field), ``heading``
    (rotation-matrix smoothing, section 4.3; a step's heading),
    ``carry`` (how the phone is carried: the mode chooses the step gates),
    ``walkdir`` (the walking direction from the acceleration, where the phone's
    axis is not it), ``deadreckoning`` (eq. 1), ``pipeline``.

``core.gnss`` -- GPS fusion (Chen et al. 2010; Kubrak et al. 2006)
    ``heading_model`` (eq. 12), ``ekf`` (eq. 13 with GPS updates),
    ``training`` (online stride and heading training), ``fusion`` (the stage
    ``Pipeline(gnss=...)`` runs).

``core.foot``
    Foot-mounted INS with zero-velocity updates (Song & Park 2018);
    ``tracker`` chooses foot or hand-held for a recording and puts the foot INS
    behind the pipeline's streaming interface.

``core.indoor``
    Floor plans (walkable area, walls, georeference) and the particle filter
    that keeps the steps inside them, with landmark fixes.

``core.floors``
    Floors from the barometer (relative altitude, stairs, lifts, slopes).

``core.metrics``
    A track's error against the truth a recording carries (shared by the
    command line and the benchmark).

``desktop/`` (not on the phone)
    ``desktop.cli`` (the ``pdr`` command), ``desktop.plot``,
    ``desktop.simulator`` (walks with exact truth, independent of the
    pipeline's models; a barometer), ``desktop.placements`` (the phone swinging
    in the hand, in a pocket, a bag, at the ear; not walking),
    ``desktop.foot_simulator``, ``desktop.floor_images`` (floor-plan images,
    Pillow), ``desktop.fast`` (a second, array-and-numba implementation of the
    batch pipeline, checked against it).
"""

__version__ = "0.1.0"
