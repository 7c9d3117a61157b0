"""The initial store: campaign, planned_pose, reading, pose_outcome.

Revision ID: 0001
Revises:
Create Date: 2025-11-22
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

# Constraint names are final (op.f): the models' naming convention must not prefix them again.

revision = "0001"
down_revision = None
branch_labels = None
depends_on = None


def _pose_fk(table: str) -> sa.ForeignKeyConstraint:
    return sa.ForeignKeyConstraint(
        ["campaign_id", "pose_index"],
        ["planned_pose.campaign_id", "planned_pose.pose_index"],
        name=op.f(f"fk_{table}_campaign_id_pose_index_planned_pose"),
        ondelete="CASCADE",
    )


def upgrade() -> None:
    op.create_table(
        "campaign",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("name", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("cell_json", sa.Text(), nullable=False),
        sa.Column("settings_json", sa.Text(), nullable=False),
        sa.Column("simulated", sa.Boolean(), nullable=False),
        sa.Column("notes", sa.Text(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_campaign")),
        sa.CheckConstraint(
            "status IN ('planned', 'running', 'paused', 'done', 'aborted', 'failed')",
            name=op.f("ck_campaign_status"),
        ),
    )
    op.create_table(
        "planned_pose",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("pose_index", sa.Integer(), nullable=False),
        sa.Column("label", sa.Text(), nullable=False),
        sa.Column("joints_deg", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_planned_pose")),
        sa.ForeignKeyConstraint(
            ["campaign_id"],
            ["campaign.id"],
            ondelete="CASCADE",
            name=op.f("fk_planned_pose_campaign_id_campaign"),
        ),
        sa.UniqueConstraint(
            "campaign_id", "pose_index", name=op.f("uq_planned_pose_campaign_id_pose_index")
        ),
        sa.UniqueConstraint("campaign_id", "label", name=op.f("uq_planned_pose_campaign_id_label")),
        sa.CheckConstraint("pose_index >= 0", name=op.f("ck_planned_pose_pose_index")),
    )
    op.create_table(
        "reading",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("pose_index", sa.Integer(), nullable=False),
        sa.Column("target", sa.Text(), nullable=False),
        sa.Column("status", sa.String(16), nullable=False),
        sa.Column("x", sa.Float(), nullable=True),
        sa.Column("y", sa.Float(), nullable=True),
        sa.Column("z", sa.Float(), nullable=True),
        sa.Column("std_x", sa.Float(), nullable=True),
        sa.Column("std_y", sa.Float(), nullable=True),
        sa.Column("std_z", sa.Float(), nullable=True),
        sa.Column("samples", sa.Integer(), nullable=True),
        sa.Column("time_s", sa.Float(), nullable=True),
        sa.Column("temp_c", sa.Float(), nullable=True),
        sa.Column("pressure_hpa", sa.Float(), nullable=True),
        sa.Column("humidity_pct", sa.Float(), nullable=True),
        sa.Column("detail", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_reading")),
        _pose_fk("reading"),
        sa.UniqueConstraint(
            "campaign_id",
            "pose_index",
            "target",
            name=op.f("uq_reading_campaign_id_pose_index_target"),
        ),
        sa.CheckConstraint("status IN ('ok', 'missing')", name=op.f("ck_reading_status")),
        sa.CheckConstraint(
            "(status = 'ok' AND x IS NOT NULL AND y IS NOT NULL AND z IS NOT NULL) OR "
            "(status = 'missing' AND x IS NULL AND y IS NULL AND z IS NULL)",
            name=op.f("ck_reading_xyz_present"),
        ),
        sa.CheckConstraint("samples IS NULL OR samples >= 1", name=op.f("ck_reading_samples")),
    )
    op.create_table(
        "pose_outcome",
        sa.Column("id", sa.Integer(), nullable=False),
        sa.Column("campaign_id", sa.Integer(), nullable=False),
        sa.Column("pose_index", sa.Integer(), nullable=False),
        sa.Column("state", sa.String(16), nullable=False),
        sa.Column("reached_deg", sa.JSON(), nullable=True),
        sa.Column("detail", sa.Text(), nullable=False),
        sa.Column("created_at", sa.DateTime(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_pose_outcome")),
        _pose_fk("pose_outcome"),
        sa.UniqueConstraint(
            "campaign_id", "pose_index", name=op.f("uq_pose_outcome_campaign_id_pose_index")
        ),
        sa.CheckConstraint(
            "state IN ('measured', 'missing-target', 'skipped')", name=op.f("ck_pose_outcome_state")
        ),
    )


def downgrade() -> None:
    op.drop_table("pose_outcome")
    op.drop_table("reading")
    op.drop_table("planned_pose")
    op.drop_table("campaign")
