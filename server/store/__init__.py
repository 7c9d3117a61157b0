"""The campaign store: SQLite through SQLAlchemy, schema by Alembic, each reading committed."""

from .access import (CampaignInfo, JobInfo, PoseInfo, ReadingInfo, campaign_measurements,
                     create_campaign, create_job, discard_unfinished_pose, export_csv, export_lines,
                     fail_unfinished_jobs, get_campaign, get_job, import_csv, list_campaigns,
                     list_jobs, update_job, next_unmeasured_pose, planned_poses, pose_readings,
                     readings_page, record_missing, record_pose_outcome, record_reading,
                     set_status,
                     LeaseHeld, take_lease, renew_lease, release_lease)
from .db import Database, open_database
from .errors import Conflict, NotFound, StoreError

__all__ = ["JobInfo", "create_job", "fail_unfinished_jobs", "get_job", "list_jobs", "update_job",
           "CampaignInfo", "Conflict", "Database", "NotFound", "PoseInfo", "ReadingInfo",
           "StoreError", "campaign_measurements", "create_campaign", "discard_unfinished_pose",
           "export_csv", "export_lines", "get_campaign", "import_csv", "list_campaigns", "next_unmeasured_pose",
           "open_database", "planned_poses", "pose_readings", "readings_page", "record_missing",
           "record_pose_outcome", "record_reading", "set_status", "LeaseHeld", "take_lease",
           "renew_lease", "release_lease"]
