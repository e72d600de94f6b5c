#!/usr/bin/env bash
# cvc_balance developer entry point: sets up .venv on first use, then runs a job.
#   ./dev.sh demo      the main job: a bundled bag played live into the node; its verdict, run, .rrd
#   ./dev.sh test      the tests (colcon build + colcon test smoke beside the pytest suite)
#   ./dev.sh test --quick   the edit-test loop: the pytest suite without its slow tests
#   ./dev.sh setup     only (re)create the virtual environment
#   ./dev.sh run CMD   run CMD inside the environment (e.g. ./dev.sh run cvc-balance --help)
#   ./dev.sh pictures [NAME ...]  make every picture the docs show again (docs/pictures.md)
#   ./dev.sh docs      build the documentation site (Sphinx, warnings as errors); prints index.html
#   ./dev.sh bags      make the bundled bags again from their scenarios (bags/X.yaml -> bags/X.mcap)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
stamp="$venv/.requirements.sha256"

find_python() {
  for candidate in python3.11 python3; do
    if command -v "$candidate" >/dev/null 2>&1 &&
       "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
      echo "$candidate"; return 0
    fi
  done
  # Debian: python3.11 with venv support from the distribution.
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    apt-get update -qq && apt-get install -y -qq python3.11 python3.11-venv >/dev/null
    echo python3.11; return 0
  fi
  echo "dev.sh: needs Python 3.11 (the ROS 2 Jazzy wheels are built for it)" >&2
  return 1
}

pip_quiet() {
  # This machine's pip configuration names local mirrors that may be absent: drop
  # those warnings, keep every other message and pip's exit status.
  "$venv/bin/python" -m pip -q "$@" 2> >(grep -v "^WARNING: Location 'file:" >&2)
}

setup() {
  local want
  want="$(cat "$here/requirements.txt" "$here/requirements-test.txt" "$here/setup.py" | sha256sum)"
  if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
    return 0
  fi
  local python
  python="$(find_python)"
  echo "dev.sh: setting up $venv (one-time, about a minute)" >&2
  "$python" -m venv "$venv"
  pip_quiet install --upgrade pip
  pip_quiet install -r "$here/requirements-test.txt"
  PYTHONWARNINGS=ignore pip_quiet install --no-deps -e "$here"
  echo "$want" > "$stamp"
}

in_venv() {
  export PATH="$venv/bin:$PATH" VIRTUAL_ENV="$venv"
  # ROS packages from the wheels live in the venv prefix; colcon and ament look here.
  export AMENT_PREFIX_PATH="$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  export RERUN_TELEMETRY_ENABLED=false HYPOTHESIS_NO_PLUGINS=1
  "$@"
}

colcon_check() {
  # colcon build and a colcon test smoke run (lint + thesis tests), outside the source
  # tree; their chatter goes to a log that is shown only if something fails.
  local base="$here/.colcon" log
  rm -rf "$base" && mkdir -p "$base"
  log="$base/colcon.log"
  if ! (cd "$here" &&
        in_venv colcon --log-base "$base/log" build --base-paths "$here" \
          --build-base "$base/build" --install-base "$base/install" &&
        in_venv colcon --log-base "$base/log" test --base-paths "$here" \
          --build-base "$base/build" --install-base "$base/install" \
          --return-code-on-test-failure \
          --pytest-args -q -p no:cacheprovider -k "lint or thesis") >"$log" 2>&1; then
    cat "$log" >&2
    in_venv colcon test-result --test-result-base "$base/build" --verbose >&2 || true
    echo "dev.sh: colcon build/test failed (log: $log)" >&2
    return 1
  fi
  echo "colcon: $(in_venv colcon test-result --test-result-base "$base/build" | tail -n 1)"
}

demo() {
  # The balance_monitor node on this machine's ROS graph (discovery kept on localhost),
  # a bundled bag played into it live, its outputs and diagnostics recorded and its rerun
  # view saved; it ends with the node's verdict per layout and where the run is.
  local bag="$here/bags/spin_up_tube_swap.mcap" runs="$here/runs"
  local out="$runs/spin_up_tube_swap_live.mcap" rrd="$runs/spin_up_tube_swap_live.rrd"
  local said="$runs/spin_up_tube_swap_live.txt"
  mkdir -p "$runs"
  export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-42}" ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
  # exec: $! is then the node itself; SIGTERM, since background jobs ignore SIGINT.
  in_venv exec balance-monitor --ros-args --params-file "$here/config/balance_monitor.yaml" \
    -p rerun:=save -p rerun_target:="$rrd" &
  local node=$!
  trap 'kill -TERM $node 2>/dev/null; wait $node 2>/dev/null' EXIT
  in_venv cvc-balance play "$bag" -o "$out" | tee "$said"
  kill -TERM $node && wait $node
  trap - EXIT
  echo
  sed -n '/verdict per layout/,$p' "$said"
  echo "the live run's outputs and /diagnostics: $out"
  echo "its rerun view:                         $rrd"
  echo "open it:                                ./dev.sh run rerun $rrd"
}

vulkan() {
  # rerun's viewer renders through Vulkan; without a GPU, Mesa's software driver (lavapipe).
  if command -v dpkg >/dev/null 2>&1 && dpkg -s mesa-vulkan-drivers libvulkan1 >/dev/null 2>&1; then
    return 0
  fi
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "dev.sh: installing mesa-vulkan-drivers libvulkan1 (the viewer's headless rendering)" >&2
    apt-get update -qq && apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
    return $?
  fi
  echo "dev.sh: mesa-vulkan-drivers and libvulkan1 are missing and cannot be installed" \
    "here (needs root and apt-get)" >&2
  return 1
}

node_readers() {
  # Foxglove's TypeScript readers for test/test_foxglove_readers.py: Node.js and npm
  # (Debian's, when the machine has none) and the packages of test/js/package-lock.json.
  if ! command -v node >/dev/null 2>&1 || ! command -v npm >/dev/null 2>&1; then
    if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
      echo "dev.sh: installing nodejs npm (Foxglove's readers, in the tests)" >&2
      apt-get update -qq && apt-get install -y -qq nodejs npm >/dev/null || return 1
    else
      echo "dev.sh: nodejs and npm are missing and cannot be installed here (needs root" \
        "and apt-get)" >&2
      return 1
    fi
  fi
  local js="$here/test/js"
  if [ ! -f "$js/node_modules/.package-lock.json" ] ||
     [ "$js/package-lock.json" -nt "$js/node_modules/.package-lock.json" ]; then
    (cd "$js" && npm ci --no-audit --no-fund --loglevel=error) || return 1
  fi
}

chromium_browser() {
  # The report's pictures and its browser test: Debian's Chromium, headless.
  if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then
    return 0
  fi
  if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
    echo "dev.sh: installing chromium (the report's pictures and browser test)" >&2
    apt-get update -qq && apt-get install -y -qq chromium >/dev/null
    return $?
  fi
  echo "dev.sh: chromium is missing and cannot be installed here (needs root and apt-get)" >&2
  return 1
}

pictures() {
  # Every picture the README and docs show, from bags/ and config/ only (docs/pictures.py):
  # the rerun viewer headless (Mesa's Vulkan drivers), the report in Chromium, the charts;
  # then docs/pictures.json (what each was made from) and docs/pictures.md.
  vulkan || echo "dev.sh: the viewer's picture will fail without them" >&2
  chromium_browser || echo "dev.sh: the report's picture will fail without it" >&2
  cd "$here" && in_venv python docs/pictures.py "$@"
}

docs() {
  # The site from docs/ (MyST Markdown); the reference pages are written from the code at
  # build time. Warnings are errors: a broken link or a stale page fails the build.
  local out="$here/docs/_build/html"
  in_venv python -m sphinx -W --keep-going -q -b html "$here/docs" "$out" >&2
  echo "$out/index.html"
}

bags() {
  # Each bundled bag (bags/X.mcap) is what `cvc-balance simulate` makes of its scenario
  # (bags/X.yaml) now; test_bags.py checks that they decode equal to a fresh simulation.
  local bag
  for bag in "$here"/bags/*.mcap; do
    in_venv cvc-balance simulate "${bag%.mcap}.yaml" -o "$bag"
  done
}

cmd="${1:-}"
shift || true
case "$cmd" in
  setup) setup ;;
  demo)
    setup
    demo ;;
  test)
    setup
    # Bytecode may be written while testing (this machine sets PYTHONDONTWRITEBYTECODE=1):
    # pytest then keeps each test file's assertion-rewritten code, which every worker and
    # colcon's run otherwise rewrite anew at collection (13 s of CPU each, 6 s cached).
    export PYTHONDONTWRITEBYTECODE=
    if [ "${1:-}" = --quick ]; then
      # Seconds, not minutes: no colcon, no test marked slow (setup.cfg says which are).
      shift
      set -- -m "not slow" "$@"
    else
      vulkan || echo "dev.sh: the viewer's rendering test will be skipped" >&2
      node_readers || echo "dev.sh: Foxglove's readers are not installed (test_foxglove_readers)" >&2
      chromium_browser || echo "dev.sh: the report's browser test will be skipped" >&2
      # colcon build and test (lint, thesis) beside pytest, which runs the other tests; the
      # run fails if either does. It holds the tests' lock shared (conftest.py's
      # CVC_TEST_LOCK), so tests that must run alone wait for it too.
      export CVC_TEST_LOCK="$here/.colcon.lock"
      exec 9>"$CVC_TEST_LOCK"
      flock -s 9
      colcon_check &
      colcon=$!
      exec 9>&-
      set -- -k "not (lint or thesis)" "$@"
    fi
    # The package's bytecode once, before the processes the tests start import it.
    in_venv python -m compileall -q "$here/cvc_balance" >/dev/null
    # One worker more than cores (CVC_TEST_WORKERS overrides): the tests wait on the
    # processes they start about half the time (idle, 2 cores: 710 s with 2 workers for
    # 712 s of CPU, 519 s with 3). A file stays on one worker, in its order, with its
    # module fixtures made once. Each worker has its own ROS domain id.
    # Files longest first (test/file_costs.txt, conftest.py), not xdist's most-tests-first.
    status=0
    workers="${CVC_TEST_WORKERS:-$(($(nproc) + 1))}"
    (cd "$here" && in_venv python -m pytest -n "$workers" --dist loadfile \
      --no-loadscope-reorder "$@") || status=$?
    if [ -n "${colcon:-}" ]; then
      wait "$colcon" || status=1
    fi
    exit "$status" ;;
  run)
    setup
    in_venv "$@" ;;
  pictures)
    setup
    pictures "$@" ;;
  screenshot)       # the viewer's picture alone (its old name)
    setup
    pictures viewer ;;
  docs)
    setup
    docs ;;
  bags)
    setup
    bags ;;
  *)
    sed -n '2,10p' "$0" >&2
    exit 2 ;;
esac
