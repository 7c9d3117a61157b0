#!/usr/bin/env bash
# Run a command with a throw-away PostgreSQL server on 127.0.0.1, its URL in ROBOCAL_TEST_POSTGRES.
#   tests/postgres.sh uv run pytest -q -n 2
# Installs Debian's postgresql if absent. The server lives in a temp folder and is stopped (and the
# folder removed) when the command ends. With ROBOCAL_TEST_POSTGRES already set, it just runs it.
set -euo pipefail
if [ -n "${ROBOCAL_TEST_POSTGRES:-}" ]; then
  exec "$@"
fi
sudo=$([ "$(id -u)" = 0 ] || echo sudo) # root in containers, sudo on a CI runner
bindir() { ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1; }
if [ -z "$(bindir)" ]; then
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq postgresql
fi
bin=$(bindir)
# PostgreSQL refuses to run as root: then the server runs as the package's `postgres` user.
as_owner=()
if [ "$(id -u)" = 0 ]; then
  as_owner=(runuser -u postgres --)
fi
dir=$(mktemp -d /tmp/robocal-pg.XXXXXX)
chmod 755 "$dir"
[ "$(id -u)" = 0 ] && chown postgres: "$dir"
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
stop() {
  "${as_owner[@]}" "$bin/pg_ctl" -D "$dir/data" -m immediate stop >/dev/null 2>&1 || true
  rm -rf "$dir"
}
trap stop EXIT
# Trust on loopback: a test server that only this machine can reach and that dies with the run.
"${as_owner[@]}" "$bin/initdb" -D "$dir/data" -U robocal --auth=trust -E UTF8 >"$dir/initdb.log"
# fsync off: the data is thrown away at the end, durability is not under test here.
"${as_owner[@]}" "$bin/pg_ctl" -D "$dir/data" -l "$dir/server.log" -w \
  -o "-h 127.0.0.1 -p $port -k $dir -F -c max_connections=200" start >/dev/null
export ROBOCAL_TEST_POSTGRES="postgresql+psycopg://robocal@127.0.0.1:$port/postgres"
echo "PostgreSQL $("$bin/postgres" -V | awk '{print $3}') on 127.0.0.1:$port"
"$@"
