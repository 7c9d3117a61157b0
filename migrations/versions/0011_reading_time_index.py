"""A campaign's latest readings are found by time without reading all of them: the air
temperature each compensated pose of a thermal verification is solved at (store.latest_air).

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-06
"""

from __future__ import annotations

from alembic import op

revision = "0011"
down_revision = "0010"
branch_labels = None
depends_on = None


def upgrade() -> None:
    # id after time: the latest of readings with the same time is the one stored last
    op.create_index(
        "ix_reading_campaign_time", "reading", ["campaign_id", "time_s", "id"], unique=False
    )


def downgrade() -> None:
    op.drop_index("ix_reading_campaign_time", table_name="reading")
