"""`robocal check`: a quick check of a deployed model over its history."""

from __future__ import annotations


def cmd_check(args) -> int:
    from .. import store
    from ..check import EXIT_RECALIBRATE, run_check
    from ..formats.model_json import write_json_atomic
    from ..tables import console

    with store.open_database(args.db) as db:
        res = run_check(args.model, args.check, db)
    if args.out:
        write_json_atomic(args.out, res.to_json())
    console.print(f"{res.verdict} (check {res.history} of this model): {res.reason}")
    return EXIT_RECALIBRATE if res.verdict == "recalibrate" else 0


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    ck = sub.add_parser(
        "check",
        help="quick check of a deployed model: ok, watch or recalibrate (exit 3), over its history",
    )
    ck.add_argument("model", help="model.json (robocal calibrate or diagnose)")
    ck.add_argument("check", help="check.csv: a meas.csv of the few poses measured every check")
    ck.add_argument(
        "--db", default="robocal.db", help="database of the checks' history (file or URL)"
    )
    ck.add_argument("--out", help="write check.json here")
    ck.set_defaults(func=cmd_check)
