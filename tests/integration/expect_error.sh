#!/usr/bin/env bash
# usage: expect_error.sh EXIT_CODE REGEX -- COMMAND ARGS...
# Passes when COMMAND exits with EXIT_CODE (not a crash) and its stderr matches REGEX on a
# single line, i.e. bad input gave one clear message instead of a crash or a stack dump.
set -u
expected_code=$1; pattern=$2; shift 3
stderr_file=$(mktemp); trap 'rm -f "$stderr_file"' EXIT
"$@" >/dev/null 2>"$stderr_file"; code=$?
if [ "$code" -ne "$expected_code" ]; then
  echo "expected exit code $expected_code, got $code"; cat "$stderr_file"; exit 1
fi
if ! grep -Eq -- "$pattern" "$stderr_file"; then
  echo "stderr does not match /$pattern/:"; cat "$stderr_file"; exit 1
fi
lines=$(wc -l < "$stderr_file")
if [ "$lines" -ne 1 ]; then
  echo "expected one line on stderr, got $lines:"; cat "$stderr_file"; exit 1
fi
echo "ok: exit $code, $(cat "$stderr_file")"
