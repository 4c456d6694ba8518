"""desktop.placements: the simulator's carry placements (issue #17) and its recordings of not walking.

Short walks (about 30 s) shared per module; the whole file runs in a few seconds.  The physics is checked
as for the hand-held model (the accelerometer integrates to the phone's path, the gyroscope to its
attitude), then each placement's signature, with tolerances stated next to each assertion.
"""

import hashlib
import json
import math

import numpy as np
import pytest

from core import quaternion as quat
from core.conventions import CARRY_MODES, CARRY_STILL
from core.recording import read_recording, write_recording
from desktop.placements import STILL_KINDS, simulate_still
from desktop.simulator import simulate_walk

G = 9.80665
PATH = [(0, 0), (25, 0), (25, 8)]
QUIET = dict(gyro_noise_rad_s=0.0, gyro_bias_rad_s=(0, 0, 0), acc_noise_m_s2=0.0, mag_noise_uT=0.0)
CARRIED = ("swinging", "pocket", "bag", "ear")
_CACHE = {}


def walk(placement, **kw):
    key = (placement, repr(sorted(kw.items(), key=str)))
    if key not in _CACHE:
        _CACHE[key] = simulate_walk(PATH, placement=placement, rate_hz=200.0, **QUIET, seed=11, **kw)
    return _CACHE[key]


def walking(stream, truth, margin_s=2.0):
    """Samples of ``stream`` in the walk, ``margin_s`` from its start and end (cruising)."""
    m = (stream.t_ns > truth.walk_start_t_ns + margin_s * 1e9) & (stream.t_ns < truth.walk_end_t_ns - margin_s * 1e9)
    return stream.t_ns[m], stream.values[m]


def dominant_hz(t_ns, x):
    """Frequency (Hz) of the largest spectral peak of ``x`` (resampled to a uniform grid), above 0.3 Hz."""
    t = (t_ns - t_ns[0]) * 1e-9
    grid = np.arange(0.0, t[-1], 0.01)
    y = np.interp(grid, t, x)
    y = (y - y.mean()) * np.hanning(len(y))
    spec = np.abs(np.fft.rfft(y, 8 * len(y)))
    freq = np.fft.rfftfreq(8 * len(y), 0.01)
    spec[freq < 0.3] = 0.0
    return float(freq[np.argmax(spec)])


def integrate_twice(t_ns, acc_b, truth):
    """The phone's displacement from the accelerometer (rotated by the truth attitude, minus g; trapezoid twice
    from the truth velocity) and from the truth position, both (n, 3) from the first sample."""
    a_n = np.einsum("nij,nj->ni", quat.to_matrix_array(truth.attitude_at(t_ns)), acc_b) - [0, 0, G]
    dt = np.diff(t_ns) * 1e-9
    vel = truth.phone_velocity_at(t_ns[0]) + np.concatenate(
        [np.zeros((1, 3)), np.cumsum(0.5 * (a_n[1:] + a_n[:-1]) * dt[:, None], axis=0)])
    pos = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt[:, None], axis=0)])
    phone = truth.phone_position_at(t_ns)
    return pos, phone - phone[0]


def highpass_rms(t_ns, x, above_hz):
    t = (t_ns - t_ns[0]) * 1e-9
    grid = np.arange(0.0, t[-1], 0.005)
    y = np.interp(grid, t, x)
    spec = np.fft.rfft(y - y.mean())
    spec[np.fft.rfftfreq(len(y), 0.005) < above_hz] = 0.0
    return float(np.std(np.fft.irfft(spec, len(y))))


# -- the default is today's hand-held model -------------------------------------------------------------


def test_default_placement_gives_the_same_recording_as_before_placements():
    """Digest of a short default walk, computed with the simulator before the placements were added (values
    rounded to 1e-6 so that last-bit differences of another numpy cannot flip it)."""
    w = simulate_walk([(0, 0), (20, 0), (20, 10)], seed=3)
    h = hashlib.sha256()
    for name in sorted(w.recording.streams):
        s = w.recording.streams[name]
        h.update(name.encode())
        h.update(s.t_ns.astype("<i8").tobytes())
        h.update(np.round(s.values, 6).astype("<f8").tobytes())
    assert h.hexdigest() == "614f0f2172afea11cbed4332c8e0d6e03edc7d1577b64e482d34bd8c1274de24"
    assert "placement" not in w.recording.metadata  # the hand-held header is unchanged
    assert w.truth.placement == "handheld" and w.truth.side is None


def test_every_placement_walks_the_same_walk():
    """The placement changes only where the phone is: heel strikes, step lengths and path are the seed's."""
    base = walk("handheld")
    for p in CARRIED:
        tr = walk(p).truth
        assert tr.placement == p and p in CARRY_MODES
        np.testing.assert_array_equal(tr.step_t_ns, base.truth.step_t_ns)
        np.testing.assert_array_equal(tr.step_length_m, base.truth.step_length_m)
        t = base.recording.streams["acc"].t_ns[::50]
        np.testing.assert_allclose(tr.heading_at(t), base.truth.heading_at(t))
        md = walk(p).recording.metadata
        assert md["placement"] == p and md["placement_info"] == tr.placement_info
        json.dumps(md)


@pytest.mark.parametrize("placement", CARRIED)
def test_accelerometer_integrates_to_the_phone_path(placement):
    """Specific force rotated by the truth attitude minus g, integrated twice (trapezoid, 200 Hz) over 4 s of
    cruising from the truth position and velocity, meets the phone's truth path within 1.5 cm."""
    w = walk(placement)
    tr = w.truth
    acc = w.recording.streams["acc"]
    t_ns, a_b = walking(acc, tr, 5.0)
    t_ns, a_b = t_ns[:800], a_b[:800]
    pos, phone = integrate_twice(t_ns, a_b, tr)
    assert np.max(np.abs(pos - phone)) < 0.015


@pytest.mark.parametrize("placement", CARRIED)
def test_gyro_integrates_to_the_truth_attitude(placement):
    """Second-order integration of the noiseless 200 Hz gyro over the whole walk: within 0.5 deg."""
    w = walk(placement)
    tr = w.truth
    gyro = w.recording.streams["gyro"]
    q = tr.attitude_at(gyro.t_ns[0])
    dt = np.diff(gyro.t_ns) * 1e-9
    rv = 0.5 * (gyro.values[1:] + gyro.values[:-1]) * dt[:, None]
    for r in rv.tolist():
        q = quat.normalize(quat.multiply(q, quat.from_rotation_vector(r)))
    q_end = tr.attitude_at(gyro.t_ns[-1])
    assert math.degrees(2.0 * math.acos(min(1.0, abs(float(np.dot(q, q_end)))))) < 0.5
    np.testing.assert_allclose(tr.body_rate_at(gyro.t_ns[::97]), gyro.values[::97], atol=1e-9)


# -- each placement's signature -------------------------------------------------------------------------


def test_swinging_arm_gyro_peaks_of_3_to_6_rad_s_at_the_stride_frequency():
    w = walk("swinging")
    tr = w.truth
    t_ns, g = walking(w.recording.streams["gyro"], tr)
    norm = np.linalg.norm(g, axis=1)
    assert 3.0 < np.percentile(norm, 99) < 6.0
    stride_hz = 0.5 * tr.n_steps / ((tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9)
    axis = int(np.argmax(g.var(axis=0)))
    assert dominant_hz(t_ns, g[:, axis]) == pytest.approx(stride_hz, abs=0.1)
    assert tr.side in ("left", "right")


def test_pocket_phone_is_upright_pitching_with_the_thigh_and_feels_its_own_leg_more():
    w = walk("pocket")
    tr = w.truth
    acc = w.recording.streams["acc"]
    t_ns, _ = walking(acc, tr)
    y_n = quat.to_matrix_array(tr.attitude_at(t_ns))[:, :, 1]
    tilt = np.degrees(np.arccos(np.abs(y_n[:, 2])))  # device y from the vertical (up or down)
    assert np.median(tilt) < 20 and np.max(tilt) < 40
    # the thigh's swing: the device y axis leans forward and back once per stride
    h = tr.heading_at(t_ns)
    lean = y_n[:, 0] * np.cos(h) + y_n[:, 1] * np.sin(h)
    stride_hz = 0.5 * tr.n_steps / ((tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9)
    assert dominant_hz(t_ns, lean) == pytest.approx(stride_hz, abs=0.1)
    assert 25 < np.degrees(np.ptp(np.arcsin(lean))) < 60  # about +-20 deg of thigh swing
    # heel strikes of the pocket leg are felt more strongly than the other leg's: the transient (acc norm
    # above 15 Hz) within 40 ms of the heel strike is about 4 / 1.5 times as large (asked: 2)
    t0 = acc.t_ns[0]
    grid = np.arange(0.0, (acc.t_ns[-1] - t0) * 1e-9, 0.005)
    y = np.interp(grid, (acc.t_ns - t0) * 1e-9, np.linalg.norm(acc.values, axis=1))
    spec = np.fft.rfft(y - y.mean())
    spec[np.fft.rfftfreq(len(y), 0.005) < 15.0] = 0.0
    hf = np.abs(np.fft.irfft(spec, len(y)))
    peaks = np.array([hf[np.abs(grid - (t - t0) * 1e-9) < 0.04].max() for t in tr.step_t_ns[2:-2]])
    own = tr.step_foot[2:-2] == tr.side
    assert peaks[own].mean() > 2.0 * peaks[~own].mean()


def test_swinging_arm_swings_more_when_walking_faster():
    """The arm's amplitude grows with speed: 95th percentile of |gyro| at 2.1 steps/s (walk-ratio steps,
    1.71 m/s) at least 1.3 times that at 1.5 steps/s (0.88 m/s) (the model gives about (1.71/0.88) ~ 1.9)."""
    p95 = []
    for f in (1.5, 2.1):
        w = simulate_walk([(0, 0), (20, 0)], placement="swinging", step_frequency_hz=f, **QUIET, seed=2)
        p95.append(np.percentile(np.linalg.norm(walking(w.recording.streams["gyro"], w.truth)[1], axis=1), 95))
    assert p95[1] > 1.3 * p95[0]


def test_placements_are_reproducible_and_a_given_option_moves_no_other_draw():
    a = simulate_walk([(0, 0), (10, 0)], placement="bag", seed=6)
    b = simulate_walk([(0, 0), (10, 0)], placement="bag", seed=6)
    np.testing.assert_array_equal(a.recording.streams["acc"].values, b.recording.streams["acc"].values)
    info = a.truth.placement_info
    c = simulate_walk([(0, 0), (10, 0)], placement="bag", seed=6, placement_options={"kind": info["kind"]})
    np.testing.assert_array_equal(a.recording.streams["gyro"].values, c.recording.streams["gyro"].values)
    assert c.truth.placement_info == info


@pytest.mark.parametrize("placement, options, sign", [("pocket", {"top": "hip"}, -1), ("pocket", {"top": "knee"}, 1),
                                                      ("swinging", {"grip": "down"}, 1)])
def test_the_phone_turns_with_the_limb_that_carries_it(placement, options, sign):
    """Position and attitude tell the same story: when the thigh (arm) swings forward the phone moves forward
    and its long axis leans with the limb: device y pointing to the hip leans back, to the knee (or down the
    forearm) forward: the correlation of the two over the walk is strong and of that sign."""
    w = simulate_walk(PATH, placement=placement, placement_options=options, rate_hz=50.0, seed=3)
    tr = w.truth
    t_ns, _ = walking(w.recording.streams["acc"], tr)
    h = tr.heading_at(t_ns)
    fwd = np.stack([np.cos(h), np.sin(h)], axis=1)
    ahead = np.sum((tr.phone_position_at(t_ns)[:, :2] - tr.position_at(t_ns)) * fwd, axis=1)
    y_n = quat.to_matrix_array(tr.attitude_at(t_ns))[:, :2, 1]
    lean = np.sum(y_n * fwd, axis=1)
    assert sign * np.corrcoef(ahead, lean)[0, 1] > 0.8


def test_pocket_side_and_orientation_can_be_given():
    w = simulate_walk(PATH, placement="pocket", placement_options={"side": "left", "top": "knee", "screen": "in"},
                      seed=4)
    tr = w.truth
    assert tr.side == "left" and tr.placement_info["top"] == "knee" and tr.placement_info["screen"] == "in"
    y_n = quat.to_matrix_array(tr.attitude_at(tr.walk_start_t_ns - 10**9))[:, 1]
    assert y_n[2] < -0.9  # the top toward the knee: device y points down


def test_bag_has_less_high_frequency_content_than_the_pocket():
    """The spring between trunk and bag filters the heel strikes: acc-norm content above 10 Hz at most half
    the pocket's, and the bag turns less than the thigh."""
    hf = {}
    for p in ("bag", "pocket"):
        w = walk(p)
        t_ns, a = walking(w.recording.streams["acc"], w.truth)
        hf[p] = highpass_rms(t_ns, np.linalg.norm(a, axis=1), 10.0)
        hf[p + "_gyro"] = np.percentile(np.linalg.norm(walking(w.recording.streams["gyro"], w.truth)[1], axis=1), 95)
    assert hf["bag"] < 0.5 * hf["pocket"]
    assert hf["bag_gyro"] < hf["pocket_gyro"]
    info = walk("bag").truth.placement_info
    assert 3.0 <= info["natural_hz"] <= 6.0 and 0.2 <= info["damping"] <= 0.4


def test_bag_phone_orientation_is_arbitrary_per_seed():
    faces = {simulate_walk([(0, 0)], placement="bag", still_start_s=1.0, rate_hz=20.0, seed=s).truth
             .placement_info["face_up"] for s in range(12)}
    assert len(faces) >= 4


def test_ear_phone_has_gravity_along_device_y_and_the_screen_sideways():
    w = walk("ear")
    tr = w.truth
    t_ns, a = walking(w.recording.streams["acc"], tr)
    mean = a.mean(axis=0)
    assert mean[1] / np.linalg.norm(mean) > math.cos(math.radians(45))  # device y up within 45 deg
    fwd = tr.forward_in_device_at(t_ns)
    assert np.max(np.abs(fwd[:, 2])) < 0.35  # the screen faces the head: z is across the walking direction
    assert tr.side in ("left", "right")


def test_forward_in_device_is_the_walking_direction():
    for p in ("handheld",) + CARRIED:
        tr = walk(p).truth
        t = tr.step_t_ns[::7]
        fwd_n = np.einsum("nij,nj->ni", quat.to_matrix_array(tr.attitude_at(t)), tr.forward_in_device_at(t))
        h = tr.heading_at(t)
        np.testing.assert_allclose(fwd_n, np.stack([np.cos(h), np.sin(h), 0 * h], axis=1), atol=1e-12)


# -- not walking -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", STILL_KINDS)
def test_still_recordings_have_no_steps_and_measure_g(kind):
    w = simulate_still(kind, 30.0, seed=5)
    tr = w.truth
    assert tr.placement == CARRY_STILL and tr.placement_info["kind"] == kind and tr.n_steps == 0
    acc = w.recording.streams["acc"]
    norm = np.linalg.norm(acc.values, axis=1)
    assert w.recording.duration_s == pytest.approx(30.0, abs=0.05)
    assert abs(norm.mean() - G) < 0.05
    gyro = np.linalg.norm(w.recording.streams["gyro"].values, axis=1)
    if kind == "table":
        assert norm.std() < 0.05 and gyro.max() < 0.03  # noise and bias only
    elif kind == "hand_standing":
        assert 0.02 < norm.std() < 0.3 and gyro.max() < 0.5  # tremor and drift, no gait
    else:
        t = acc.t_ns
        pos = tr.position_at(t)
        speed = np.hypot(*np.gradient(pos, t * 1e-9, axis=0).T)
        assert speed.max() > 5.0  # it drives
        assert norm.std() > 0.1  # road vibration and manoeuvres
        a_n = np.einsum("nij,nj->ni", quat.to_matrix_array(tr.attitude_at(t)), acc.values)
        assert 0.5 < np.percentile(np.hypot(a_n[:, 0], a_n[:, 1]), 99) < 3.0
        assert tr.placement_info["bumps"] > 0 and np.max(np.abs(a_n[:, 2] - G)) > 0.9  # road bumps of 1-3 m/s^2


def test_vehicle_accelerometer_is_the_second_derivative_of_its_position():
    w = simulate_still("vehicle", 20.0, seed=2, rate_hz=400.0, **QUIET)
    tr = w.truth
    acc = w.recording.streams["acc"]
    t_ns, a_b = acc.t_ns[2000:3600], acc.values[2000:3600]
    pos, phone = integrate_twice(t_ns, a_b, tr)
    assert np.max(np.abs(pos - phone)) < 0.01


def test_placement_recordings_round_trip_through_the_file_format(tmp_path):
    for i, w in enumerate((simulate_walk([(0, 0), (4, 0)], placement="pocket", rate_hz=50.0, seed=1),
                           simulate_still("vehicle", 5.0, rate_hz=50.0, seed=1))):
        path = str(tmp_path / f"r{i}.csv.gz")
        write_recording(path, w.recording)
        back = read_recording(path)
        assert back.metadata == w.recording.metadata and back.metadata["placement"] == w.truth.placement
        np.testing.assert_array_equal(back.streams["acc"].values, w.recording.streams["acc"].values)


def test_swinging_arm_swung_hard_turns_at_9_to_10_rad_s():
    """``swing_scale`` (issue #25): the held-back clip's hand swung at up to 9-10 rad/s is ``swing_scale`` 2.5-2.8;
    the gyroscope's peaks scale with it, at the same stride frequency, and the walk is the same walk."""
    w1, w25 = walk("swinging"), walk("swinging", placement_options={"swing_scale": 2.5})
    p1 = np.percentile(np.linalg.norm(walking(w1.recording.streams["gyro"], w1.truth)[1], axis=1), 99.9)
    t_ns, g = walking(w25.recording.streams["gyro"], w25.truth)
    p25 = np.percentile(np.linalg.norm(g, axis=1), 99.9)
    assert 8.0 < p25 < 10.5
    assert p25 > 2.0 * p1  # the twist and the hand drift do not scale
    tr = w25.truth
    stride_hz = 0.5 * tr.n_steps / ((tr.walk_end_t_ns - tr.walk_start_t_ns) * 1e-9)
    assert dominant_hz(t_ns, g[:, int(np.argmax(g.var(axis=0)))]) == pytest.approx(stride_hz, abs=0.1)
    assert np.array_equal(tr.step_t_ns, w1.truth.step_t_ns)
    assert tr.placement_info["swing_scale"] == 2.5
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="swinging", placement_options={"swing_scale": 0.0})


def test_swinging_arm_twist_spreads_the_rotation_over_two_axes():
    """``twist_deg`` (issue #25): a forearm twisting 25 deg each way as the hand swings spreads the rotation over two
    axes (the main axis holds under 0.75 of the gyroscope's variance, over 0.85 at the default 8 deg); the walk and
    its heel strikes are the same walk; a twist outside 0-90 deg is refused."""
    w8, w25 = walk("swinging"), walk("swinging", placement_options={"twist_deg": 25.0})

    def share(w):
        g = walking(w.recording.streams["gyro"], w.truth)[1]
        ev = np.linalg.eigvalsh(np.cov(g.T))
        return ev[-1] / ev.sum()

    assert share(w8) > 0.85 and share(w25) < 0.75, (share(w8), share(w25))
    assert np.array_equal(w25.truth.step_t_ns, w8.truth.step_t_ns)
    assert w25.truth.placement_info["twist_amp_deg"] == 25.0
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="swinging", placement_options={"twist_deg": 120.0})


def test_invalid_placements_are_rejected():
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="helmet")
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="pocket", placement_options={"colour": "red"})
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="pocket", placement_options={"side": "middle"})
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="still", placement_options={"kind": "table"})  # walking: not still
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="bag", calibration_motion_s=5.0)
    with pytest.raises(ValueError):
        simulate_walk(PATH, placement="handheld", placement_options={"side": "left"})
    with pytest.raises(ValueError):
        simulate_still("sofa")
