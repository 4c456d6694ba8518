"""Foot-mounted navigation (Song & Park 2018): stance detection, INS-EKF-ZUPT, cascaded heading filters.

``stance``     zero-velocity detectors (the paper's J of eqs. 1-6, SHOE, acceleration moving variance,
               angular-rate energy), vectorised and streaming
``ins``        strapdown INS with the 15-state error-state EKF and zero-velocity updates (eqs. 7-10)
``course``     the first cascaded filter: the course-angle error (eqs. 11-19)
``navigator``  :class:`FootNavigator`: the four cases of the paper's Tables 2-3, batch ``run`` and streaming ``update``
``mounting``   is an IMU foot-mounted? (``detect_mounting``)
``devices``    naming of several IMUs' streams in one recording (``acc@waist``)

See ``docs/foot.md``.
"""
