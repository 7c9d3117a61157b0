"""64-bit ids on PostgreSQL, as SQLite's already are: the API takes ids up to 2**63 - 1, and a
fleet's readings outgrow 32 bits sooner than one cell's. Nothing changes on SQLite.

Revision ID: 0005
Revises: 0004
Create Date: 2026-12-02
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0005"
down_revision = "0004"
branch_labels = None
depends_on = None

# table: its columns that hold an id (its own, then the campaign it belongs to).
ID_COLUMNS = {
    "campaign": ("id",),
    "planned_pose": ("id", "campaign_id"),
    "reading": ("id", "campaign_id"),
    "pose_outcome": ("id", "campaign_id"),
    "job": ("id", "campaign_id"),
}


def _retype(old, new, sequence_type: str) -> None:
    if op.get_bind().dialect.name != "postgresql":
        return
    for table, columns in ID_COLUMNS.items():
        for column in columns:
            op.alter_column(table, column, type_=new, existing_type=old)
        op.execute(f"ALTER SEQUENCE {table}_id_seq AS {sequence_type}")


def upgrade() -> None:
    _retype(sa.Integer(), sa.BigInteger(), "bigint")


def downgrade() -> None:
    _retype(sa.BigInteger(), sa.Integer(), "integer")
