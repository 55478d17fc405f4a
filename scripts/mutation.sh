#!/usr/bin/env bash
# Mutation testing of the harness's judge (docs/mutation.md): mutmut mutates the verifier's
# modules (harness/pyproject.toml [tool.mutmut]) and runs, against each mutant, the fast tests
# that reach the mutated function; then scripts/mutation_summary.py counts the mutants per
# module, subtracts the ones recorded as equivalent (harness/mutation_equivalent.toml, each
# with its reason) and writes reports/mutation/harness.json.
#
#   scripts/mutation.sh              # fresh run (about 15 minutes on 2 cores), then the summary
#   scripts/mutation.sh --summary    # the summary of the last run only
#
# Exit 1 when a module's score is under the goal (90% of the non-equivalent mutants killed) or
# an equivalent entry is stale (the mutant is gone, or a test now kills it: drop the entry).
# Long and low priority: run it under `nice -n 19`; the PR workflow runs it as its own job.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PY="${RENDIFF_PYTHON:-$REPO/.venv/bin/python}"
MUTMUT="$(dirname "$PY")/mutmut"
if [[ ! -x "$MUTMUT" ]]; then
    echo "mutation.sh: $MUTMUT missing: run scripts/setup.sh (harness/requirements.txt pins mutmut)" >&2
    exit 2
fi
cd "$REPO/harness"
if [[ "${1:-}" != "--summary" ]]; then
    # A fresh run: mutmut keeps results between runs, and a result from older code or tests is stale.
    rm -rf mutants
    # The mutants' copy must be imported, not the checkout's harness (mutmut puts it first on sys.path).
    env -u PYTHONPATH "$MUTMUT" run --max-children "${MUTATION_JOBS:-$(nproc)}" >mutants.log 2>&1 || {
        tail -c 4000 mutants.log >&2
        echo "mutation.sh: mutmut run failed (log: harness/mutants.log)" >&2
        exit 2
    }
    tail -c 300 mutants.log | tr '\r' '\n' | tail -n 2
fi
exec "$PY" "$REPO/scripts/mutation_summary.py" --mutants mutants --equivalent mutation_equivalent.toml \
    -o "$REPO/reports/mutation/harness.json"
