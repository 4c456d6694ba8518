"""Tuning and report splits of every benchmark dataset (issue #8, "Honest numbers").

Every recording belongs to exactly one split:

``tuning``
    Parameters may be chosen by looking at these numbers (``python -m
    benchmarks.tune`` runs only this split unless told otherwise).
``report``
    The numbers we publish and check the targets on.  Nothing is tuned on
    them: :func:`benchmarks.tune.evaluate` refuses this split unless called
    with ``allow_report=True`` (for a final check, never for a search).

The declaration, dataset by dataset:

IPIN 2023 Track 3 (``ipin2023_track3``)
    By route: routes 01, 02, 21, 22 are **tuning**, routes 04, 05, 23, 24
    **report** (every route has its repetitions in one split, so a route's
    geometry is never seen on both sides).
Microsoft indoor location 2020 (``ms_indoor_location_2020``)
    By file: the trace files of a floor folder sorted by file name and
    numbered from 1; odd numbers (1st, 3rd, ...) are **tuning**, even numbers
    **report**.  The numbering counts every trace file in the folder, also the
    few the reader skips (fewer than 3 waypoints), so a file's split never
    depends on the reader's filter.
ETH Sensor Logger walk (``sensorlogger_gps_walk_ethz``)
    Its one recording is **report**.
Outdoor phone walks with GPS (``gps_walks_phone``)
    All **report** (declared with issue #9, before any GPS number was seen on
    them): nothing is tuned on them.
GPS fusion on the simulator (``sim_gps``, :mod:`benchmarks.gnss_eval`)
    Seeds 0-19 of :func:`desktop.simulator.outdoor_walk` are **tuning** (the
    GPS fusion's defaults were set looking at seeds 0-5), seeds 1000-1019
    **report**.
GPS fusion with injected faults (``sim_gps_faults``, :mod:`benchmarks.gnss_faults`, issue #10)
    Seeds 0-9 of :func:`desktop.simulator.outdoor_walk` with the faults of
    :func:`benchmarks.gnss_faults.fault_schedule` are **tuning**, seeds 2000-2009
    **report** (declared before any number of this benchmark was seen; the
    fault walks are other walks than ``sim_gps``'s: longer, 50 Hz, faults).
    Its real walks keep their splits above (the ETH walk and ``gps_walks_phone``
    report, IPIN 2023 by route).
Carry modes on the simulator (``sim_carry``, :mod:`benchmarks.carry`, issue #17)
    Seeds 0-29 of the simulator's placements (:func:`desktop.simulator.simulate_walk` with
    ``placement=``, and the not-walking recordings) are **tuning**, seeds 3000-3029 **report**
    (declared before any carry-mode number was seen).  The carry-mode detector, the per-mode step
    gates and the walking-direction estimator may be tuned on the tuning seeds and on the real
    tuning recordings above (IPIN tuning routes: hand-held; IPOL: waist, the nearest to a belt or
    bag); the Oxford placements (all report, below) and the outdoor phone walks are only reported.
Attitude consistency on a bent field (``sim_bent_field``, ``tests/test_attitude_consistency.py``, issue #27)
    Seeds 1-12 of the simulator's square walk with :func:`desktop.bent_field.corridor_steel` (the building's
    steel as dipoles) are **tuning** (any attitude setting chosen on the simulator is chosen there), seeds
    4001-4012 **report** (declared 2026-12-06 before any number was seen on them).
Oxford step counter, Brajdic-Harle, trundle wheel
    All **report**: nothing will be tuned on them.  Honest caveat: the step
    detector's thresholds and gates were developed before this split existed
    while looking at Oxford and Brajdic-Harle numbers, so those report numbers
    are not from data the detector never saw.
IPOL healthy gait (``ipol_healthy_gait_xsens``)
    All **tuning**: the shipped stride model (``core/pdr/models/default.json``)
    was fitted on these walks, so their distance numbers are training numbers.
    The honest stride-model numbers are the leave-one-subject-out
    cross-validation of :mod:`benchmarks.stride_eval`.

Caveat for the "before" numbers (``benchmarks/baseline_before.json``): our
attitude filter was tuned on all IPIN 2023 routes before the split was
declared, so its IPIN report-split numbers before issue #8 are optimistic.

More phone walks (``phone_walks_more``, issue #25, declared 2026-12-04 before any number was seen on them)
    By repository, about a third tuning: ``thomasdingemanse/ML4QS`` (``thomasdingemanse_lopen``, an
    outdoor GPS walk, probably in a trouser pocket) is **tuning**; ``kim66003/ML4QS_group25`` and
    ``Aymdi/DeadReckoning`` are **report**.
Further public recordings (issue #25, fetched into a folder outside the repository)
    By repository, listed in :data:`REAL_TUNING_REPOS` when they are declared; a repository not
    listed there is **report**.
    Declared 2026-12-06, before any number was seen on them (``/work/extra_data``, its MANIFEST.tsv;
    the rule: the repositories sorted by ``owner/name``, every third from the first is tuning):
    ``fif911/ML4QS`` (one 73-s outdoor phyphox walk with GPS) is **tuning**; ``mikamartinb/ML4QS`` (the 11
    outdoor phyphox walks of 1-2 minutes with GPS fixes and a gyroscope, one walker, of its 78 "gehen"
    walks) is **report**; ``parabiomech/25.GPS-TRACKING`` (one 158-s Sensor Logger recording with GPS,
    Android, added later the same day, declared before it was run) is **report**.  Honest caveat: the
    tuning side of this corpus is one short walk, so it can guide little.
    Declared 2026-12-06 (later the same day, a second search), continuing the same rule over the
    repositories added (the 4th in ``owner/name`` order, so tuning): ``psy901/SensorActivity`` (one 57-s
    counted clip, 100 steps by its file name, Physics Toolbox g-Force Meter, accelerometer only, carry
    not stated) is **tuning**.  Declared before any benchmark number was run on it; honest caveat: one
    ``pdr replay`` of the clip (105 steps) was seen while its new reader was checked, before this
    declaration -- the split follows the rule above, not that number.
    Declared 2026-12-06 (a third search), before any number was seen on it, continuing the same rule (the 5th
    repository in ``owner/name`` order and in order of addition, so report): ``sgrzegorz/StepApp`` (twelve
    20-step clips of 15-19 s, one walker and phone, 100 Hz accelerometer only, the count from the folder name
    ``20steps``, held in front by inference) is **report**.  The same day, the 6th, also before any number:
    ``Omer1Eryilmaz/SignalProcessing`` (seven MATLAB Mobile clips of 48-51 counted steps with the carry stated:
    right / left trouser pocket, a waving hand, a hand; MIT licence; kept in ``/work/extra_data/pending/``
    because no importer reads MATLAB timetable objects yet) is **report**; a reader
    (:mod:`core.importers.matlabmobile`) was added afterwards and the clips moved into the scanned folder, still
    before any number was run on them.
    Declared 2026-12-07 (a fourth search, issue #25 part 1), before any number was seen on it, continuing the same
    rule in order of addition (the 7th repository, so **tuning**): ``yh570/sensibility_testbed`` (Sensibility
    Testbed pedometer experiments of 2016, one Android phone and walker, accelerometer only, 50-150 Hz; thirteen
    clips of 20-500 steps whose count the ``*_result.csv`` files record (the README: "recorded steps"), the carry
    stated per file: hand, trouser pocket, coat pocket) is **tuning**.  The next repository added (the 8th) and the
    9th will be report, the 10th tuning.
    Declared 2026-12-07 (the same search), before any number was seen on it: the 8th repository,
    ``zDrakon/SensorDataExplorer`` (a 2016 high-school class's step-counter data; three SensorLog walks of 50 counted
    steps with the phone in the right side trouser pocket, iPhone 6 Plus, acc + gyro + mag, the count and position
    from the student's ``data_description.txt``), is **report**.
    Declared 2026-12-07 (a fifth search, issue #25 part 1), before any number was seen on them, in this order of
    addition (the order chosen before either was run: the repository whose clips state their carry goes where the
    rule puts tuning): the 9th, ``NIghtwing1914/Assignment2-Ubicomp`` (a 2021 Ubicomp class's MATLAB Mobile step
    clips: 20 accelerometer-only logs of 6-10 s, five walkers, 12-15 steps, the count in the file name and in the
    class's ``Evaluations/Experiment *.csv`` "Ground Truth"; the carry not stated), is **report**; the 10th,
    ``Tclack88/MatlabSucks`` (``sensor_systems/pedometer``: eight MATLAB Mobile accelerometer-only logs of 42-134 s,
    one walker and phone, 80-250 counted steps, the count and the carry -- ``pocket`` / ``hand`` -- in the file
    names, 2023), is **tuning**.  Only the files' rates, lengths and mean gravity were looked at (to check the
    reader), no step count.  The 11th and 12th repository added will be report, the 13th tuning.  Added later the
    same day, after the first run: four more ``Tclack88/MatlabSucks`` clips that the repository keeps only as
    MATLAB-written CSVs (``60_pocket_slow``, ``50_hand_slow``, ``532_hand``, ``70_pause_demo``), tuning with their
    repository.  Of NIghtwing1914's 20 logs, 19 were copied (``Dhvani_12_6.94_14(3)`` has an 11-s gap inside a
    clip its name says lasted 6.94 s).

Truth walks: OxIOD copies with a Vicon track (``oxiod_truth_walks``, :mod:`benchmarks.truth_walks`, issue #25)
    Declared 2026-12-07 (a seventh search, h12/oxdata), **before any number was seen on them** (only the files'
    row and column counts were read, to check the copy).  One repository, ``CantLooseToAMoose/IMU_RELATIVE_POSITIONING``,
    holds the Oxford Inertial Odometry Dataset; the copies present in its snapshot (``/work/extra_data2``, its
    MANIFEST.tsv) are 14 ``syn`` sequences of four placements (handheld 4, pocket 1, running 2, trolley 7), so they
    are split by sequence, not by repository.  The rule: within each placement folder, the sequences sorted by
    (data folder, sequence number); the 1st, 4th, 7th, ... are **tuning**, the others **report** (every third
    from the first, as the extra corpus's repositories are).  So: handheld data1 seq2 and seq7 tuning, seq3 and
    seq4 report; pocket data1 seq5 (the only pocket walk) tuning; running data1 seq6 tuning, seq7 report; trolley
    data1 seq7, data2 seq3 and data2 seq6 tuning, data2 seq1, seq2, seq4, seq5 report.  Honest caveats: the small
    groups make it 7 tuning of 14, not a third; the pocket placement has no report walk (its one walk goes where
    the rule puts it), so a pocket number from here is a tuning number only.  A sequence this does not list
    (another copy, another OxIOD placement) is **report**.

Truth walks: RIDI copies with a Tango track (``ridi_truth_walks``, :mod:`benchmarks.truth_walks`, issue #25)
    Declared 2026-12-07 (the same seventh search, later), **before any number was seen on them** (only the file
    names and the sizes of the snapshot were read).  ``Wdong886/PDR_CNN_BiLSTM_Transformer`` (MIT) holds RIDI
    sequences (Yan, Shan & Furukawa 2018: Android phone, Tango truth) as ``data/error/<name>_data_with_errors.xlsx``;
    28 of them are in the snapshot (the others over 4 MiB): bag 5, body 13, handheld 7, leg (trouser pocket) 3.
    The same rule as OxIOD's: within each placement (the name's second word without its digits), the sequence
    names sorted; the 1st, 4th, 7th, ... are **tuning**, the others **report**.  So tuning: bag ``dan_bag1``,
    ``huayi_bag2``; body ``dan_body1``, ``hang_body_fast1``, ``hao_body2``, ``ma_body2``, ``zhicheng_body2``;
    handheld ``dan_handheld1``, ``ma_handheld3``, ``xiaojing_handheld2``; leg ``dan_leg1`` (11 of 28); every other
    sequence report.  Honest caveat: split by sequence, not by walker, so a walker (``dan`` most) is on both sides.

Truth walks: Tyrex attitude benchmark with a Qualisys track (``tyrex_truth_walks``, :mod:`benchmarks.truth_walks`,
issue #25)
    Declared 2026-12-07 (an eighth search, h13/datahunt), **before any benchmark number was seen on them** (only
    the files' sizes, the Qualisys frame counts, the share of lost frames and the truth's path length and extent
    were read, to check the copy).  ``tyrex-team/benchmarks-attitude-smartphones`` (CeCILL; Michel et al., "On
    attitude estimation with smartphones", PerCom 2017) holds 2-minute walks in a ~5 x 5 m motion-capture room
    (Qualisys, 60 Hz) with a Nexus 5, three walkers (Guillaume, Jakob, Thibaud), each with and without magnetic
    perturbations (``Dist`` / ``NoDist``).  Copied: the three carries this issue lacks, ``FrontPocket``,
    ``BackPocket`` (trouser pockets) and ``Swinging`` (hand swinging): 18 walks.  Split **by walker** (so tuning
    and report never share a walker): **Jakob's 6 walks tuning**, Guillaume's and Thibaud's 12 report (a third).
    The walker was chosen by name before any number, as the one in the middle of the sorted three.  Not
    copied: the hand-held carries (Texting, Phoning, AR), running, the iPhone 4S / 5 recordings (another file
    layout; copied since, below) and ``Jakob_Nexus5_Dist_Swinging_old`` (a superseded take).  A Tyrex walk this does not name is report.
    Declared 2026-12-07 (a ninth search, h14/datahunt), **before any number was seen on them** (only the files' names,
    sizes and sha256 and the Qualisys files' header dates were read, to check the copy and that no walk is another's
    double): the same repository's **iPhone 4S and iPhone 5** walks of the same three carries (``datasets/ios/``, 36
    walks, ``<walker>_<iPhone4S|iPhone5>_<Dist|NoDist>_<carry>``; the folder ``Jakob_iPhone4S_NoDist_Backpocket`` is
    named ``..._BackPocket`` as its ``.mat``).  Separate recordings (their Qualisys exports are of other days than the
    Nexus 5 walks').  No new walker: the same three, so each walk goes to its walker's split -- **Jakob's 12 tuning**,
    Guillaume's and Thibaud's 24 report.  Honest caveat: the tuning pocket walks are still one walker's (now on three
    phones).

A recording the declarations do not name (a dataset, an IPIN route or a repository not listed here)
has never been tuned on: it counts as **report** (issue #29), and :func:`declared` says whether it was
named.
"""

from __future__ import annotations

TUNING = "tuning"
REPORT = "report"
SPLITS = (TUNING, REPORT)

IPIN_TUNING_ROUTES = ("01", "02", "21", "22")
IPIN_REPORT_ROUTES = ("04", "05", "23", "24")

#: simulator seeds of the GPS fusion benchmark
SIM_GPS_SEEDS = {TUNING: tuple(range(0, 20)), REPORT: tuple(range(1000, 1020))}
#: simulator seeds of the GPS fault benchmark (issue #10, :mod:`benchmarks.gnss_faults`)
SIM_GPS_FAULT_SEEDS = {TUNING: tuple(range(0, 10)), REPORT: tuple(range(2000, 2010))}

#: simulator seeds of the carry-mode benchmark (issue #17, :mod:`benchmarks.carry`)
SIM_CARRY_SEEDS = {TUNING: tuple(range(0, 30)), REPORT: tuple(range(3000, 3030))}

#: simulator seeds of the attitude filter's heading consistency on a bent field (issue #27)
SIM_BENT_FIELD_SEEDS = {TUNING: tuple(range(1, 13)), REPORT: tuple(range(4001, 4013))}

#: repositories of real walks whose recordings are tuning (issue #25); every other repository is report
REAL_TUNING_REPOS = frozenset({
    "thomasdingemanse/ML4QS",  # declared 2026-12-04 before any number was seen (phone_walks_more)
    "fif911/ML4QS",  # declared 2026-12-06 before any number was seen (extra corpus; mikamartinb/ML4QS report)
    "psy901/SensorActivity",  # declared 2026-12-06, the rule's 4th extra repository (a counted clip; see the docstring)
    "yh570/sensibility_testbed",  # declared 2026-12-07 before any number was seen, the rule's 7th (counted clips)
    "Tclack88/MatlabSucks",  # declared 2026-12-07 before any number was seen, the rule's 10th (counted clips)
})

#: the repository of each ``phone_walks_more`` walk (its MANIFEST.tsv says the same)
PHONE_WALKS_MORE_REPOS = {
    "thomasdingemanse_lopen": "thomasdingemanse/ML4QS",
    "kim66003_walking_2020-06-03_15-13-20": "kim66003/ML4QS_group25",
    "aymdi_data": "Aymdi/DeadReckoning",
}

#: the OxIOD truth walks' dataset name (:mod:`benchmarks.truth_walks`)
OXIOD_TRUTH_DATASET = "oxiod_truth_walks"
#: OxIOD sequences declared tuning (placement, data folder, sequence number), 2026-12-07 before any number was seen;
#: every other OxIOD sequence is report (see the docstring's rule)
OXIOD_TUNING_SEQUENCES = frozenset({
    ("handheld", "data1", 2), ("handheld", "data1", 7),
    ("pocket", "data1", 5),
    ("running", "data1", 6),
    ("trolley", "data1", 7), ("trolley", "data2", 3), ("trolley", "data2", 6),
})
#: the OxIOD sequences the declaration names (both splits)
OXIOD_DECLARED_SEQUENCES = OXIOD_TUNING_SEQUENCES | frozenset({
    ("handheld", "data1", 3), ("handheld", "data1", 4),
    ("running", "data1", 7),
    ("trolley", "data2", 1), ("trolley", "data2", 2), ("trolley", "data2", 4), ("trolley", "data2", 5),
})


#: the RIDI truth walks' dataset name (:mod:`benchmarks.truth_walks`)
RIDI_TRUTH_DATASET = "ridi_truth_walks"
#: RIDI sequences declared tuning, 2026-12-07 before any number was seen (every other RIDI sequence is report)
RIDI_TUNING_SEQUENCES = frozenset({
    "dan_bag1", "huayi_bag2",
    "dan_body1", "hang_body_fast1", "hao_body2", "ma_body2", "zhicheng_body2",
    "dan_handheld1", "ma_handheld3", "xiaojing_handheld2",
    "dan_leg1",
})
#: the RIDI sequences the declaration names (both splits)
RIDI_DECLARED_SEQUENCES = RIDI_TUNING_SEQUENCES | frozenset({
    "dan_bag2", "hang_bag_side1", "huayi_bag_test1",
    "dan_body2", "dan_body3", "hang_body_test1", "hao_body1", "huayi_body_test1", "ma_body1", "ruixuan_body2",
    "yajie_body2",
    "dan_handheld2", "hang_handheld_side_test2", "ruixuan_handheld2", "shali_handheld1",
    "hao_leg2", "zhicheng_leg2",
})


#: the Tyrex attitude benchmark's truth walks' dataset name (:mod:`benchmarks.truth_walks`)
TYREX_TRUTH_DATASET = "tyrex_truth_walks"
#: Tyrex walkers declared tuning, 2026-12-07 before any number was seen (their declared walks are tuning)
TYREX_TUNING_WALKERS = frozenset({"Jakob"})
#: the Tyrex walks the declaration names (both splits): ``<walker>_<Nexus5|iPhone4S|iPhone5>_<Dist|NoDist>_<carry>``
TYREX_DECLARED_SEQUENCES = frozenset(
    f"{w}_{phone}_{d}_{c}" for w in ("Guillaume", "Jakob", "Thibaud")
    for phone in ("Nexus5", "iPhone4S", "iPhone5")  # the iPhones declared later the same day (the docstring)
    for d in ("Dist", "NoDist") for c in ("FrontPocket", "BackPocket", "Swinging"))


def tyrex_split(sequence: str) -> str:
    """A Tyrex truth walk by its name (``Jakob_Nexus5_NoDist_Swinging``): tuning only if declared and its walker is
    a tuning walker."""
    if sequence in TYREX_DECLARED_SEQUENCES and sequence.split("_")[0] in TYREX_TUNING_WALKERS:
        return TUNING
    return REPORT


def oxiod_split(placement: str, data_folder: str, sequence: int) -> str:
    """An OxIOD truth walk by (placement folder, ``dataN`` folder, sequence number): tuning only if declared so."""
    return TUNING if (placement, data_folder, int(sequence)) in OXIOD_TUNING_SEQUENCES else REPORT


#: datasets whose every recording is in one split
WHOLE_DATASET = {
    "oxford_step_counter": REPORT,
    "brajdic_harle_handheld": REPORT,
    "trundlewheel_distance": REPORT,
    "sensorlogger_gps_walk_ethz": REPORT,
    "gps_walks_phone": REPORT,
    "ipol_healthy_gait_xsens": TUNING,
}


def ms_indoor_split(file_no: int) -> str:
    """Microsoft indoor traces: 1-based number of the file in its sorted folder; odd = tuning, even = report."""
    if int(file_no) < 1:
        raise ValueError(f"file numbers start at 1, got {file_no}")
    return TUNING if int(file_no) % 2 == 1 else REPORT


def ipin_split(route: str) -> str:
    """IPIN 2023 by route; a route not declared has never been tuned on: report."""
    route = f"{int(route):02d}"
    return TUNING if route in IPIN_TUNING_ROUTES else REPORT


def repo_split(repository: str) -> str:
    """A real walk by its source repository (``owner/name``): tuning only if declared so."""
    return TUNING if repository in REAL_TUNING_REPOS else REPORT


def split_of(dataset: str, info: dict | None = None) -> str:
    """The split of one recording from its dataset name and the reader's ``info`` facts.

    ``info`` needs ``route`` for IPIN 2023 and ``file_no`` (1-based, in the
    sorted folder) for the Microsoft traces; other datasets need nothing.
    """
    info = info or {}
    if dataset in WHOLE_DATASET:
        return WHOLE_DATASET[dataset]
    if dataset == "ipin2023_track3" and "route" in info:
        return ipin_split(info["route"])
    if dataset == OXIOD_TRUTH_DATASET and "sequence" in info:
        return oxiod_split(info.get("placement", ""), info.get("data_folder", ""), info["sequence"])
    if dataset == RIDI_TRUTH_DATASET and "sequence" in info:
        return TUNING if info["sequence"] in RIDI_TUNING_SEQUENCES else REPORT
    if dataset == TYREX_TRUTH_DATASET and "sequence" in info:
        return tyrex_split(info["sequence"])
    if dataset == "ms_indoor_location_2020" and "file_no" in info:
        return ms_indoor_split(info["file_no"])
    if "repository" in info:
        return repo_split(info["repository"])
    if dataset == "phone_walks_more" and info.get("walk") in PHONE_WALKS_MORE_REPOS:
        return repo_split(PHONE_WALKS_MORE_REPOS[info["walk"]])
    return REPORT


def declared(dataset: str, info: dict | None = None) -> bool:
    """Whether the declarations above name this recording (else :func:`split_of` says report)."""
    info = info or {}
    if dataset in WHOLE_DATASET:
        return True
    if dataset == "ipin2023_track3":
        return f"{int(info.get('route', -1)):02d}" in IPIN_TUNING_ROUTES + IPIN_REPORT_ROUTES
    if dataset == "ms_indoor_location_2020":
        return "file_no" in info
    if dataset == "phone_walks_more":
        return info.get("walk") in PHONE_WALKS_MORE_REPOS
    if dataset == RIDI_TRUTH_DATASET:
        return info.get("sequence") in RIDI_DECLARED_SEQUENCES
    if dataset == TYREX_TRUTH_DATASET:
        return info.get("sequence") in TYREX_DECLARED_SEQUENCES
    if dataset == OXIOD_TRUTH_DATASET:
        return (info.get("placement"), info.get("data_folder"), int(info.get("sequence", -1))) in OXIOD_DECLARED_SEQUENCES
    return "repository" in info


def trial_split(trial) -> str:
    """:func:`split_of` for a :class:`benchmarks.datasets.base.Trial`."""
    return split_of(trial.dataset, trial.info)


def check_split(split: str) -> str:
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}: one of {', '.join(SPLITS)}")
    return split
