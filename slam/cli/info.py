"""``sonarslam info``: what a dataset holds, its settings and their sources."""

from __future__ import annotations

import argparse
import math

from datasets.source import open_dataset
from slam.cli.common import EPILOG, Subparsers, add_source
from slam.run.sources import dvl_quality


def add_parser(sub: Subparsers) -> None:
    p = sub.add_parser("info", help="what a dataset holds", epilog=EPILOG)
    add_source(p)
    p.set_defaults(func=command)


def command(args: argparse.Namespace) -> int:
    d = open_dataset(args.source)
    t0, t1 = d.nav_span_s
    print(f"{d.name}: {d.root}")
    print(f"  sonar beams {len(d.beams)} ({len(d.nav_beams())} inside the navigation span)")
    print(f"  DVL rows {d.dvl.t.size} ({int((~d.dvl.valid).sum())} without bottom lock)")
    print(f"  AHRS rows {d.attitude.t.size}; GPS fixes {0 if d.gps is None else d.gps.t.size}")
    faults = {k: v for k, v in d.report.counts.items() if v}
    gaps = ", ".join(
        f"{name} {g.count} (longest {g.longest_s:.1f} s)" for name, g in d.report.gaps.items()
    )
    print(f"  gates (datasets/gates.py): {faults or 'nothing dropped'}; gaps: {gaps or 'none'}")
    print(f"  navigation span {t1 - t0:.1f} s; head {d.config.sonar}")
    for name in ("sonar", "dvl", "ahrs"):
        m = getattr(d.config, f"{name}_mounting")
        print(
            f"  {name} mounting x={m.x_m} m y={m.y_m} m yaw={math.degrees(m.yaw_rad):.2f} deg ({m.source})"
        )
    b, c = (math.degrees(v) for v in d.config.ahrs_deviation_rad)
    print(
        f"  AHRS deviation B={b:.2f} C={c:.2f} deg (taken off: B sin(yaw) + C cos(yaw)); heading"
        f" between AHRS samples from the {d.config.yaw_rate_source}"
    )
    n, dq = d.config.noise, dvl_quality(d)
    print(
        f"  DVL scatter over {n.dvl_scatter_window_s or 60.0:g} s (m/s): "
        + ", ".join(f"p{p} {dq[f'dvl_scatter_p{p}_mps']:.3f}" for p in (10, 50, 90, 99))
    )
    if n.dvl_scatter_window_s > 0:
        first = dq["dvl_excess_from_s"]
        print(
            f"  DVL sigma {n.dvl_sigma_mps} m/s, plus the scatter's excess over"
            f" {n.dvl_nominal_scatter_mps} m/s: {dq['dvl_excess_s']:.0f} s of the run"
            + (f", first at {first:.0f} s" if first >= 0 else "")
        )
    else:
        print(f"  DVL sigma {n.dvl_sigma_mps} m/s (the scatter's excess is not added)")
    return 0
