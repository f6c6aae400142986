"""The long mode of the project's fuzzer: seeded mutations of small real slices through every
reader, the configuration loaders (``sonarslam.toml``, ``extract --config``, ``--set``) and the
dataset opener, each judged by an oracle (``tests/fuzzing.py`` says what is checked).

python benchmarks/fuzz_readers.py [--cases 20000] [--seed 0] [--out FILE.json]

Prints one row per target: cases, accepted, data errors (and how many name a line), foreign
exceptions, hangs (no answer in 10 s), and cases the oracle found wrong (an accepted value
that is not finite or not what the file says, a value cut short and kept, a broken promise of
the gates, an error naming another file or a line the mutation did not touch); then up to
five examples of each problem; then the named bad bags of issue 30 (``tests/fuzz_inputs.bad_bags``:
what each must give and what it gave). The seeds are the marina's slices when ``$SONARSLAM_DATA`` holds
it, a 20 s simulated harbour's otherwise. The process's memory is capped (4 GiB of address
space) so that a reader that reads without end fails here instead of exhausting the machine.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the fuzzer lives in tests/

from tests.fuzz_inputs import bad_bags  # noqa: E402
from tests.fuzzing import build_seeds, fuzz, summarise  # noqa: E402

MEMORY_CAP_BYTES = 4 * 2**30


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", type=int, default=20000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="JSON of the table and the problems")
    args = parser.parse_args()
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP_BYTES, MEMORY_CAP_BYTES))
    work = Path(tempfile.mkdtemp(prefix="fuzz_readers_"))
    seeds = build_seeds(work)
    label = "marina slices" if "sim_dataset" in seeds else "simulated harbour slices"
    wall0 = time.perf_counter()

    def progress(i: int) -> None:
        if (i + 1) % 1000 == 0:
            print(f"  {i + 1} cases, {time.perf_counter() - wall0:.0f} s", file=sys.stderr)

    outcomes = fuzz(seeds, args.cases, work, seed=args.seed, progress=progress)
    wall_s = time.perf_counter() - wall0
    rows = summarise(outcomes)
    total = {k: sum(int(r[k]) for r in rows) for k in rows[0] if k != "target"}
    print(f"{args.cases} cases on {label}, seed {args.seed}, in {wall_s:.0f} s\n")
    print("| target | cases | accepted | DataError (with line) | foreign | hang | wrong |")
    print("|---|---|---|---|---|---|---|")
    for r in [*rows, {"target": "**all**", **total}]:
        print(
            f"| {r['target']} | {r['cases']} | {r['accepted']} | {r['data_error']} "
            f"({r['with_line']}) | {r['foreign']} | {r['hang']} | {r['problems']} |"
        )
    bad = [o for o in outcomes if o.problems or o.status in ("foreign", "hang")]
    kinds = Counter((o.target, o.status, (o.problems or [o.message])[0][:100]) for o in bad)
    if kinds:
        print("\nProblems (target, outcome, first problem): count")
        for (target, status, first), n in kinds.most_common(30):
            print(f"  {target}, {status}, {first!r}: {n}")
        for o in bad[:5]:
            print(f"\n--- {o.target} {o.status} after {o.mutation}\n{o.message}\n{o.problems}")
    bags = _bad_bags(work, seeds)
    print("\n| bad bag | must give | gave |\n|---|---|---|")
    for name, expect, gave in bags:
        print(f"| {name} | {expect} | {gave} |")
    mutations = Counter(o.mutation.split(":")[0] for o in outcomes)
    print("\nmutations:", ", ".join(f"{k} {v}" for k, v in sorted(mutations.items())))
    if args.out:
        Path(args.out).write_text(
            json.dumps(
                {
                    "cases": args.cases,
                    "seed": args.seed,
                    "seeds": label,
                    "wall_s": wall_s,
                    "table": rows,
                    "bad_bags": bags,
                    "problems": [o.__dict__ for o in bad],
                },
                indent=1,
            )
        )


def _bad_bags(work: Path, seeds: dict) -> list[tuple[str, str, str]]:
    """Each named bad bag read: (name, what it must give, what it gave in one line)."""
    import warnings

    from sonarslam.datasets.errors import DataError
    from sonarslam.datasets.rosbag import open_bag

    out = []
    for case in bad_bags(work / "bad_bags", seeds["bag_ros1"]):
        expect = case.expect + (f" ({case.count})" if case.count else "")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                d = open_bag(case.path, topics_file=case.topics)
                counts = {k: v for k, v in d.report.counts.items() if v and k == case.count}
                gave = f"read, {len(caught)} warning(s), {counts or 'no count'}"
            except DataError as exc:
                gave = f"DataError: {exc}"
            except Exception as exc:  # a bug: what the fuzz suite exists to find
                gave = f"FOREIGN {type(exc).__name__}: {exc}"
        out.append((case.name, expect, gave[:200]))
    return out


if __name__ == "__main__":
    main()
