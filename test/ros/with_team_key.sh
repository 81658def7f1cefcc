#!/bin/bash
# Launch prefix of team_hostile_key.test: makes the team key the station and the test share (a
# file readable only by its owner, at the path given first), then runs the rest of the command line.
set -euo pipefail
key="$1"
shift
(umask 077 && openssl rand -hex 32 >"$key")
exec "$@"
