"""A pose may keep the joints the arm came from (an imported file's `prev_q`, degrees): the
direction of each joint's last motion (backlash) survives a file split or reordered.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0008"
down_revision = "0007"
branch_labels = None
depends_on = None


def upgrade() -> None:
    with op.batch_alter_table("pose_outcome") as batch:
        batch.add_column(sa.Column("prev_deg", sa.JSON(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("pose_outcome") as batch:
        batch.drop_column("prev_deg")
