#!/usr/bin/env bash
# usage: check_completion.sh SCRIPTS_DIR BIN_DIR
# Loads the completion functions every tool generates (scripts/bash-completion) and completes
# as a user would at the prompt: a flag prefix, a choice value, a file argument.
set -euo pipefail
scripts=$1; bin=$2
source <("$scripts/bash-completion" "$bin")
fail=0
complete_words() {  # complete_words FUNCTION WORD...  -> COMPREPLY for the last word
  local fn=$1; shift
  COMP_WORDS=("$@"); COMP_CWORD=$(( ${#COMP_WORDS[@]} - 1 )); COMPREPLY=()
  "$fn"
  echo "${COMPREPLY[*]:-}"
}
expect() {  # expect DESCRIPTION GOT WANTED
  if [ "$2" != "$3" ]; then echo "FAIL $1: got '$2', wanted '$3'"; fail=1; else echo "ok   $1: $2"; fi
}
for tool in "$bin"/hapco-*; do
  name=$(basename "$tool"); fn="_${name//-/_}"
  if ! declare -F "$fn" >/dev/null; then echo "FAIL $name: no completion function $fn"; fail=1; continue; fi
  expect "$name --vers" "$(complete_words "$fn" "$name" --vers)" "--version"
done
expect "hapco-sim --sol" "$(complete_words _hapco_sim hapco-sim --sol)" "--solver"
expect "hapco-sim --solver glo" "$(complete_words _hapco_sim hapco-sim --solver glo)" "global-uzawa-gs global-uzawa-jacobi"
expect "hapco-phantom --force" "$(complete_words _hapco_phantom hapco-phantom --force)" "--force-timeout-ms"
expect "hapco-phantom --mode h" "$(complete_words _hapco_phantom hapco-phantom --mode h)" "hand"
# A FILE value completes file names: this script's own folder holds it.
here=$(dirname "$0")
expect "hapco-sim --csv <file>" "$(cd "$here" && complete_words _hapco_sim hapco-sim --csv check_compl)" "check_completion.sh"
# A numeric value offers nothing (not file names).
expect "hapco-sim --steps <N>" "$(cd "$here" && complete_words _hapco_sim hapco-sim --steps "")" ""
exit $fail
