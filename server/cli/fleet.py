"""`robocal fleet`: the arms of one robot model against the fleet's spread, and their jumps."""

from __future__ import annotations


def cmd_fleet(args) -> int:
    from robocal.server import store
    from robocal.server.cli import tables
    from robocal.server.cli.tables import console

    from ..fleet import fleet_models, fleet_view
    from ..formats.model_json import write_json_atomic

    with store.open_database(args.db) as db:
        if args.robot_model is None:
            for m in fleet_models(db):
                console.print(f"{m.robot_model}: {m.arms} arms, {m.calibrations} calibrations")
            return 0
        view = fleet_view(db, args.robot_model)
    if args.out:
        write_json_atomic(args.out, view.model_dump(mode="json"))
    console.print(tables.fleet(view))
    for a in view.arms:
        for p in a.parameters:
            if p.flagged:
                console.print(
                    f"{a.arm}: {p.parameter} {p.value:.6g} is {p.z:+.1f} spreads from the fleet's "
                    f"median (limit {_limit(view, p.parameter)})"
                )
            if p.jump_flagged:
                console.print(
                    f"{a.arm}: {p.parameter} moved {p.jump:+.4g} since job {a.previous_job_id} "
                    f"({p.jump_z:+.1f} times its uncertainty, limit {view.jump_limit:.1f})"
                )
    return 0


def _limit(view, name: str) -> str:
    limit = next(p.limit for p in view.parameters if p.parameter == name)
    return "-" if limit is None else f"{limit:.1f}"


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    fl = sub.add_parser(
        "fleet",
        help="the calibrated arms of one robot model: which is off the fleet, which jumped",
    )
    fl.add_argument(
        "robot_model",
        nargs="?",
        help="the robot model, as the cells name it (e.g. irb2600); none: list the models",
    )
    fl.add_argument("--db", default="robocal.db", help="the database (file or URL)")
    fl.add_argument("--out", help="also write the fleet view as JSON here")
    fl.set_defaults(func=cmd_fleet)
