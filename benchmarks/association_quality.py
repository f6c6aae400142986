"""Association precision and recall of the closed loops against the simulator's walls.

python benchmarks/association_quality.py --seeds 0-9 --duration 600
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from sonarslam.datasets.simulator import simulate
from sonarslam.datasets.source import open_dataset
from sonarslam.slam.run.run import run_backend


def measure(source: Path, backend: str) -> dict[str, float]:
    """The association scores the runner measures against the true walls (``truth_*``)."""
    m = run_backend(open_dataset(source), backend).metrics
    return {
        "precision": m["truth_precision"],
        "recall": m["truth_recall"],
        "associated": m["truth_associations"],
        "true_pairs": m["truth_reobservations"],
        "spurious": m["truth_spurious_features"],
        "seeds": m["truth_seeds"],
        "seed_precision": m["truth_seed_precision"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", default="0-9", help="range of harbour seeds, e.g. 0-9")
    parser.add_argument("--duration", type=float, default=600.0, help="seconds per run")
    parser.add_argument("--out", default=None, help="results JSON")
    args = parser.parse_args()
    lo, hi = (int(v) for v in args.seeds.split("-"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(lo, hi + 1):
            src = simulate(
                "harbour", seed=seed, out_dir=Path(tmp) / f"h{seed}", duration_s=args.duration
            )
            for backend in ("ekf", "isam2"):
                rows.append({"seed": seed, "backend": backend, **measure(src, backend)})
    for backend in ("ekf", "isam2"):
        r = [x for x in rows if x["backend"] == backend]
        n = sum(x["associated"] for x in r)
        prec = sum(x["precision"] * x["associated"] for x in r) / n
        m = sum(x["true_pairs"] for x in r)
        rec = sum(x["recall"] * x["true_pairs"] for x in r if x["true_pairs"]) / m
        seeds = sum(x["seeds"] for x in r)
        seed_ok = sum(x["seed_precision"] * x["seeds"] for x in r if x["seeds"])
        print(
            f"{backend}: precision {prec:.4f} over {n} associations; recall {rec:.4f} over {m}"
            f" re-observations of mapped lines; {seeds} seeding observations"
            f" ({seed_ok / max(seeds, 1):.4f} on their landmark's line);"
            f" spurious features {sum(x['spurious'] for x in r)}"
        )
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
