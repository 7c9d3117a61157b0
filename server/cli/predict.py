"""`robocal predict`: SMR positions a model predicts for poses."""

from __future__ import annotations


def cmd_predict(args) -> None:
    import sys

    from robocal.server.calibration import workflow
    from robocal.server.formats.model_json import approach_unknown, extrapolated

    from ..formats.campaign_csv import read_poses, write_predictions

    model = workflow.read_model(args.model)
    pose_ids, q, time_s, temp_c, prev_q = read_poses(args.poses, model.robot)
    try:
        xyz = workflow.model_predict(model, q, time_s, temp_c, prev_q, pose_ids)
    except workflow.DataError as e:
        raise workflow.DataError(f"{args.poses}: {e}") from None
    write_predictions(args.out, pose_ids, list(model.targets), xyz)
    for why in (
        extrapolated(model, q, pose_ids),
        approach_unknown(model, q, time_s, prev_q, pose_ids),
    ):
        if why:
            print(f"robocal: warning: {args.poses}: {why}", file=sys.stderr)
    # plain print, not rich's console: rich's import would be a fifth of predict's start
    print(f"predicted {len(pose_ids)} poses x {len(model.targets)} targets to {args.out}")


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    pr = sub.add_parser("predict", help="SMR positions a model predicts for poses")
    pr.add_argument("model", help="model.json (robocal calibrate)")
    pr.add_argument("poses", help="poses.csv: pose, q1..qN [, time_s, temp_c] (deg)")
    pr.add_argument("--out", default="pred.csv", help="predictions to write (default pred.csv)")
    pr.set_defaults(func=cmd_predict)
