"""Filter consistency against simulator truth (in the style of pyins): NEES, NIS, bias, turns.

The simulator (desktop.simulator) is independent of the pipeline's models:
an inverted-pendulum gait, a phone held at a yaw offset and tilted, a hand
that drifts while "still", a true gyroscope bias.  For NEES and NIS the
filter is given the simulator's stated sensor noise (how consistency is
checked: a filter is consistent for the noise it is told about); the
product's defaults are wider, for real phones.  The product's defaults are
checked on walks whose phone has the residual hard iron measured on the real
tuning recordings (``iron``: desktop.simulator.residual_hard_iron_uT, issue #27).
"""

import functools
import math
import os

import numpy as np
import pytest

from core import quaternion as quat
from core.conventions import wrap_angle
from core.pdr.attitude import AttitudeEKF, Outcome
from core.pdr.pipeline import Pipeline
from benchmarks.splits import SIM_BENT_FIELD_SEEDS, TUNING
from desktop.bent_field import MU0_4PI_UT, corridor_steel, dipole_field
from desktop.simulator import RESIDUAL_HARD_IRON_SD_UT, residual_hard_iron_uT, simulate_walk

SQUARE = [(0, 0), (0, 30), (30, 30), (30, 0), (0, 0)]
RATE_HZ = 100.0
GYRO_NOISE = 0.003  # rad/s per sample: the simulator's default
MAG_NOISE_UT = 0.4
FIELD_UT = math.hypot(20.0, 44.0)
READINGS_PER_UPDATE = 0.1 * 50.0  # magnetometer at half the rate, one update per 0.1 s


def _matched_filter():
    # the simulator's gyroscope bias is constant (simulate_walk's gyro_bias_walk_rad_s_sqrt_s=0): told the
    # product's 2e-5 rad/s/sqrt(s) for real phones, the bias variance never shrinks and widens the tilt's, and
    # through the dip the heading's (heading NEES 0.71 over 84 epochs of 12 seeds instead of 0.83).  Told the
    # noise, it has no floors to learn (noise_scale_rate=0); the simulator's field is not bent (no disturbance
    # zones): no field heading offset (mag_offset_sd_rad=0)
    return AttitudeEKF(gyro_noise_rad_sqrt_s=GYRO_NOISE / math.sqrt(RATE_HZ), gyro_scale_noise_sqrt_s=0.0,
                       gyro_bias_walk_rad_s_sqrt_s=0.0,
                       mag_noise_base=MAG_NOISE_UT / FIELD_UT / math.sqrt(READINGS_PER_UPDATE), k_m1=0.0, k_m2=0.0,
                       noise_scale_rate=0.0, mag_offset_sd_rad=0.0)


#: the rate of the noise floors' learnt scale checked here (AttitudeSettings.noise_scale_rate; 0, off, by default)
LEARNT_RATE = 0.05

#: the filters the NEES is checked for: told the simulator's noise, and the product's defaults with their noise
#: floors' scale learnt (the product's defaults as they are: heading NEES 0.27 over 12 walks, conservative)
#: (the field's heading offset state is off in both: the simulator's field is not bent, and a filter told that the field
#: may be off by mag_offset_sd_rad reports a wider heading sigma on a clean one -- the product's defaults, with it:
#: heading NEES 0.44 over 84 epochs of 12 walks, without it 0.27: below the band [0.72, 1.32], because a filter told the
#: field's azimuth may be off by 0.1 rad, alike over 30 s, cannot tell its heading from that offset within a walk, so
#: it reports a heading sigma of about the offset's, 5 deg, where on a uniform field only the gyroscope errs (seed 1:
#: 0.5 deg rms, sigma 5.4 deg, NEES 0.007; the 0.44 comes from a few walks with larger errors); the bent
#: field, where the offset is real, is checked with the defaults below)
FILTERS = {"matched": _matched_filter,
           "learnt_floors": lambda: AttitudeEKF(noise_scale_rate=LEARNT_RATE, mag_offset_sd_rad=0.0),
           # the product's defaults, the field's heading offset state included (checked on the bent field below)
           "defaults": AttitudeEKF,
           # the defaults without the offset state: the field's error white (mag_offset_sd_rad=0)
           "white_field": lambda: AttitudeEKF(mag_offset_sd_rad=0.0)}


def _attitude_error_n(q_true, q_est):
    """Navigation-frame rotation vector ``dtheta`` with ``R_true = exp([dtheta]x) R_est``."""
    e = np.array(quat.to_matrix(tuple(q_true))) @ np.array(quat.to_matrix(tuple(q_est))).T
    return quat.to_rotation_vector_array(quat.from_matrix(tuple(map(tuple, e))))[0]


@functools.lru_cache(maxsize=None)
def _walk(seed, bent=False, iron=False):
    """The square walked twice; ``bent``: in a corridor whose steel bends the field (desktop.bent_field); ``iron``:
    the phone's calibrated magnetometer keeps a residual hard iron of the size measured on the real tuning
    recordings (desktop.simulator.RESIDUAL_HARD_IRON_SD_UT per axis, benchmarks.residual_iron), drawn per seed."""
    steel = corridor_steel(SQUARE, seed=seed) if bent else None  # one lap: the second walks the same corridor
    hard_iron = residual_hard_iron_uT(seed) if iron else (0.0, 0.0, 0.0)
    return simulate_walk(SQUARE * 2, rate_hz=RATE_HZ, seed=seed, field_sources=steel, mag_hard_iron_uT=hard_iron)


@functools.lru_cache(maxsize=None)
def _run_against_truth(seed, filter_name="matched", bent=False, iron=False):
    walk = _walk(seed, bent, iron)
    tr = walk.truth
    ekf = FILTERS[filter_name]()
    handlers = {"gyro": ekf.predict, "acc": ekf.update_acc, "mag": ekf.update_mag}
    nees, nis = [], {"acc": [], "mag": []}
    heading = []  # (t_ns, heading NEES) at every accelerometer update while walking
    epochs = []  # (t_ns, the filter's attitude, its attitude covariance) at those updates
    bias_at_60s = None
    for name, t, v in walk.recording.events(["gyro", "acc", "mag"]):
        f = handlers[name](t, v[0], v[1], v[2])
        if name == "gyro" or f.outcome is not Outcome.USED or f.nis != f.nis:
            continue
        nis[name].append(f.nis)
        if name == "acc" and t > tr.walk_start_t_ns:
            epochs.append((t, tuple(ekf.q), np.array(ekf.P[:3, :3])))
        if bias_at_60s is None and t > tr.walk_start_t_ns + 60_000_000_000:
            bias_at_60s = (np.array(ekf.gyro_bias), tr.gyro_bias_at(t))
    # the true attitudes of all those epochs in one call (the simulator's model, vectorised), not one call each
    q_true = tr.attitude_at(np.array([t for t, _, _ in epochs], dtype=np.int64))
    for (t, q, P), qt in zip(epochs, q_true):
        d = _attitude_error_n(qt, q)
        nees.append(float(d @ np.linalg.solve(P, d)))
        heading.append((t - tr.walk_start_t_ns, d[2] ** 2 / P[2, 2]))
    return np.array(nees), {k: np.array(v) for k, v in nis.items()}, bias_at_60s, np.array(heading)


@pytest.fixture(scope="module", params=[1, 2])
def walked(request):
    return _run_against_truth(request.param)


def test_attitude_nees_is_within_the_band_of_its_dimension(walked):
    """Mean NEES of the 3-dof attitude error within [dof / 3, 2 dof] (measured 1.8-2.3)."""
    nees, _, _, _ = walked
    assert len(nees) > 1000
    assert 1.0 < nees.mean() < 6.0  # [dof / 3, 2 dof]
    # and the filter is not wildly overconfident anywhere: 99 % of epochs below the chi2(3) 99.99 % point x 3
    assert np.quantile(nees, 0.99) < 3 * 21.1


def test_heading_nees_is_not_overconfident():
    """Heading-error NEES (1 dof) of the walks above, at epochs 30 s apart (independent, see HEADING_EPOCH_S),
    no higher than the upper end of the two-sided 95 % band of the mean of chi2(1) for that count.

    The reported heading sigma must not be smaller than the heading errors: the failure of the TCKF that
    issue #27 found (NEES about 82).  Measured: 0.35 over these 14 epochs (band [0.40, 1.87]).  The next
    test checks the lower end too, on enough walks.
    """
    x = _heading_epochs([_run_against_truth(1), _run_against_truth(2)])
    assert len(x) >= 12
    assert x.mean() <= _chi2_mean_band(len(x))[1], x.mean()


#: seeds of the two-sided heading-NEES test (0: skipped); 12 take about 35 s on one core
CONSISTENCY_SEEDS = int(os.environ.get("PDR_CONSISTENCY_SEEDS", "0"))


@pytest.mark.skipif(CONSISTENCY_SEEDS < 6, reason="the two-sided band needs about 80 independent epochs: "
                    "PDR_CONSISTENCY_SEEDS=12 (about 35 s per filter)")
@pytest.mark.parametrize("filter_name", ["learnt_floors", "matched"])
def test_heading_nees_is_within_its_two_sided_chi2_band(filter_name):
    """The lower end too, on enough walks: the heading sigma neither too small nor too large.

    Measured with PDR_CONSISTENCY_SEEDS=12, 84 epochs (band [0.72, 1.32]): told the simulator's noise 0.83 (per
    seed 0.2 to 3.6: a seed's epochs share its hand's pose and gait, so two walks say little about the lower
    end; with the product's bias random walk instead of the simulator's, see _matched_filter: 0.71, outside);
    the product's defaults with the floors' scale learnt 0.91 (as they are, issue #27: 0.27, too conservative).
    """
    x = _heading_epochs([_run_against_truth(seed, filter_name) for seed in range(1, CONSISTENCY_SEEDS + 1)])
    lo, hi = _chi2_mean_band(len(x))
    assert lo <= x.mean() <= hi, (x.mean(), lo, hi)


def test_learnt_noise_floors_make_the_heading_sigma_neither_too_small_nor_too_large():
    """The product's defaults (without the field's offset state) with the noise floors' scale learnt, one simulated
    walk (7 epochs 30 s apart):
    heading NEES within the two-sided 95 % band of its mean, [0.24, 2.29].

    The product's noise floors are for real phones indoors; on the simulator's cleaner phone they make the
    reported heading sigma 2-3 times the error (issue #27: NEES 0.09 on this walk, 0.27 over 12 walks: this
    test fails with noise_scale_rate=0, the default).  Scaling the floors by what the heading innovations show
    (AttitudeSettings.noise_scale_rate): 0.83 here, 0.91 over 12 walks (the test above, PDR_CONSISTENCY_SEEDS=12).
    """
    x = _heading_epochs([_run_against_truth(1, "learnt_floors")])
    lo, hi = _chi2_mean_band(len(x))
    assert len(x) >= 6
    assert lo <= x.mean() <= hi, (x.mean(), lo, hi)


def test_nis_means_are_near_their_dimensions(walked):
    _, nis, _, _ = walked
    assert 0.67 < nis["acc"].mean() < 4.0  # dof 2, band [dof / 3, 2 dof] (a direction); walking linear acceleration included
    assert 0.33 < nis["mag"].mean() < 2.0  # dof 1 (the heading)


def test_gyro_bias_is_within_20_percent_after_60_s_of_walking(walked):
    _, _, (est, true), _ = walked
    assert np.linalg.norm(est - true) <= 0.2 * np.linalg.norm(true)


# -- a bent field (issue #27): the building's steel as dipoles (desktop.bent_field), fixed in space ---------------


def test_dipole_field_is_the_textbook_one_and_divergence_free():
    """One dipole: on its axis ``2 k m / r^3``, across it ``-k m / r^3`` (k = mu0 / 4 pi); the summed field of random
    dipoles has no divergence (finite differences, h = 1 mm: within 1e-4 of its gradient's scale)."""
    m = np.array([0.0, 0.0, 50.0])
    np.testing.assert_allclose(dipole_field([[0, 0, 2.0]], [[0, 0, 0]], [m])[0], [0, 0, 2 * MU0_4PI_UT * 50 / 8])
    np.testing.assert_allclose(dipole_field([[2.0, 0, 0]], [[0, 0, 0]], [m])[0], [0, 0, -MU0_4PI_UT * 50 / 8])
    rng = np.random.default_rng(3)
    pos, mom = rng.uniform(-3, 3, (20, 3)), rng.normal(0, 30, (20, 3))
    p, h = np.array([0.2, -0.1, 0.4]), 1e-3
    grad = np.array([(dipole_field([p + h * e], pos, mom)[0] - dipole_field([p - h * e], pos, mom)[0]) / (2 * h)
                     for e in np.eye(3)])  # grad[i, j] = dB_j / dx_i
    assert abs(np.trace(grad)) < 1e-4 * np.abs(grad).max()


def test_corridor_steel_stands_where_a_building_has_it():
    """A straight corridor keeps every piece: slab steel below and above, columns in both walls, beams across the
    ceiling (over the walkway too), cores 4-10 m off; on the square, nothing at phone height within the corridor's
    half width of any leg (a column or a core placed beside one leg is dropped where it would stand on another)."""
    pos = corridor_steel([(0, 0), (0, 60)], seed=0).positions_enu_m
    x, z = np.abs(pos[:, 0]), pos[:, 2]
    assert np.sum(z < 0) >= 35 and np.sum(np.isclose(z, 3.1)) >= 35  # every 1.5 m of 60 m, floor and ceiling
    assert np.sum(np.isclose(x, 1.5) & (z > 0) & (z < 3)) == 2 * 6 * 10  # 10 bays: a column per wall, 6 pieces
    beams = np.isclose(z, 3.2)
    assert np.sum(beams) == 6 * 10 and np.any(beams & (x < 0.5))
    cores = (x >= 4.0) & (x <= 10.0)
    assert 2 <= np.sum(cores) <= 4 and np.all(np.isclose(z[cores], 1.5))
    pos = corridor_steel(SQUARE, seed=1).positions_enu_m
    t = np.linspace(0.0, 1.0, 301)[:, None]
    legs = np.concatenate([np.add(a, t * np.subtract(b, a)) for a, b in zip(SQUARE[:-1], SQUARE[1:])])
    near = np.min(np.hypot(*(pos[:, None, :2] - legs[None]).transpose(2, 0, 1)), axis=1)
    at_phone_height = (pos[:, 2] > 0.0) & (pos[:, 2] < 3.0)
    assert np.min(near[at_phone_height]) >= 1.2 - 0.01


def test_bent_walk_field_is_an_indoor_one():
    """The corridor's steel turns the field's azimuth at the phone by 5-15 deg rms (measured 7.8 on this walk, 6.3-8.0
    on the 12 tuning seeds), its autocorrelation along the walk halving within 0.5-5 m (1.2 m), the same where the
    walk passes twice."""
    tr = _walk(1, True, True).truth  # the walk the defaults are checked on below (the iron is no field)
    walking = (tr.mag_t_ns > tr.walk_start_t_ns) & (tr.mag_t_ns < tr.walk_end_t_ns)
    h = tr.mag_field_enu_uT[walking]
    az = wrap_angle(np.arctan2(h[:, 1], h[:, 0]) - math.pi / 2)  # the Earth's field points north
    assert 5.0 <= math.degrees(math.sqrt(np.mean(az ** 2))) <= 15.0
    p = tr.phone_position_at(tr.mag_t_ns[walking])
    s = np.r_[0.0, np.cumsum(np.hypot(*np.diff(p[:, :2], axis=0).T))]
    a = np.interp(np.arange(0.0, s[-1], 0.1), s, az - az.mean())
    rho = [np.mean(a[:len(a) - k] * a[k:]) / np.mean(a * a) for k in range(60)]
    assert 0.5 <= 0.1 * np.argmax(np.array(rho) < 0.5) <= 5.0
    # the second lap reads the first lap's field where it passes the same place (within the gait's few cm)
    i = np.searchsorted(s, 30.0)
    lap2 = np.arange(len(s))[s > s[-1] / 2]
    j = lap2[np.argmin(np.hypot(*(p[lap2, :2] - p[i, :2]).T))]
    assert np.hypot(*(p[j, :2] - p[i, :2])) < 0.1
    assert np.linalg.norm(h[i] - h[j]) < 0.5, (h[i], h[j])


def test_defaults_heading_nees_on_a_bent_field():
    """The product's defaults on one bent walk (7 epochs 30 s apart) whose phone keeps the measured residual hard
    iron: heading NEES within the two-sided 95 % band of its mean, [0.24, 2.29] (measured 0.43; without the iron
    0.39); the same filter with the field's error white (no offset state, mag_offset_sd_rad=0) is overconfident there
    (measured 14.7; without the iron 11.0): the bent field and the iron are what the offset state is for.
    (One walk's band is wide: the two-sided check over 12 walks below is the one the defaults miss.)"""
    x = _heading_epochs([_run_against_truth(1, "defaults", True, True)])
    lo, hi = _chi2_mean_band(len(x))
    assert len(x) >= 6
    assert lo <= x.mean() <= hi, (x.mean(), lo, hi)
    white = _heading_epochs([_run_against_truth(1, "white_field", True, True)])
    assert white.mean() > hi, white.mean()


#: what the 12-walk checks of the defaults measured (PDR_CONSISTENCY_SEEDS=12, 84 epochs, band [0.72, 1.32]), with
#: the measured residual hard iron (RESIDUAL_HARD_IRON_SD_UT, 0.6 uT per axis) -- and, for the size of the miss,
#: without it and with other sizes (tuning seeds): uniform field 0.44 (none), 0.49 (0.6), 0.67 (1.1, the Microsoft
#: cross-check of benchmarks.residual_iron), 0.89 (1.5), 1.27 (2.0); bent field 0.50 (none), 0.55 (0.6), 0.73 (1.1),
#: 0.95 (1.5), 1.33 (2.0).  The defaults' heading sigma is about 5.4 deg (the field offset's prior, 0.1 rad) on every
#: walk; the errors (rms per walk, median) are 0.5 deg on the uniform field without iron, 1.7 deg with the measured
#: iron, 3.2 deg on the bent field with it: the defaults would be consistent here with about 1.1-1.9 uT per axis, two
#: to three times the iron measured on the IPIN tuning files (and about what the Microsoft cross-check suggests).
_DEFAULTS_MISS = ("issue #27, missed: the defaults are conservative on the simulator even with the residual hard iron "
                  "measured on the tuning recordings (heading NEES 0.49 uniform field, 0.55 bent field, over 12 walks; "
                  "band [0.72, 1.32]); the settings that would raise it make the IPIN tuning split worse "
                  "(benchmarks/RESULTS.md, 'bent field')")


@pytest.mark.skipif(CONSISTENCY_SEEDS < 6, reason="the two-sided band needs about 80 independent epochs: "
                    "PDR_CONSISTENCY_SEEDS=12 (about 40 s per field)")
@pytest.mark.xfail(strict=True, reason=_DEFAULTS_MISS)
@pytest.mark.parametrize("bent", [False, True], ids=["uniform_field", "bent_field"])
def test_defaults_heading_nees_is_within_its_two_sided_chi2_band(bent):
    """The walks of the declared tuning seeds (benchmarks.splits.SIM_BENT_FIELD_SEEDS, the first
    PDR_CONSISTENCY_SEEDS of them; the uniform field's walks are the same seeds without the steel), the phone with
    the measured residual hard iron, the product's defaults: heading NEES within the two-sided 95 % band of its mean.

    Measured with PDR_CONSISTENCY_SEEDS=12, 84 epochs (band [0.72, 1.32]): uniform field 0.49, bent field 0.55, below
    (_DEFAULTS_MISS; without the iron 0.44 and 0.50).  Bent field, per seed 0.09 to 2.8: most walks conservative, the
    heading sigma about 5 deg -- the offset's prior, a process over 30 s, about 38 m of walking -- against errors
    of 2-4 deg, because the steel's disturbance is correlated over about 1 m and averages out and the measured iron
    (0.6 uT per axis against a horizontal field of 20 uT) turns the heading by about 2 deg; seed 9 overconfident,
    errors of 10 deg, where a gyroscope bias misread while the hand drifted at the start ramps the heading and the
    offset state takes the ramp for the field.  Without the offset state 6.48 (overconfident; 3.27 without the
    iron).  Strict xfail: when a change brings the defaults into the band, this says so.
    PDR_CONSISTENCY_SPLIT=report runs the declared report seeds instead (seen once, with the iron: uniform field
    0.13, bent field 0.48; without it 0.06 and 0.45; the white field's 2.05 and 6.93).
    """
    seeds = SIM_BENT_FIELD_SEEDS[os.environ.get("PDR_CONSISTENCY_SPLIT", TUNING)][:CONSISTENCY_SEEDS]
    x = _heading_epochs([_run_against_truth(seed, "defaults", bent, True) for seed in seeds])
    lo, hi = _chi2_mean_band(len(x))
    assert lo <= x.mean() <= hi, (x.mean(), lo, hi)


def test_residual_hard_iron_is_the_measured_size_and_reaches_the_magnetometer():
    """The draw: seeded, each axis of the measured standard deviation (within 5 % over 2000 seeds); a walk with it
    differs from one without only in its magnetometer, by the drawn offset (within the noise's 0.05 uT)."""
    assert residual_hard_iron_uT(3) == residual_hard_iron_uT(3) != residual_hard_iron_uT(4)
    sd = np.std([residual_hard_iron_uT(s) for s in range(2000)], axis=0)
    np.testing.assert_allclose(sd, RESIDUAL_HARD_IRON_SD_UT, rtol=0.05)
    line = [(0, 0), (0, 8)]
    clean, ironed = (simulate_walk(line, seed=3, mag_hard_iron_uT=h) for h in ((0, 0, 0), residual_hard_iron_uT(3)))
    np.testing.assert_array_equal(clean.recording.streams["gyro"].values, ironed.recording.streams["gyro"].values)
    diff = ironed.recording.streams["mag"].values - clean.recording.streams["mag"].values
    np.testing.assert_allclose(diff.mean(axis=0), residual_hard_iron_uT(3), atol=0.05)


#: heading-NEES epochs this far apart (s): the normalised heading error's autocorrelation on these walks
#: is 0.55-0.72 at 10 s and 0.23-0.46 at 20 s (12 seeds), so epochs 30 s apart count as independent
HEADING_EPOCH_S = 30.0


def _heading_epochs(walked_list):
    """Heading NEES (1 dof) at the first update after 10 s, 40 s, 70 s ... of walking, over the walks."""
    out = []
    for *_, heading in walked_list:
        t_s = heading[:, 0] * 1e-9
        for t0 in np.arange(10.0, t_s[-1], HEADING_EPOCH_S):
            out.append(heading[np.searchsorted(t_s, t0), 1])
    return np.array(out)


def _chi2_mean_band(k, dof=1, p=0.95):
    """Two-sided ``p`` band of the mean of ``k`` independent chi2(dof) samples."""
    from scipy.stats import chi2

    return chi2.ppf((1 - p) / 2, k * dof) / k, chi2.ppf((1 + p) / 2, k * dof) / k


def _leg_means(track_t, headings, truth_t, truth_heading, walk_heading):
    """Mean heading error of each straight leg (steps of a turn and the first two of a leg left out)."""
    k = np.abs(np.asarray(track_t)[:, None] - np.asarray(truth_t)[None, :]).argmin(axis=1)
    err = wrap_angle(np.asarray(headings) - truth_heading[k])
    turning = np.r_[False, np.abs(np.diff(np.unwrap(walk_heading[k]))) > math.radians(3.0)]
    leg = np.cumsum(turning)
    means = []
    for i in np.unique(leg[~turning]):
        m = np.where((leg == i) & ~turning)[0][2:]
        if len(m) > 5:
            means.append(math.atan2(np.mean(np.sin(err[m])), np.mean(np.cos(err[m]))))
    return np.array(means), err, turning


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_every_turn_is_right_within_3_degrees(seed):
    """The product's defaults: the heading change across each corner of a square matches the truth within 3 deg.

    Truth per step: the heading of the device y axis averaged over the step
    (what a hand-held PDR measures: the walking direction plus the phone's
    yaw offset and the hand's drift).  Steps in
    the middle of a turn are right to about 9 deg (the smoother's lag on a
    90 deg/s turn); the legs between turns must agree.
    """
    walk = simulate_walk([(0, 0), (0, 20), (20, 20), (20, 0), (0, 0)], rate_hz=RATE_HZ, seed=seed)
    tr = walk.truth
    res = Pipeline().run(walk.recording)
    assert len(res.steps) == tr.n_steps
    # truth per step: the device y axis' heading averaged over the step (yaw offset and hand drift included)
    t_att = np.asarray(tr.att_t_ns)
    dev = np.asarray(tr.att_device_heading_rad)
    starts = np.r_[tr.walk_start_t_ns, tr.step_t_ns[:-1]]
    truth = np.array([np.mean(dev[(t_att >= a) & (t_att <= b)]) for a, b in zip(starts, tr.step_t_ns)])
    means, err, turning = _leg_means(res.track.t_ns, res.track.heading_rad, tr.step_t_ns, truth,
                                     np.unwrap(tr.step_heading_rad))
    assert len(means) == 4
    turn_errors = np.degrees(wrap_angle(np.diff(means)))
    assert np.max(np.abs(turn_errors)) <= 3.0, turn_errors
    assert np.max(np.abs(np.degrees(wrap_angle(err - means[0])))) < 12.0  # every single step, turns included
