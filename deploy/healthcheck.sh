#!/bin/bash
# Container health check of `kitchen-r serve`: GET /healthz on the HTTP port, expect
# {"status":"ok"}. The image has no curl; bash's /dev/tcp is enough for one request.
# The port comes from KITCHEN_R_HTTP (default 0.0.0.0:8080), or the first argument.
set -euo pipefail
port="${1:-${KITCHEN_R_HTTP##*:}}"
port="${port:-8080}"
exec 3<>"/dev/tcp/127.0.0.1/${port}"
printf 'GET /healthz HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n' >&3
response="$(timeout 4 cat <&3)"
case "$response" in
  "HTTP/1.1 200"*'"status":"ok"'*) exit 0 ;;
  *) echo "unhealthy: ${response%%$'\r'*}" >&2; exit 1 ;;
esac
