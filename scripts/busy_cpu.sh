#!/usr/bin/env bash
# Wall time and the whole machine's busy CPU seconds (from /proc/stat) while a command runs:
# it counts processes `time` does not (Chromium's GPU process is not a waited-for child).
#   scripts/busy_cpu.sh .venv/bin/python -m pytest -q -p no:cacheprovider -m browser tests/browser/
set -uo pipefail
busy() { read -r _ u n s _ _ x y z _ < /proc/stat; echo $((u + n + s + x + y + z)); }
hz=$(getconf CLK_TCK)
b0=$(busy); t0=$(date +%s.%N)
"$@"; rc=$?
b1=$(busy); t1=$(date +%s.%N)
python3 -c "print(f'wall {$t1 - $t0:.1f} s, busy CPU {($b1 - $b0) / $hz:.1f} s (all processes)')"
exit $rc
