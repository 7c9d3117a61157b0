"""`robocal bench`: benchmarks printing JSON."""

from __future__ import annotations

import json
from pathlib import Path

from .common import _nonnegative_int, _positive_int


def _effect_spec(text: str) -> str:
    """A hidden effect's spec as `simulate --effect` takes it, checked on the default cell's arm."""
    import argparse

    import numpy as np

    from robocal.drivers.cell import VirtualCell
    from robocal.drivers.effects import make_effect

    from ..formats.cell_json import default_cell

    cell = default_cell()
    try:
        make_effect(
            text, VirtualCell.random(cell.robot, cell.targets, seed=0), np.random.default_rng(0)
        )
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
    return text


def _real_campaigns() -> list[Path]:
    """The real campaigns beside a checkout (../shared/data/real), when they are there."""
    real = Path(__file__).resolve().parents[3] / "shared" / "data" / "real"
    return sorted(p for p in real.glob("*") if p.is_dir())


def cmd_bench(args) -> None:
    if args.what == "diagnose":
        from ..bench.diagnose import run_diagnose_bench

        result = run_diagnose_bench(
            quick=args.quick,
            effect_cases=args.cases,
            clean_cases=args.clean,
            sizes=args.poses,
            workers=args.workers,
            split_cases=args.split_cases,
            real=() if args.quick else _real_campaigns(),
        )
    elif args.what == "uncertainty":
        from ..bench.uncertainty import run_uncertainty_bench

        result = run_uncertainty_bench(seeds=args.seeds)
    elif args.what == "outliers":
        from ..bench.screen import run_screen_bench

        result = run_screen_bench()
    elif args.what == "service":
        from ..bench.service import run_service_bench

        result = run_service_bench()
    elif args.what == "startup":
        from ..bench.startup import run_startup_bench

        result = run_startup_bench(repeats=args.repeats)
    elif args.what == "compensate":
        from ..bench.compensate import run_compensate_bench

        result = run_compensate_bench()
    elif args.what == "air":
        from ..bench.air import run_air_bench

        result = run_air_bench(poses=max(args.poses))
    elif args.what == "verify":
        from ..bench.verify import run_verify_bench

        result = run_verify_bench()
    elif args.what == "acquire":
        from ..bench.acquire import run_acquire_bench

        result = run_acquire_bench(
            suite_seeds=args.seeds,
            suite_effects=tuple(args.suite_effect or ()),
            first_seed=args.first_seed,
        )
    elif args.what == "recording":
        from ..bench.recording import run_recording_bench

        result = run_recording_bench()
    elif args.what == "check":
        from ..bench.check import run_check_bench

        result = run_check_bench(
            clean=args.clean or 70, poses="random" if args.random_check_poses else "planned"
        )
    elif args.what == "scale":
        from ..bench.scale import run_calibrate_scale, run_diagnose_scale

        result = run_calibrate_scale(poses=args.scale_poses, repeats=args.repeats)
        result["diagnose"] = run_diagnose_scale()
    elif args.what == "validation":
        from ..bench import validation as bench_validation

        result = bench_validation.run(20, "minimax", _real_campaigns())
    else:
        from ..bench.solver import run_solver_bench

        result = run_solver_bench(
            sizes=args.sizes, reference=not args.no_reference, reference_max=args.reference_max
        )
    print(json.dumps(result, indent=2))


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    b = sub.add_parser("bench", help="benchmarks printing JSON")
    b.add_argument(
        "what",
        choices=(
            "solver",
            "diagnose",
            "acquire",
            "service",
            "outliers",
            "startup",
            "compensate",
            "verify",
            "air",
            "recording",
            "validation",
            "check",
            "scale",
            "uncertainty",
        ),
        help="what to time (validation: the deployment guard's flags on clean, effect, small and "
        "real campaigns; check: quick checks' false alarms and delays to a change; scale: `robocal calibrate` of a large campaign as a process, next to np.loadtxt of its file, "
        "then diagnose of 1,000 / 3,000 / 10,000 poses; uncertainty: the coverage of the "
        "position U of diagnosed and ls-sum models on independent positions; air: the latest "
        "air temperature looked up before each pose of a 1,000-pose run, or --poses N)",
    )
    b.add_argument(
        "--seeds",
        type=_nonnegative_int,
        default=20,
        help="acquire: seeds of each arm in the adaptive campaign's suite (default 20, 0: none); "
        "uncertainty: seeds of each arm (default 20)",
    )
    b.add_argument(
        "--first-seed",
        type=_nonnegative_int,
        default=0,
        help="acquire: the suite's first seed (default 0; others check on seeds not used before)",
    )
    b.add_argument(
        "--suite-effect",
        action="append",
        type=_effect_spec,
        metavar="SPEC",
        help="acquire: a hidden effect of the suite's arms, as `simulate --effect` takes it "
        "(repeatable), e.g. joint_periodic:2=0.002",
    )
    b.add_argument(
        "--repeats",
        type=_positive_int,
        default=7,
        help="startup, scale: runs of each command (median reported)",
    )
    b.add_argument(
        "--poses",
        type=_positive_int,
        nargs="+",
        default=[100, 1000],
        help="diagnose: sizes of the campaigns timed one at a time; air: the run's poses (the "
        "largest given, default 1,000)",
    )
    b.add_argument(
        "--scale-poses",
        type=_positive_int,
        default=50_000,
        help="scale: poses of the campaign calibrated (default 50000)",
    )
    b.add_argument(
        "--quick",
        action="store_true",
        help="diagnose: a short run (10 effect cases, 10 clean campaigns)",
    )
    b.add_argument(
        "--cases", type=_positive_int, help="diagnose: effect cases of the suite (default 60)"
    )
    b.add_argument(
        "--clean",
        type=_positive_int,
        help="diagnose: clean campaigns (default 200); check: clean checks an arm (default 70)",
    )
    b.add_argument(
        "--random-check-poses",
        action="store_true",
        help="check: random valid check poses rather than those `check --plan` picks",
    )
    b.add_argument(
        "--split-cases",
        type=_nonnegative_int,
        help="diagnose: cases of the configuration-split suite (default 45, quick 5; 0 skips it)",
    )
    b.add_argument(
        "--workers", type=_positive_int, default=2, help="diagnose: processes in the pool"
    )
    b.add_argument(
        "--sizes",
        type=_positive_int,
        nargs="+",
        default=[100, 1000, 10000],
        help="solver: pose counts timed (default 100 1000 10000)",
    )
    b.add_argument(
        "--no-reference",
        action="store_true",
        help="solver: skip the peers (scipy with analytic derivatives; finite differences up to "
        "1,000 poses)",
    )
    b.add_argument(
        "--reference-max",
        type=_positive_int,
        default=10000,
        help="solver: largest pose count for which to run the peers",
    )
    b.set_defaults(func=cmd_bench)
