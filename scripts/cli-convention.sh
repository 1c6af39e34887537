# Sourced by HapCo's bash scripts: their options follow the convention of the C++ tools
# (docs/cli.md: units in the name, --output for what the run writes, --build for the build
# folder), and old spellings keep working with the note the tools print.
#
#   hapco_deprecated TOOL OLD CURRENT    # on stderr: "TOOL: note: OLD is deprecated, use CURRENT (same meaning)"
hapco_deprecated() { printf '%s: note: %s is deprecated, use %s (same meaning)\n' "$1" "$2" "$3" >&2; }
