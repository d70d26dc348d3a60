#!/bin/sh
# The `mc` verbs docker/compose.distributed.yaml uses, for the stand-in image (minio.Dockerfile):
#   mc ready local | mc alias set NAME URL USER SECRET | mc mb [--ignore-existing] NAME/BUCKET
# Aliases are kept in ~/.mc-standin (NAME URL per line).
set -eu
aliases="$HOME/.mc-standin"
# An alias set last wins; `local` is http://127.0.0.1:9000 until set, as in mc's own config.
url_of() {
  url=$(awk -v n="$1" '$1 == n { print $2 }' "$aliases" 2>/dev/null | tail -n 1)
  [ -z "$url" ] && [ "$1" = local ] && url=http://127.0.0.1:9000
  echo "$url"
}
case "${1:-}" in
ready) curl -fsS -o /dev/null "$(url_of "$2")/" ;;
alias)
  [ "${2:-}" = set ] || { echo "mc stand-in: only 'alias set'" >&2; exit 2; }
  echo "$3 $4" >>"$aliases"
  echo "Added \`$3\` successfully."
  ;;
mb)
  shift
  ignore=0
  [ "$1" = --ignore-existing ] && { ignore=1; shift; }
  name=${1%%/*} bucket=${1#*/}
  url=$(url_of "$name")
  [ -n "$url" ] || { echo "mc stand-in: no alias $name" >&2; exit 1; }
  code=$(curl -sS -o /dev/null -w '%{http_code}' -X PUT "$url/$bucket")
  case "$code" in
  200) echo "Bucket created successfully \`$1\`." ;;
  409) [ $ignore = 1 ] || { echo "mc stand-in: bucket $bucket exists" >&2; exit 1; } ;;
  *) echo "mc stand-in: creating $bucket answered HTTP $code" >&2; exit 1 ;;
  esac
  ;;
*) echo "mc stand-in: unsupported verb ${1:-}" >&2; exit 2 ;;
esac
