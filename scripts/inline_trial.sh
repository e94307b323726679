#!/usr/bin/env bash
# A trial of stepping telemetry in zenoh's callback thread (as the contract floor
# does) instead of handing it to the service's worker: a copy of this tree with
# Service._on_sample patched runs as bench_bursts' `baseline`, beside the service as it is,
# the echo and the floor, in one run.
#   scripts/inline_trial.sh            # ~2.5 min (10 s windows); prints the bursts table
# Results: docs/service_profile.md, section 7.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
tree=$(mktemp -d)
trap 'rm -rf "$tree"' EXIT
git -C "$repo" archive HEAD | tar -x -C "$tree"
"$repo/.venv/bin/python" - "$tree/groundstation/service.py" <<'EOF'
import sys
path = sys.argv[1]
text = open(path, encoding="utf-8").read()
old = """        if parsed is None:
            return
        if self._queue.qsize() >= self._queue_size:"""
new = """        if parsed is None:
            return
        if parsed.kind == "telemetry":  # the trial: step it here, in zenoh's thread
            with self._lock:
                outputs = self.pipeline.process_batch([parsed], self._on_error)
            self._publish(outputs)
            return
        if self._queue.qsize() >= self._queue_size:"""
assert text.count(old) == 1, "Service._on_sample changed: update the trial's patch"
open(path, "w", encoding="utf-8").write(text.replace(old, new))
EOF
cd "$repo"
.venv/bin/python -m benchmarks.bench_bursts --quick --baseline "$tree" --out "$tree/bursts.md"
sed -n '/^| case/,/^$/p;/^p99 service/p' "$tree/bursts.md"
