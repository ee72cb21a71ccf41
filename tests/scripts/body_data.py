#!/usr/bin/env python3
"""Converts the body data sets in ../shared/data/body into plain JSON the Rust tests can read.

Usage: body_data.py SHARED_DATA_DIR OUT_DIR

Writes (only when missing or older than this script):
  OUT_DIR/humaneva.json  HumanEva-I Train, every STEP_HE-th frame of each chunk, all three cameras:
      {"cameras": {"S1": [{"rotation": 3x3 world->camera, "center_mm": [x,y,z]} x3], ...},
       "sequences": [{"subject", "action", "camera": 0..2, "frames": [i...],
                      "joints3d_mm": [[[x,y,z] x15] ...], "joints2d": [[[u,v] x15] ...]}]}
      World frame: z up, floor at z = 0, millimetres. Joint order: VideoPose3D humaneva15
      (pelvis, thorax, lshoulder, lelbow, lwrist, rshoulder, relbow, rwrist, lhip, lknee, lankle,
      rhip, rknee, rankle, head).
  OUT_DIR/h36m.json  Human3.6M, every STEP_H36M-th 10-fps frame of every action, mapped to the same
      15 joints, with the four real cameras per subject:
      {"cameras": {"S1": [{"rotation", "center_mm", "f": [fx, fy], "c": [cx, cy]} x4]},
       "sequences": [{"subject", "action", "joints3d_mm": [[[x,y,z] x15] ...]}]}

The source formats: VideoPose3D npz files hold pickled dicts (positions_3d / positions_2d keyed
'Train/S1' -> action -> array); HumanEva camera orientations are quaternions (w, x, y, z) of the
camera-to-world rotation and translations the camera centres in mm (VideoPose3D's
`world_to_camera`); cameras.h5 is Martinez et al.'s file, X_cam = R^T (X - T) with R as stored (their loader transposes it).
Needs numpy and h5py (pip install numpy h5py).
"""
import json
import os
import sys

import numpy as np

STEP_HE = 10  # 60 fps -> 6 fps: keeps the cross-crate tests around a minute
STEP_H36M = 40  # 10 fps -> 0.25 fps
# Human3.6M 32-joint indices for the humaneva15 order above.
H36M_TO_HE15 = [0, 13, 17, 18, 19, 25, 26, 27, 6, 7, 8, 1, 2, 3, 15]


def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def fresh(path):
    return os.path.exists(path) and os.path.getmtime(path) >= os.path.getmtime(__file__)


def rnd(a, k=2):
    return np.round(np.asarray(a, dtype=np.float64), k).tolist()


def humaneva(shared, out):
    path = os.path.join(out, "humaneva.json")
    if fresh(path):
        return
    d = os.path.join(shared, "body", "humaneva")
    cams = json.load(open(os.path.join(d, "cameras_extrinsic_humaneva_videopose3d.json")))
    p3 = np.load(os.path.join(d, "data_3d_humaneva15.npz"), allow_pickle=True)["positions_3d"].item()
    p2 = np.load(os.path.join(d, "data_2d_humaneva15_gt.npz"), allow_pickle=True)["positions_2d"].item()
    cameras = {}
    for s in ("S1", "S2", "S3"):
        cameras[s] = [
            {"rotation": rnd(quat_to_matrix(c["orientation"]).T, 9), "center_mm": rnd(c["translation"], 3)}
            for c in cams[s]
        ]
    seqs = []
    for key in sorted(p3):
        subject = key.split("/")[1]
        for action in sorted(p3[key]):
            x3 = p3[key][action] * 1000.0
            idx = list(range(0, x3.shape[0], STEP_HE))
            for cam in range(3):
                x2 = p2[key][action][cam]
                seqs.append({"subject": subject, "action": action, "camera": cam, "frames": idx,
                             "joints3d_mm": rnd(x3[idx]), "joints2d": rnd(x2[idx], 3)})
    json.dump({"cameras": cameras, "sequences": seqs}, open(path + f".{os.getpid()}.tmp", "w"))
    os.replace(path + f".{os.getpid()}.tmp", path)


def h36m(shared, out):
    path = os.path.join(out, "h36m.json")
    if fresh(path):
        return
    import h5py

    d = os.path.join(shared, "body", "h36m")
    poses = np.load(os.path.join(d, "poses3d_mm_10fps.npz"))
    cameras = {}
    with h5py.File(os.path.join(d, "cameras.h5"), "r") as f:
        for s in ("S1", "S5", "S6", "S7", "S8"):
            cams = []
            for c in range(1, 5):
                g = f["subject%s/camera%d" % (s[1:], c)]
                cams.append({"rotation": rnd(g["R"][()].T, 9), "center_mm": rnd(g["T"][()].ravel(), 3),
                             "f": rnd(g["f"][()].ravel(), 4), "c": rnd(g["c"][()].ravel(), 4)})
            cameras[s] = cams
    seqs = []
    for key in sorted(poses.files):
        subject, action = key.split("/", 1)
        x = poses[key][::STEP_H36M][:, H36M_TO_HE15, :]
        seqs.append({"subject": subject, "action": action, "joints3d_mm": rnd(x)})
    json.dump({"cameras": cameras, "sequences": seqs}, open(path + f".{os.getpid()}.tmp", "w"))
    os.replace(path + f".{os.getpid()}.tmp", path)


# Whole sequences (10 fps, not subsampled) for the motion comparison tests: the first 12 s.
MOTION_KEYS = ["S1/Walking", "S5/Walking", "S1/Eating", "S1/Greeting"]
MOTION_FRAMES = 120


def motion(shared, out):
    path = os.path.join(out, "motion.json")
    if fresh(path):
        return
    poses = np.load(os.path.join(shared, "body", "h36m", "poses3d_mm_10fps.npz"))
    seqs = []
    for key in MOTION_KEYS:
        subject, action = key.split("/", 1)
        x = poses[key][:MOTION_FRAMES][:, H36M_TO_HE15, :]
        seqs.append({"subject": subject, "action": action, "joints3d_mm": rnd(x)})
    json.dump({"fps": 10, "sequences": seqs}, open(path + f".{os.getpid()}.tmp", "w"))
    os.replace(path + f".{os.getpid()}.tmp", path)


def main():
    shared, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    humaneva(shared, out)
    h36m(shared, out)
    motion(shared, out)


if __name__ == "__main__":
    main()
