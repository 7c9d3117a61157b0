"""A calibration job may name a held-out campaign: readings of the same cell it does not fit on,
which give the model's validation figure and the held-out poses of its recording.

Revision ID: 0006
Revises: 0005
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0006"
down_revision = "0005"
branch_labels = None
depends_on = None

ID = sa.BigInteger().with_variant(sa.Integer(), "sqlite")  # as 0005 made every id


def upgrade() -> None:
    # SQLite adds a foreign key only by copying the table: batch mode does that.
    with op.batch_alter_table("job") as batch:
        batch.add_column(sa.Column("holdout_campaign_id", ID, nullable=True))
        batch.create_foreign_key(
            op.f("fk_job_holdout_campaign_id_campaign"),
            "campaign",
            ["holdout_campaign_id"],
            ["id"],
            ondelete="SET NULL",
        )


def downgrade() -> None:
    with op.batch_alter_table("job") as batch:
        batch.drop_constraint(op.f("fk_job_holdout_campaign_id_campaign"), type_="foreignkey")
        batch.drop_column("holdout_campaign_id")
