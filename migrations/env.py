"""Alembic environment: the store's models as target, batch mode so SQLite tables can be altered."""

from __future__ import annotations

import os
from logging.config import fileConfig

from alembic import context

from robocal.server.store.db import make_engine
from robocal.server.store.models import Base

config = context.config
target_metadata = Base.metadata
if config.config_file_name is not None:  # the command line; open_database leaves logging alone
    fileConfig(config.config_file_name, disable_existing_loggers=False)


def _url():
    # In code: the URL given to alembic_config. On the command line: DATABASE_URL, as the server
    # reads it, else alembic.ini's sqlalchemy.url.
    return (
        config.attributes.get("url")
        or os.environ.get("DATABASE_URL")
        or config.get_main_option("sqlalchemy.url")
    )


def _configure(**kwargs) -> None:
    # SQLite cannot ALTER most things; batch mode rebuilds the table instead (copy and swap).
    context.configure(
        target_metadata=target_metadata, render_as_batch=True, compare_type=True, **kwargs
    )


def run_offline() -> None:
    """Print the SQL (`alembic upgrade head --sql`) instead of running it."""
    _configure(url=_url(), literal_binds=True)
    with context.begin_transaction():
        context.run_migrations()


def run_online() -> None:
    """Migrate on open_database's connection, or on a new engine for the command line."""
    connection = config.attributes.get("connection")
    if connection is not None:  # open_database passes its own, pragmas set, transaction open
        _configure(connection=connection)
        with context.begin_transaction():
            context.run_migrations()
        return
    engine = make_engine(_url())
    try:
        with engine.connect() as connection:
            _configure(connection=connection)
            with context.begin_transaction():
                context.run_migrations()
    finally:
        engine.dispose()


if context.is_offline_mode():
    run_offline()
else:
    run_online()
