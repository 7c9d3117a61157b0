"""The campaign's status is the engine's life-cycle state (9 states); a lease on a running one.

Revision ID: 0003
Revises: 0002
Create Date: 2026-12-01
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0003"
down_revision = "0002"
branch_labels = None
depends_on = None

OLD = ("planned", "running", "paused", "done", "aborted", "failed")
# drivers/lifecycle.py STATES as of this revision (a migration is frozen: no import).
NEW = (
    "planned",
    "running",
    "pausing",
    "paused",
    "stopping",
    "aborted",
    "estopped",
    "failed",
    "done",
)


def _check(states) -> str:
    return f"status IN ({', '.join(repr(s) for s in states)})"


def upgrade() -> None:
    # SQLite cannot alter a CHECK: batch mode copies the table with the new one.
    with op.batch_alter_table("campaign") as batch:
        batch.drop_constraint(op.f("ck_campaign_status"), type_="check")
        batch.create_check_constraint(op.f("ck_campaign_status"), _check(NEW))
        batch.add_column(sa.Column("lease_owner", sa.Text(), nullable=True))
        batch.add_column(sa.Column("lease_expires_at", sa.DateTime(), nullable=True))


def downgrade() -> None:
    # The old vocabulary has no in-between states: a campaign caught in one becomes failed
    # (resumable there); an e-stopped one paused, where a reset would have left it.
    op.execute("UPDATE campaign SET status = 'failed' WHERE status IN ('pausing', 'stopping')")
    op.execute("UPDATE campaign SET status = 'paused' WHERE status = 'estopped'")
    with op.batch_alter_table("campaign") as batch:
        batch.drop_column("lease_expires_at")
        batch.drop_column("lease_owner")
        batch.drop_constraint(op.f("ck_campaign_status"), type_="check")
        batch.create_check_constraint(op.f("ck_campaign_status"), _check(OLD))
