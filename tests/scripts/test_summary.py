#!/usr/bin/env python3
"""Sums libtest's per-binary lines (`test result: ok. N passed; N failed; N ignored; ...`) in the
logs given and prints one line per log and a total, with the ignored tests counted by their reason
(`test NAME ... ignored, REASON`). With --no-data-ignored, exits 1 if any test was ignored for
needing ../shared/data (where the data is present, none may be)."""
import re
import sys
from collections import Counter

args = [a for a in sys.argv[1:] if not a.startswith("--")]
strict = "--no-data-ignored" in sys.argv
total = Counter()
reasons = Counter()
for path in args:
    label, _, path = path.partition("=")
    c = Counter()
    with open(path, errors="replace") as f:
        for line in f:
            m = re.search(r"test result: \w+\. (\d+) passed; (\d+) failed; (\d+) ignored; "
                          r"\d+ measured; (\d+) filtered out", line)
            if m:
                c["passed"] += int(m[1]); c["failed"] += int(m[2]); c["ignored"] += int(m[3])
                c["filtered"] += int(m[4])
                continue
            m = re.match(r"test .* \.\.\. ignored(?:, (.*))?$", line.rstrip())
            if m:
                reasons[m[1] or "no reason given (a doc example marked ignore, or #[ignore] alone)"] += 1
    total.update(c)
    filtered = f", {c['filtered']} left out by name" if c["filtered"] else ""
    print(f"  {label}: {c['passed']} passed, {c['failed']} failed, {c['ignored']} ignored{filtered}")
print(f"rust total: {total['passed']} passed, {total['failed']} failed, {total['ignored']} ignored")
for r, n in reasons.most_common():
    print(f"  ignored {n}: {r}")
data = sum(n for r, n in reasons.items() if "shared/data" in r)
if strict and data:
    print(f"FAILED: {data} tests ignored for ../shared/data although it is present "
          "(a stale build: the tests crate's build.rs reads the folder; `cargo clean -p monotrack-tests`)")
    sys.exit(1)
sys.exit(1 if total["failed"] else 0)
