#!/usr/bin/env bash
# Checks that docker/Dockerfile's build stage copies everything the build reads, without building
# the image: the stage's COPY lines are replayed into a temporary folder (WORKDIR and absolute
# destinations honoured), the project is configured there with the stage's SPECBAKE_CMAKE_ARGS,
# and `make -n -k all` (a dry run: nothing is compiled) must find every input of every target the
# stage builds ("No rule to make target ..." names a missing one) and run exactly the commands a
# dry run of the whole repository runs (which catches a globbed folder — kernels/, data/ — that
# is missing: a glob finds nothing rather than failing). Exits 1 naming what is missing.
# Headers are not listed to make (the compiler finds them); they come with src/ and kernels/.
#
#   tests/docker/build_inputs_test.sh REPO_ROOT [--drop SRC]
# --drop SRC replays the stage without its COPY of SRC: the check's own test (it must fail).
set -euo pipefail
root=$(cd "$1" && pwd)
dockerfile=$root/docker/Dockerfile
drop=""
if [ "${2:-}" = --drop ]; then drop=${3:?--drop needs a source path}; fi
stage=build

say() { echo "build-inputs: $*"; }
fail() { echo "build-inputs: FAIL: $*" >&2; exit 1; }

tmp=$(mktemp -d "${TMPDIR:-/tmp}/specbake-build-inputs.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
fs=$tmp/fs # the stage's file system

# The stage's lines: from `FROM ... AS build` to the next FROM, continuation lines joined.
lines=$(sed -e ':a' -e '/\\$/{N;s/\\\n//;ba' -e '}' "$dockerfile" |
        awk -v s="$stage" 'toupper($1) == "FROM" { in_stage = (tolower($NF) == s && toupper($(NF-1)) == "AS"); next }
                           in_stage')
[ -n "$lines" ] || fail "no stage 'AS $stage' in $dockerfile"

workdir=/
copies=0
while read -r instr rest; do
  case "${instr^^}" in
    WORKDIR)
      case "$rest" in /*) workdir=$rest ;; *) workdir=$workdir/$rest ;; esac ;;
    COPY | ADD)
      read -ra args <<<"$rest"
      case "${args[0]}" in --from=*) continue ;; --*) args=("${args[@]:1}") ;; esac
      ((${#args[@]} >= 2)) || fail "cannot read '$instr $rest'"
      dest=${args[-1]}
      case "$dest" in /*) ;; *) dest=$workdir/$dest ;; esac
      srcs=("${args[@]:0:${#args[@]}-1}")
      if [ "${srcs[*]}" = "$drop" ]; then say "leaving out '$instr $rest'"; dropped=1; continue; fi
      for src in "${srcs[@]}"; do
        [ -e "$root/$src" ] || fail "$dockerfile: '$instr $rest': no $src in the build context"
        if ((${#srcs[@]} > 1)) || [[ $dest == */ ]]; then
          mkdir -p "$fs$dest" && cp -a "$root/$src" "$fs$dest/"
        elif [ -d "$root/$src" ]; then
          mkdir -p "$fs$dest" && cp -a "$root/$src/." "$fs$dest/"
        else
          mkdir -p "$(dirname "$fs$dest")" && cp -a "$root/$src" "$fs$dest"
        fi
      done
      copies=$((copies + 1)) ;;
  esac
done <<<"$lines"
((copies > 0)) || fail "the $stage stage copies nothing"
[ -z "$drop" ] || [ -n "${dropped:-}" ] || fail "the $stage stage has no COPY of $drop to leave out"

# The configure arguments the stage passes to scripts/setup.sh.
cmake_args=$(grep -oE 'SPECBAKE_CMAKE_ARGS="[^"]*"' <<<"$lines" | head -n1 | sed -E 's/^[^"]*"(.*)"$/\1/') ||
  fail "no SPECBAKE_CMAKE_ARGS=\"...\" in the $stage stage"
say "$copies COPY lines into $workdir; configuring with $cmake_args"

src=$fs$workdir
# Configures SOURCE into BUILD as the stage does, and dry-runs every target it builds (`make -n`:
# nothing is compiled), printing make's output with both folders replaced by placeholders.
dry_run() {
  local source=$1 build=$2
  # shellcheck disable=SC2086 # the stage's arguments, split as the shell in the image splits them
  cmake -S "$source" -B "$build" -G "Unix Makefiles" -DCMAKE_BUILD_TYPE=Release $cmake_args \
    >"$build.configure.log" 2>&1 || { cat "$build.configure.log" >&2; return 1; }
  # -k: go on past a missing file to report every one.
  make -C "$build" -n -k all 2>&1 | sed -e "s|$build|<build>|g" -e "s|$source|<source>|g" || true
}
dry_run "$src" "$tmp/build" >"$tmp/make.log" || fail "configure from the $stage stage's files failed"

# A dry run names a missing file as "No rule to make target '/abs/path'"; it also says so of the
# libraries another target would have built (relative names in the build folder), which a dry run
# never makes: those are not inputs.
missing=$(sed -nE "s/.*No rule to make target '<source>([^']*)'.*/\1/p" "$tmp/make.log" | sort -u)
if [ -n "$missing" ]; then
  echo "build-inputs: files the build reads that the $stage stage does not copy:" >&2
  sed 's/^/  /' <<<"$missing" >&2
  fail "add them to the $stage stage's COPY lines in $dockerfile"
fi
# The dry run reached the binary's own compile (not a configure that dropped the target).
grep -q 'cli/main\.cpp' "$tmp/make.log" || { cat "$tmp/make.log" >&2; fail "the dry run does not compile src/cli/main.cpp"; }

# Files found by a glob (kernels, data, sources) are no rule's input when absent: the build from
# the stage's files must run exactly the commands a build of the whole repository runs.
dry_run "$root" "$tmp/ref-build" >"$tmp/ref-make.log" || fail "configure of $root failed"
# One word a line (lists such as the embedded files' split on ';'), so that the diff names files.
words() { tr ' ;=' '\n\n\n' <"$1"; }
if ! diff -u <(words "$tmp/ref-make.log") <(words "$tmp/make.log") >"$tmp/diff"; then
  grep -E '^[-+][^-+]' "$tmp/diff" | sort -u | head -n 40 >&2
  fail "the build from the $stage stage's files differs from a build of the repository (- repository, + stage): add the missing files to its COPY lines"
fi
say "PASS: every input of the build is in the $stage stage"
