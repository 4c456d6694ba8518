"""Train the step-length models of ``core.pdr.stride_models`` (desktop tool).

Usage (from the repository root)::

    python -m tools.train_stride                    # LOSO CV table, then fit on all subjects and write core/pdr/models/
    python -m tools.train_stride --no-write         # only the cross-validation
    python -m tools.train_stride --data-root PATH   # data elsewhere than ../shared/data
    python -m tools.train_stride --phones           # issue #25: refit default.json's C on the tuning split's
                                                    # phones, score it on the report split's (no IPOL study)

The fitting code is :mod:`desktop.stride_training`; the study (walks from the
datasets, leave-one-subject-out) is :mod:`benchmarks.stride_eval`.
"""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from benchmarks import stride_eval  # noqa: E402
from benchmarks.datasets.base import default_data_root  # noqa: E402
from desktop.stride_training import TrainConfig  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data-root", type=Path, default=default_data_root())
    ap.add_argument("--out-dir", type=Path, default=ROOT / "core" / "pdr" / "models")
    ap.add_argument("--no-write", action="store_true", help="only run the cross-validation")
    ap.add_argument("--seed", type=int, default=TrainConfig.seed)
    ap.add_argument("--extra", type=Path, default=None,
                    help="--phones: the extra corpus of issue #25 (default /work/extra_data when present)")
    ap.add_argument("--phones", action="store_true",
                    help="refit the default Weinberg C on the tuning split's phone walks (issue #25)")
    args = ap.parse_args(argv)
    if args.phones:
        return _phones(args)
    cfg = TrainConfig(seed=args.seed)
    study = stride_eval.run_study(args.data_root, cfg)
    print(stride_eval.render_markdown(study))
    if not args.no_write:
        written = stride_eval.write_models(study, args.out_dir, cfg,
                                           created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        for p in written:
            print(f"wrote {p}")
    return 0


def _phones(args) -> int:
    """Refit ``default.json``'s C on the tuning split's phones (leave-one-dataset-out on the tuning split for
    the transfer); the report split's phones are only scored.  Prints the table; writes unless ``--no-write``."""
    import json

    from core.pdr.stride_models import load_stride_model, save_stride_model

    walks = stride_eval.phone_walks(args.data_root, args.extra)
    c_new = stride_eval.fit_phone_c(walks, "tuning")
    lodo = stride_eval.leave_one_dataset_out(walks)
    path = args.out_dir / "default.json"
    old = json.loads(path.read_text(encoding="utf-8"))
    training = dict(old.get("training", {}))
    c_old = float(training.get("phones", {}).get("c_before", old["c"]))  # the IPOL fit, also after a refit
    print(stride_eval.phone_distance_markdown(walks, c_old, c_new, lodo))
    if args.no_write:
        return 0
    model = load_stride_model(path)
    model.coefficient.c = c_new
    tuning = [w for w in walks if w.split == "tuning"]
    stats = stride_eval.error_stats([w.error_pct(c_new) for w in tuning])
    training["phones"] = {
        "issue": 25, "tool": "python -m tools.train_stride --phones", "split": "tuning",
        "data": "IPIN 2023 tuning routes 01, 02, 21, 22 (hand-held, two phones; surveyed landmark stretches) and "
                "the tuning split's phone walks with GPS (benchmarks.splits.REAL_TUNING_REPOS) by their straight "
                "40-s chords of good fixes: phone_walks_more/thomasdingemanse_lopen (carry detected as bag, "
                "probably a trouser pocket); fif911/ML4QS has no straight chord, psy901/SensorActivity no distance",
        "walks": [{"name": w.name, "dataset": w.dataset, "truth": w.truth, "distance_m": round(w.distance_m, 1),
                   "carry_mode": stride_eval.mode_share(w)[0], "c": round(w.c_needed(), 4)} for w in tuning],
        "rule": "1 / mean over the datasets of (mean over the dataset's walks of 1 / C_walk): zero mean signed "
                "error, every source weighted alike; one C for every carry mode (a per-mode C had one walk "
                "outside the hand and gave the same leave-one-dataset-out errors)",
        "tuning_error_pct": {"median_abs": round(stats["median_abs_pct"], 2),
                             "mean_signed": round(stats["mean_signed_pct"], 2), "walks": stats["n"]},
        "leave_one_dataset_out": [
            {"held_out": ds, "c": round(float(m), 4),
             **{k: round(v, 2) for k, v in stride_eval.error_stats([e for _, e in errs]).items()
                if k.endswith("_pct")}} for ds, m, errs in lodo],
        "c_before": c_old,
    }
    meta = {k: v for k, v in old.items() if k not in ("format", "format_version", "kind", "inputs", "output", "c",
                                                      "c_unit", "length_clip_m")}
    meta.update(description="default = Weinberg, constant C refitted on the tuning split's phones (issue #25)",
                placement="phone", training=training,
                created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
    save_stride_model(model, path, **meta)
    print(f"wrote {path}: C {c_old:.4f} -> {c_new:.4f} (now also core.pdr.stride.ConstantCoefficient's default)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
