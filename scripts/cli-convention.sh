# Sourced by HapCo's bash scripts: their options follow the convention of the C++ tools
# (docs/cli.md: units in the name, --output for what the run writes, --build for the build
# folder), and old spellings keep working with the note the tools print.
#
#   hapco_deprecated TOOL OLD CURRENT    # on stderr: "TOOL: note: OLD is deprecated, use CURRENT (same meaning)"
hapco_deprecated() { printf '%s: note: %s is deprecated, use %s (same meaning)\n' "$1" "$2" "$3" >&2; }

#   hapco_need_value TOOL "$@"           # in an option loop: exit 1 unless the option ($1) has a value
hapco_need_value() {
  local tool=$1; shift
  if [ $# -lt 2 ] || [ -z "$2" ]; then
    printf '%s: %s needs a value (see --help)\n' "$tool" "$1" >&2; exit 1
  fi
}
#   hapco_check_number TOOL FLAG VALUE   # exit 1 unless VALUE is a positive decimal number
hapco_check_number() {
  [[ "$3" =~ ^[0-9]+([.][0-9]*)?([eE][-+]?[0-9]+)?$ ]] && awk -v v="$3" 'BEGIN{exit !(v > 0)}' ||
    { printf '%s: %s expects a positive number, got '\''%s'\''\n' "$1" "$2" "$3" >&2; exit 1; }
}
#   hapco_check_integers TOOL FLAG "LIST" # exit 1 unless LIST is one or more integers >= 0
hapco_check_integers() {
  local item n=0
  for item in $3; do
    [[ "$item" =~ ^[0-9]+$ ]] || { printf '%s: %s expects integers, got '\''%s'\''\n' "$1" "$2" "$item" >&2; exit 1; }
    n=$((n + 1))
  done
  [ "$n" -gt 0 ] || { printf '%s: %s is empty\n' "$1" "$2" >&2; exit 1; }
}
#   hapco_runs_folder TOOL DIR [default] # DIR for per-run files: made if missing, marked as the
#                                        # scripts'; a --runs-dir with other files is refused (it was
#                                        # emptied with rm -rf: a user's notes went with it); the
#                                        # default folder, in the build folder, is the scripts' own
hapco_runs_folder() {
  local tool=$1 dir=$2 given=${3:-given}
  if [ "$given" = given ] && [ -d "$dir" ] && [ -n "$(ls -A "$dir" 2>/dev/null)" ] && [ ! -e "$dir/.hapco-runs" ]; then
    printf '%s: --runs-dir %s holds files of its own: give an empty or new folder (the runs replace its contents)\n' \
      "$tool" "$dir" >&2
    exit 1
  fi
  mkdir -p "$dir" && : >"$dir/.hapco-runs"
}
#   hapco_keep_data TOOL DATA            # move DATA.tmp over DATA only if it holds a data row; else
#                                        # leave DATA as it was, say so and return 1
hapco_keep_data() {
  if [ -f "$2.tmp" ] && [ "$(wc -l <"$2.tmp")" -gt 1 ]; then
    mv "$2.tmp" "$2"
  else
    rm -f "$2.tmp"
    printf '%s: no run finished: %s left as it was\n' "$1" "$2" >&2
    return 1
  fi
}
