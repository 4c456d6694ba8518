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
    """Refit the default's C on the tuning split's phones (leave-one-dataset-out on the tuning split for the
    transfer); the report split's phones are only scored.  Prints the table; writes ``OUT_DIR/default.json``
    unless ``--no-write`` (the shipped default's other fields kept; ``--out-dir`` elsewhere leaves it alone)."""
    import json

    from core.pdr.stride_models import MODELS_DIR

    walks = stride_eval.phone_walks(args.data_root, args.extra)
    old = json.loads((MODELS_DIR / "default.json").read_text(encoding="utf-8"))
    c_old = float(old.get("training", {}).get("phones", {}).get("c_before", old["c"]))  # the IPOL fit
    lodo = stride_eval.leave_one_dataset_out(walks)
    print(stride_eval.phone_distance_markdown(walks, c_old, stride_eval.fit_phone_c(walks), lodo))
    if args.no_write:
        return 0
    path = args.out_dir / "default.json"
    d = stride_eval.write_phone_default(walks, old, path,
                                        created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
    print(f"wrote {path}: C {c_old:.4f} -> {d['c']:.4f} (the pipeline's built-in default is "
          "core.pdr.stride.ConstantCoefficient's: change it too to ship this)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
