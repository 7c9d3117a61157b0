"""The campaign store: SQLite or PostgreSQL through SQLAlchemy, schema by Alembic."""

from .campaigns import (
    CampaignInfo,
    create_campaign,
    extend_plan,
    get_campaign,
    list_campaigns,
    set_status,
    update_settings,
)
from .db import Database, open_database
from .errors import Conflict, DatabaseGone, NotFound, StoreError, StoreUnavailable
from .exchange import (
    campaign_measurements,
    export_csv,
    export_lines,
    import_csv,
)
from .jobs import (
    JobInfo,
    create_job,
    fail_unfinished_jobs,
    get_job,
    list_jobs,
    update_job,
)
from .leases import (
    LeaseHeld,
    release_lease,
    renew_lease,
    take_lease,
)
from .readings import (
    PoseInfo,
    ReadingInfo,
    discard_unfinished_pose,
    next_unmeasured_pose,
    planned_poses,
    pose_readings,
    readings_of_poses,
    readings_page,
    record_missing,
    record_pose_outcome,
    record_reading,
)

__all__ = [
    "JobInfo",
    "create_job",
    "fail_unfinished_jobs",
    "get_job",
    "list_jobs",
    "update_job",
    "CampaignInfo",
    "Conflict",
    "Database",
    "DatabaseGone",
    "NotFound",
    "PoseInfo",
    "ReadingInfo",
    "StoreError",
    "StoreUnavailable",
    "campaign_measurements",
    "create_campaign",
    "extend_plan",
    "discard_unfinished_pose",
    "export_csv",
    "export_lines",
    "get_campaign",
    "import_csv",
    "list_campaigns",
    "update_settings",
    "next_unmeasured_pose",
    "open_database",
    "planned_poses",
    "pose_readings",
    "readings_of_poses",
    "readings_page",
    "record_missing",
    "record_pose_outcome",
    "record_reading",
    "set_status",
    "LeaseHeld",
    "take_lease",
    "renew_lease",
    "release_lease",
]
