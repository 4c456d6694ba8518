"""A fix's reported horizontal accuracy as the per-axis SD of its position: the one conversion every GPS stage uses.

A phone reports ``hacc_m`` (Android's ``Location.getAccuracy``, NMEA's and the IPIN logs' accuracy) as the radius
of the circle that holds the true position with probability :data:`HACC_PROBABILITY` (68 %).  For a circular 2-D
Gaussian of per-axis SD ``sigma`` the distance from the centre is Rayleigh-distributed, ``P(r <= h) = 1 -
exp(-h^2 / (2 sigma^2))``, so ``hacc = sigma sqrt(-2 ln(1 - 0.68)) = 1.5096 sigma``.  Before issue #26's review
two values were in use (the fusion's 1.5096, the judge's and the drift check's rounded 1.515); this module is
the one place it is defined.
"""

from __future__ import annotations

import math

#: the probability that the true position lies within the reported horizontal accuracy
HACC_PROBABILITY = 0.68

#: the reported accuracy (a 68 % radius) in units of the per-axis SD of a circular 2-D Gaussian: 1.5096
HACC_PER_SIGMA = math.sqrt(-2.0 * math.log(1.0 - HACC_PROBABILITY))
