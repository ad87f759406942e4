#!/usr/bin/env bash
# End-to-end test of the container image: builds docker/Dockerfile, bakes the small jobs of every
# kind in tests/nightly/configs (dispersion, diffraction, an atmosphere with its path-traced scene
# check) inside it as a non-root user with the output folder mounted from a host temporary
# folder, then checks every bundle from the host with `build/specbake inspect` (built by
# scripts/setup.sh if missing). Exits non-zero on any failure. Too long for CI (the image build
# compiles specbake); CTest's Docker.BuildStageHasEveryInput guards the Dockerfile there.
#
#   scripts/docker-test.sh
#
# Environment:
#   SPECBAKE_ENGINE   docker | podman | docker-podman (the docker client through podman's socket).
#                     Default: docker when a Docker daemon answers, else podman, set up by
#                     ../shared/tools/container-env.sh (no daemon, no registry needed).
#   SPECBAKE_IMAGE    tag to build (default specbake:test)
#   SPECBAKE_CONTEXT  worktree (default: the working tree as it is) | head (the committed tree,
#                     exported with git archive)
#   SPECBAKE_HOST_BIN host specbake used for `inspect` (default build/specbake)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
image=${SPECBAKE_IMAGE:-specbake:test}
context_mode=${SPECBAKE_CONTEXT:-worktree}
host_bin=${SPECBAKE_HOST_BIN:-$root/build/specbake}
configs=tests/nightly/configs
jobs=(bk7-prism sf11-prism sine-grating small-sky) # one or more of each kind
SECONDS=0

say() { echo "docker-test: $*"; }
fail() { echo "docker-test: FAIL: $*" >&2; exit 1; }

tmp=$(mktemp -d "${TMPDIR:-/tmp}/specbake-docker-test.XXXXXX")
socket_pid=""
cleanup() {
  # Files written by the container may belong to its uid: remove them from inside it when needed.
  if [ -n "${tmp:-}" ] && ! rm -rf "$tmp" 2>/dev/null && [ -n "${engine_cmd:-}" ]; then
    "$engine_cmd" run --rm --user 0 -v "$tmp:/t" --entrypoint rm "$image" -rf /t/out >/dev/null 2>&1 || true
    rm -rf "$tmp" || true
  fi
  if [ -n "$socket_pid" ]; then kill "$socket_pid" 2>/dev/null || true; fi
}
trap cleanup EXIT

# --- Container engine -------------------------------------------------------------------------
engine=${SPECBAKE_ENGINE:-}
if [ -z "$engine" ]; then
  if command -v docker >/dev/null 2>&1 && docker info >/dev/null 2>&1; then engine=docker; else engine=podman; fi
fi
case "$engine" in
  docker) ;;
  podman | docker-podman)
    env_script="$root/../shared/tools/container-env.sh"
    [ -f "$env_script" ] || fail "no Docker daemon and no $env_script to set up podman"
    # shellcheck source=/dev/null
    source "$env_script"
    set -euo pipefail # the environment script switches these off at its end
    if [ "$engine" = docker-podman ]; then
      container_docker_socket
      socket_pid=$CONTAINER_SOCKET_PID
      export DOCKER_BUILDKIT=0 # podman's API serves the classic builder, not BuildKit
    fi
    ;;
  *) fail "SPECBAKE_ENGINE must be docker, podman or docker-podman, not '$engine'" ;;
esac
engine_cmd=${engine%-podman}
say "engine: $engine_cmd ($engine)"

# --- Host specbake for the check --------------------------------------------------------------
if [ ! -x "$host_bin" ]; then
  say "no $host_bin: building it with scripts/setup.sh"
  "$root/scripts/setup.sh"
fi

# --- Build context, version and revision ------------------------------------------------------
version=$(sed -n 's/^project(specbake VERSION \([0-9.]*\).*/\1/p' "$root/CMakeLists.txt")
[ -n "$version" ] || fail "cannot read the project version from CMakeLists.txt"
revision=unknown
if git -C "$root" rev-parse HEAD >/dev/null 2>&1; then revision=$(git -C "$root" rev-parse HEAD); fi
case "$context_mode" in
  worktree)
    context=$root
    if [ "$revision" != unknown ] && [ -n "$(git -C "$root" status --porcelain 2>/dev/null)" ]; then
      revision="$revision-dirty"
    fi
    ;;
  head)
    [ "$revision" != unknown ] || fail "SPECBAKE_CONTEXT=head needs a git checkout"
    context=$tmp/context
    mkdir -p "$context"
    git -C "$root" archive HEAD | tar -x -C "$context"
    ;;
  *) fail "SPECBAKE_CONTEXT must be worktree or head, not '$context_mode'" ;;
esac

# --- Build the image --------------------------------------------------------------------------
say "building $image (version $version, revision $revision, context: $context_mode)"
build_start=$SECONDS
"$engine_cmd" build -f "$context/docker/Dockerfile" -t "$image" \
  --build-arg SPECBAKE_VERSION="$version" \
  --build-arg SPECBAKE_REVISION="$revision" \
  --build-arg SPECBAKE_CREATED="$(date -u +%Y-%m-%dT%H:%M:%SZ)" \
  "$context" || fail "the image build failed"
say "image built in $((SECONDS - build_start)) s"

label() { "$engine_cmd" image inspect --format "{{ index .Config.Labels \"$1\" }}" "$image"; }
[ "$(label org.opencontainers.image.version)" = "$version" ] || fail "version label is '$(label org.opencontainers.image.version)', expected $version"
[ "$(label org.opencontainers.image.revision)" = "$revision" ] || fail "revision label is '$(label org.opencontainers.image.revision)', expected $revision"
[ "$("$engine_cmd" run --rm "$image" --version)" = "specbake $version" ] || fail "specbake --version in the image does not say $version"

# --- Who runs the container -------------------------------------------------------------------
# The container must run as a non-root user and be able to write the mounted output folder:
#   host user not root, docker:  --user <host uid>:<host gid> (files come out owned by the host user)
#   host user not root, podman:  --userns=keep-id (rootless: the host uid maps onto itself)
#   host user root:              the image's own user; the output folder is chowned to it
out=$tmp/out
mkdir -p "$out"
run_user=()
if [ "$(id -u)" -ne 0 ]; then
  if [ "$engine" = podman ]; then run_user=(--userns=keep-id); else run_user=(--user "$(id -u):$(id -g)"); fi
else
  image_ids=$("$engine_cmd" run --rm --entrypoint sh "$image" -c 'echo "$(id -u):$(id -g)"')
  chown "$image_ids" "$out"
fi
run_opts=(--rm "${run_user[@]}" -v "$root/$configs:/work/configs:ro" -v "$out:/out")
container_uid=$("$engine_cmd" run "${run_opts[@]}" --entrypoint id "$image" -u)
[ "$container_uid" != 0 ] || fail "the container runs as root"
say "container runs as uid $container_uid"

# --- Real jobs of each kind in the container ----------------------------------------------------
"$engine_cmd" run "${run_opts[@]}" "$image" devices
run_start=$SECONDS
"$engine_cmd" run "${run_opts[@]}" "$image" run configs --out /out --report /out/report.json ||
  fail "specbake run in the container exited $?"
say "jobs ran in $((SECONDS - run_start)) s"

# --- Check the bundles from the host ------------------------------------------------------------
for job in "${jobs[@]}"; do
  bundle=$out/$job/latest
  [ -e "$bundle/manifest.json" ] || fail "no $bundle/manifest.json after the run"
  owner=$(stat -c %u "$bundle/manifest.json")
  [ "$owner" = "$container_uid" ] || fail "$job's manifest.json is owned by uid $owner, expected $container_uid"
  "$host_bin" inspect "$bundle" >"$tmp/inspect.txt" || { cat "$tmp/inspect.txt"; fail "host specbake inspect rejected $bundle"; }
  say "$job: inspect OK ($(readlink "$bundle"))"
done
[ -e "$out/small-sky/latest/scene_check.csv" ] || fail "the atmosphere bundle has no scene_check.csv"
statuses=$(python3 -c 'import json, sys; print(" ".join(sorted(j["name"] + "=" + j["status"] for j in json.load(open(sys.argv[1]))["jobs"])))' "$out/report.json")
[ "$statuses" = "bk7-prism=built sf11-prism=built sine-grating=built small-sky=built" ] || fail "the run's report says: $statuses"
if find "$out" -name '.tmp-*' -o -name '.lock' | grep -q .; then fail "temporary folders or locks left in the output"; fi

say "PASS in $SECONDS s"
