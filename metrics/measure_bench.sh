#!/usr/bin/env bash
# Re-measures the bench tables on this machine: the phone's path (metrics/bench_phone_path.json:
# three runs each of the portable and native paths, alternating) and what each x86-64 kernel form
# earns (metrics/bench_forms.json: every kernel choice in turn, three rounds), then rewrites the
# docs' tables. Run on an otherwise idle machine; it builds the CLI with the bench profile first.
#   metrics/measure_bench.sh [ROUNDS]
set -euo pipefail
cd "$(dirname "$0")/.."
rounds=${1:-3}
cargo build --profile bench -p monotrack-cli
bin=target/release/monotrack
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
bench() { "$bin" --kernels "$1" bench --format nv21 --rotation 90 --frames 300 --json; }

choices=(portable native "native,conv=f32x4,flow=portable" native,conv=avx2
  native,conv=bf16 native,conv=vnni native,flow=portable native,flow=avx2 native,flow=avx512)
for r in $(seq "$rounds"); do
  for i in "${!choices[@]}"; do
    bench "${choices[$i]}" > "$tmp/$r-$i.json"
    echo "round $r: ${choices[$i]}" >&2
  done
done

python3 - "$tmp" "${choices[@]}" <<'PY'
import glob, json, os, sys
tmp, choices = sys.argv[1], sys.argv[2:]
runs = []
for path in sorted(glob.glob(os.path.join(tmp, "*.json"))):
    r, i = os.path.basename(path)[:-5].split("-")
    d = json.load(open(path))
    d["kernels"] = choices[int(i)]
    runs.append((int(r), int(i), d))
runs.sort(key=lambda t: (t[0], t[1]))
phone = [dict(d, format="nv21", rotation=90) for _, _, d in runs if d["kernels"] in ("portable", "native")]
for d in phone:
    del d["kernels"]
json.dump(phone, open("metrics/bench_phone_path.json", "w"), indent=1)
forms = [
    ("3×3 layers (M3 trunks, detector stem), f32 on 256-bit registers", "native,conv=avx2", "landmarks", "native,conv=f32x4,flow=portable"),
    ("3×3 layers, bf16 pairs (the default on AMD CPUs with AVX-512 BF16)", "native,conv=bf16", "landmarks", "native,conv=avx2"),
    ("3×3 layers and heads, int8 (the default on other CPUs with AVX-512 VNNI)", "native,conv=vnni", "landmarks", "native,conv=avx2"),
    ("Lucas–Kanade windows, AVX2", "native,flow=avx2", "flow", "native,flow=portable"),
    ("Lucas–Kanade windows, AVX-512", "native,flow=avx512", "flow", "native,flow=avx2"),
    ("patch warps, bilateral filter, heads: AVX2 / AVX-512 forms", "native,conv=f32x4,flow=portable", "landmarks", "portable"),
    ("frame conversion: the plane turn (SSE2 tiles), AVX2 copies", "native,conv=f32x4,flow=portable", "convert", "portable"),
    ("NCC search: AVX2 copies", "native,conv=f32x4,flow=portable", "region", "portable"),
]
json.dump({
    "cpu": runs[0][2]["cpu"],
    "command": "metrics/measure_bench.sh",
    "runs": [d for _, _, d in runs],
    "forms": [dict(kernel=k, kernels=c, stage=s, against=a) for k, c, s, a in forms],
}, open("metrics/bench_forms.json", "w"), indent=1)
PY
python3 tests/scripts/docs_tables.py
