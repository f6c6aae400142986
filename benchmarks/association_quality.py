"""Association precision and recall of the closed loops against the simulator's walls.

python benchmarks/association_quality.py --seeds 0-9 --duration 600
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from datasets.simulator import simulate
from datasets.source import open_dataset
from slam.backends.ekf import EkfConfig, LineEkf
from slam.backends.isam2.graph import GraphConfig, isam2_backend_factory, pose_source_of
from slam.eval.consistency import association_against_truth
from slam.run.closed_loop import run_closed_loop
from slam.run.run import default_extractor_config


def measure(source: Path, backend: str) -> dict[str, float]:
    ds = open_dataset(source)
    mount = ds.config.sonar_mounting
    if backend == "ekf":
        res = run_closed_loop(
            ds,
            lambda t, p, c: LineEkf(t, p, c, mount, EkfConfig()),
            default_extractor_config(ds),
            progress=False,
        )
    else:
        res = run_closed_loop(
            ds,
            isam2_backend_factory(mount, GraphConfig()),
            default_extractor_config(ds),
            pose_source_of=pose_source_of,
            progress=False,
        )
    s = association_against_truth(ds, res)
    return {
        "precision": s.precision,
        "recall": s.recall,
        "associated": s.n_associated,
        "true_pairs": s.n_true_pairs,
        "spurious": s.n_spurious,
        "seeds": s.n_seeds,
        "seed_precision": s.seed_precision,
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
