"""Train the step-length models of ``core.pdr.stride_models`` (desktop tool).

Usage (from the repository root)::

    python -m tools.train_stride                    # LOSO CV table, then fit on all subjects and write core/pdr/models/
    python -m tools.train_stride --no-write         # only the cross-validation
    python -m tools.train_stride --data-root PATH   # data elsewhere than ../shared/data

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
    args = ap.parse_args(argv)
    cfg = TrainConfig(seed=args.seed)
    study = stride_eval.run_study(args.data_root, cfg)
    print(stride_eval.render_markdown(study))
    if not args.no_write:
        written = stride_eval.write_models(study, args.out_dir, cfg,
                                           created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        for p in written:
            print(f"wrote {p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
