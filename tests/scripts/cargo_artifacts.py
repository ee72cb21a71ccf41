#!/usr/bin/env python3
"""Reads cargo's JSON messages (`cargo test --no-run --message-format=json...`) on stdin and prints
one line per artifact the scripts run or load: `test TARGET KIND EXECUTABLE` for each test
executable (KIND: lib, bin, test, example, bench; TARGET: the crate name of a lib, else the target's
name), `bin NAME bin EXECUTABLE` for each binary, `cdylib NAME lib FILE` for each shared library.
Fresh artifacts are reported as well, so a no-op build lists everything."""
import json
import sys

for line in sys.stdin:
    try:
        m = json.loads(line)
    except ValueError:
        continue
    if m.get("reason") != "compiler-artifact":
        continue
    target = m["target"]
    kind = target["kind"][0] if target["kind"][0] != "cdylib" else "lib"
    if kind in ("rlib", "dylib", "staticlib", "proc-macro"):
        kind = "lib"
    name = target["name"].replace("-", "_") if kind == "lib" else target["name"]
    if m["profile"]["test"] and m.get("executable"):
        print("test", name, kind, m["executable"])
    elif "bin" in target["kind"] and m.get("executable"):
        print("bin", name, "bin", m["executable"])
    elif "cdylib" in target["kind"]:
        for f in m["filenames"]:
            if f.endswith((".so", ".dylib", ".dll")):
                print("cdylib", name, "lib", f)
