"""A campaign may name the physical arm it measured (its serial number): the fleet view compares
the calibrations of the arms of one robot model and follows each arm's from one to the next.

Revision ID: 0010
Revises: 0009
Create Date: 2026-12-04
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0010"
down_revision = "0009"
branch_labels = None
depends_on = None


# Never the batch mode's copy and swap: dropping the old campaign table would cascade to every
# job, pose and reading of it (foreign keys are on). SQLite adds (and, since 3.35, drops) a
# plain column in place.


def upgrade() -> None:
    with op.batch_alter_table("campaign", recreate="never") as batch:
        batch.add_column(sa.Column("arm", sa.Text(), nullable=True))
    op.create_index(op.f("ix_campaign_arm"), "campaign", ["arm"], unique=False)


def downgrade() -> None:
    op.drop_index(op.f("ix_campaign_arm"), table_name="campaign")
    with op.batch_alter_table("campaign", recreate="never") as batch:
        batch.drop_column("arm")
