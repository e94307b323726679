"""Rewrite ``tests/durations.json`` from a JUnit XML report: every test that took ≥ 1 s.

python -m pytest -p no:cacheprovider --junitxml=/tmp/t.xml
python scripts/durations.py /tmp/t.xml
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "tests" / "durations.json"


def main(report: str) -> None:
    seconds: dict[str, float] = {}
    for case in ET.parse(report).getroot().iter("testcase"):
        # classname "tests.test_x" or "tests.test_x.TestClass": the module is the longest
        # dotted prefix that is a file.
        parts = (case.get("classname") or "").split(".")
        for n in range(len(parts), 0, -1):
            module = "/".join(parts[:n]) + ".py"
            if (REPO / module).exists():
                nodeid = "::".join([module, *parts[n:], case.get("name") or ""])
                seconds[nodeid] = seconds.get(nodeid, 0.0) + float(case.get("time") or 0.0)
                break
    slow = {k: round(v, 1) for k, v in sorted(seconds.items(), key=lambda kv: -kv[1]) if v >= 1.0}
    OUT.write_text(json.dumps(slow, indent=0, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"{OUT}: {len(slow)} tests of {len(seconds)} took ≥ 1 s")


if __name__ == "__main__":
    main(sys.argv[1])
