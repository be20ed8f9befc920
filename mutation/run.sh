#!/bin/sh
# Run one mutation session on a copy of this checkout (cosmic-ray rewrites the module on
# disk while its tests run, so it never touches the working tree you edit).
#   mutation/run.sh NAME [SAMPLE]      e.g.  mutation/run.sh store_checks 60
# NAME is a config in mutation/ (NAME.toml); SAMPLE keeps a seeded random subset of the
# mutants that are not annotation-only (mutation/choose.py). The session database stays in
# $MUTATION_WORKDIR/NAME/ (default /tmp/slr-mutation); the summary is printed at the end.
# BUDGET=SECONDS stops the run after that long (SIGINT: cosmic-ray puts the module back);
# cosmic-ray runs the pending mutants in random order, so the mutants run by then are a
# uniform random subset of the sample (the summary counts them). SEED=N draws another
# sample (default 19).
set -eu
name=$1
sample=${2:-}
root=$(cd "$(dirname "$0")/.." && pwd)
work=${MUTATION_WORKDIR:-/tmp/slr-mutation}/$name
rm -rf "$work"
mkdir -p "$work"
(cd "$root" && tar --exclude=.git --exclude=__pycache__ --exclude=.hypothesis -cf - .) | tar -xf - -C "$work"
cd "$work"
cosmic-ray init "mutation/$name.toml" "$name.sqlite"
if [ -n "$sample" ]; then
    python mutation/choose.py "$name.sqlite" --sample "$sample" --seed "${SEED:-19}"
else
    python mutation/choose.py "$name.sqlite"
fi
cosmic-ray baseline "mutation/$name.toml"
if [ -n "${BUDGET:-}" ]; then
    timeout -s INT "$BUDGET" cosmic-ray exec "mutation/$name.toml" "$name.sqlite" || true
else
    cosmic-ray exec "mutation/$name.toml" "$name.sqlite"
fi
python mutation/summary.py "$name.sqlite" --diffs
