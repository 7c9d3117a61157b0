"""Planning jobs: a campaign's planning (D-optimal choice, long tour) off the request path; such a
job has no campaign until it made one.

Revision ID: 0004
Revises: 0003
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0004"
down_revision = "0003"
branch_labels = None
depends_on = None

OLD = ("calibration", "diagnosis")
# server/store/models.py JOB_KINDS as of this revision (a migration is frozen: no import).
NEW = ("calibration", "diagnosis", "planning")


def _check(kinds) -> str:
    return f"kind IN ({', '.join(repr(k) for k in kinds)})"


def upgrade() -> None:
    # SQLite cannot alter a CHECK or a NOT NULL: batch mode copies the table with the new ones.
    with op.batch_alter_table("job") as batch:
        batch.drop_constraint(op.f("ck_job_kind"), type_="check")
        batch.create_check_constraint(op.f("ck_job_kind"), _check(NEW))
        batch.alter_column("campaign_id", existing_type=sa.Integer(), nullable=True)


def downgrade() -> None:
    # The old vocabulary has no planning jobs; they only ever made campaigns, which stay.
    op.execute("DELETE FROM job WHERE kind = 'planning'")
    with op.batch_alter_table("job") as batch:
        batch.alter_column("campaign_id", existing_type=sa.Integer(), nullable=False)
        batch.drop_constraint(op.f("ck_job_kind"), type_="check")
        batch.create_check_constraint(op.f("ck_job_kind"), _check(OLD))
