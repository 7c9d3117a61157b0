"""Quick checks of deployed models (`robocal check`): each check's figures, verdict and errors,
the history later checks of the same model are judged against.

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-03
"""

from __future__ import annotations

import sqlalchemy as sa
from alembic import op

revision = "0009"
down_revision = "0008"
branch_labels = None
depends_on = None


def upgrade() -> None:
    op.create_table(
        "model_check",
        sa.Column("id", sa.BigInteger().with_variant(sa.Integer(), "sqlite"), nullable=False),
        sa.Column("model_sha256", sa.String(64), nullable=False),
        sa.Column("checked_at", sa.DateTime(), nullable=False),
        sa.Column("source", sa.Text(), nullable=False),
        sa.Column("poses", sa.Integer(), nullable=False),
        sa.Column("rms_mm", sa.Float(), nullable=False),
        sa.Column("max_mm", sa.Float(), nullable=False),
        sa.Column("expected_rms_mm", sa.Float(), nullable=False),
        sa.Column("change_z", sa.Float(), nullable=False),
        sa.Column("cusum", sa.Float(), nullable=False),
        sa.Column("verdict", sa.String(16), nullable=False),
        sa.Column("reason", sa.Text(), nullable=False),
        sa.Column("errors", sa.JSON(), nullable=False),
        sa.PrimaryKeyConstraint("id", name=op.f("pk_model_check")),
        sa.CheckConstraint(
            "verdict IN ('ok', 'watch', 'recalibrate')", name=op.f("ck_model_check_verdict")
        ),
    )
    op.create_index(
        op.f("ix_model_check_model_sha256"), "model_check", ["model_sha256"], unique=False
    )


def downgrade() -> None:
    op.drop_index(op.f("ix_model_check_model_sha256"), table_name="model_check")
    op.drop_table("model_check")
