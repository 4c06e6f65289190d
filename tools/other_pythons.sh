#!/usr/bin/env bash
# The quick tests on every supported Python this machine has besides the one that runs the suite
# (pyenv's interpreters, or python3.X on PATH), each in a venv of its own with the wheel, its runtime
# dependencies and the test runner alone (the tests import the tree's cipstack, run from its root; a
# test that needs a peer or an extra is skipped with the reason, never an error: the wheel-alone check).
# The oldest of them runs the quick tests whole; the others run a sample (tests/sampling.py: the
# modules that meet what differs between Pythons whole, one test in three of the rest). The precise
# event loop reads asyncio's private queues, which each Python may lay out anew, and the standard
# library moves under the rest (Python 3.10's str() of an IntEnum member is its name;
# loop.sock_sendto came with 3.11). A supported Python the machine lacks is named and skipped; with
# none at all, the running Python runs the quick tests whole with the wheel alone. An unknown Python
# is refused by check_python (tests/test_precise_loop.py, on every Python).
#
#   bash tools/other_pythons.sh prepare DIST/cipstack-*.whl WORKDIR   # the venvs (network and disk)
#   bash tools/other_pythons.sh test WORKDIR                           # the tests (CPU)
#
# .ci/run prepares while podman builds its image, then tests.
set -euo pipefail
cd "$(dirname "$0")/.."
#: One test in this many of each module that is not version-sensitive, on all but the oldest Python.
SAMPLE=3

phase="$1"
if [ "$phase" = prepare ]; then
  wheel="$2"
  work="$3"
  mkdir -p "$work"
  running="$(python3 -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')"
  supported="$(python3 -c 'import ast, re, pathlib
text = pathlib.Path("cipstack/eip/precise_loop.py").read_text(encoding="utf-8")
print(" ".join(f"{a}.{b}" for a, b in ast.literal_eval(re.search(r"^SUPPORTED_PYTHONS = (.*)$", text, re.M).group(1))))')"
  pyenv_root="$(command -v pyenv >/dev/null 2>&1 && pyenv root || echo "${PYENV_ROOT:-$HOME/.pyenv}")"
  : >"$work/prepared"
  for version in $supported; do
    [ "$version" = "$running" ] && continue
    # pyenv's own build first: python3.X on PATH may be a pyenv shim that runs only the selected version.
    python="$(ls -d "$pyenv_root"/versions/"$version".*/bin/python3 2>/dev/null | sort -V | tail -n 1 || true)"
    if [ -z "$python" ] || ! "$python" -c pass 2>/dev/null; then
      python="$(command -v "python$version" || true)"
    fi
    if [ -z "$python" ] || ! "$python" -c pass 2>/dev/null; then
      echo "quick tests on Python $version: no such interpreter on this machine, skipped"
      continue
    fi
    "$python" -m venv "$work/$version"
    "$work/$version/bin/python" -m pip install --quiet --disable-pip-version-check "$wheel[test-runner]"
    echo "$version" >>"$work/prepared"
  done
  if [ ! -s "$work/prepared" ]; then
    python3 -m venv "$work/$running"
    "$work/$running/bin/python" -m pip install --quiet --disable-pip-version-check "$wheel[test-runner]"
    echo "$running" >>"$work/prepared"
  fi
  exit 0
fi

[ "$phase" = test ] || { echo "usage: $0 prepare WHEEL WORKDIR | test WORKDIR" >&2; exit 2; }
work="$2"
failed=""
first=yes
for version in $(cat "$work/prepared"); do
  python="$work/$version/bin/python"
  exact="$("$python" -c 'import sys; print(sys.version.split()[0])')"
  if [ "$first" = yes ]; then
    selection=(-m quick)
    what="the quick tests, whole"
    first=no
  else
    selection=(-m quick --sample "$SAMPLE")
    what="a sample of the quick tests (--sample $SAMPLE)"
  fi
  # Bounded: a hang on a new Python fails the step instead of holding CI.
  if timeout 1200 "$python" -m pytest -q -p no:cacheprovider "${selection[@]}"; then
    echo "Python $exact, the wheel and the test runner alone: $what pass"
  else
    echo "Python $exact, the wheel and the test runner alone: $what FAILED"
    failed="$failed $exact"
  fi
done
if [ -n "$failed" ]; then
  echo "the quick tests failed on Python$failed" >&2
  exit 1
fi
