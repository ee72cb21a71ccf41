#!/usr/bin/env python3
"""One command from a face data folder to a model bundle: trains M3 (train_m3.py, fixed seeds) on
DATA, a folder laid out like ../shared/data/faces68 (`train.jsonl` with 68-point labels,
`teacher_mediapipe.jsonl`, the images they name), and packs the result with the shipped detector
and face model (make_bundle.py). The other data sets training reads (GENKI-4K and the rest of
../shared/data) come from MONOTRACK_SHARED_DATA or ../shared/data beside the repository.

    python3 core/models/train/build_bundle.py DATA OUT.mtb [--work DIR] [train_m3.py options ...]

Training takes hours on a CPU; `--steps-scale 0.01` makes a quick, poor bundle to try the
plumbing with. Needs torch, onnx, onnxruntime, opencv (core/models/train/README.md).
"""
import argparse
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import make_bundle  # noqa: E402


def data_root(faces, work):
    """A data root whose faces68 is `faces`, the other data sets linked from the shared one."""
    shared = os.environ.get("MONOTRACK_SHARED_DATA",
                            os.path.join(make_bundle.REPO, "..", "shared", "data"))
    root = os.path.join(work, "data")
    os.makedirs(root, exist_ok=True)
    link = os.path.join(root, "faces68")
    if not os.path.lexists(link):
        os.symlink(os.path.abspath(faces), link)
    if os.path.isdir(shared):
        for name in os.listdir(shared):
            target = os.path.join(root, name)
            if name != "faces68" and not os.path.lexists(target):
                os.symlink(os.path.abspath(os.path.join(shared, name)), target)
    # The shared tools beside the data (pseudo_genki.py runs DATA/../tools/peer_landmarks.py).
    tools = os.path.join(shared, "..", "tools")
    if os.path.isdir(tools) and not os.path.lexists(os.path.join(work, "tools")):
        os.symlink(os.path.abspath(tools), os.path.join(work, "tools"))
    return root


def pseudo_path(work):
    """The teacher-labelled GENKI-4K faces (pseudo_genki.py) the face net learns from: MONOTRACK_PSEUDO,
    else the shared cache when it exists, else a file in `work` (made there: its image paths point
    into `work`, so it must not take the shared cache's place)."""
    import pseudo_genki
    if os.environ.get("MONOTRACK_PSEUDO"):
        return os.environ["MONOTRACK_PSEUDO"]
    if os.path.exists(pseudo_genki.default_path()):
        return pseudo_genki.default_path()
    return os.path.join(work, "genki_pfld.jsonl")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data")
    ap.add_argument("out")
    ap.add_argument("--work", default=None, help="where the trained networks go (default: a temporary folder)")
    a, train_args = ap.parse_known_args()
    for need in ("train.jsonl", "teacher_mediapipe.jsonl"):
        if not os.path.isfile(os.path.join(a.data, need)):
            raise SystemExit(f"{a.data} is not laid out like faces68: no {need}")
    work = a.work or tempfile.mkdtemp(prefix="monotrack-bundle-")
    m3_out = os.path.join(work, "m3")
    env = dict(os.environ, MONOTRACK_SHARED_DATA=data_root(a.data, work), MONOTRACK_M3_OUT=m3_out,
               MONOTRACK_PSEUDO=pseudo_path(work))
    subprocess.run([sys.executable, os.path.join(HERE, "train_m3.py"), *train_args], env=env, check=True)
    n, size = make_bundle.write(a.out, m3_out,
                                os.path.join(make_bundle.MODELS, "detector"),
                                os.path.join(make_bundle.MODELS, "face_model", "face_model.json"))
    print(f"{a.out}: {n} files, {size} bytes (networks trained in {m3_out})")


if __name__ == "__main__":
    main()
