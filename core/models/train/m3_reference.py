"""Reference M3 inference in Python (onnxruntime), following core/models/M3_IO.md step by step.

It is the yardstick for the Rust implementation (`core::landmarks`): the evaluation script and the
golden-test generators use it. `M3(model_dir).run(gray, box)` returns a dict with the 68 points,
yaw probabilities, face probability, gestures and gaze.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import m3data as D  # noqa: E402


def _session(path):
    import onnxruntime as ort
    so = ort.SessionOptions()
    so.intra_op_num_threads = so.inter_op_num_threads = 1
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def softmax(x):
    e = np.exp(x - x.max())
    return e / e.sum()


class Level1Runner:
    def __init__(self, path, size=64, crop_scale=1.3, indices=None, mirror_average=False):
        self.sess = _session(path)
        self.size, self.crop_scale = size, crop_scale
        self.indices, self.mirror_average = indices, mirror_average

    def _net(self, crop):
        lm, yl, fl = self.sess.run(None, {"image": (crop / 255.0).astype(np.float32)[None, None]})
        return lm.reshape(-1, 2).astype(np.float64), softmax(yl[0].astype(np.float64)), fl[0, 0]

    def run(self, gray, box):
        c, s = D.square_of_box(box)
        A = D.level1_map(c, s, self.size, self.crop_scale)
        crop = D.sample(gray, A, self.size, self.size)
        lm, yaw, fl = self._net(crop)
        if self.mirror_average:
            # M3_IO.md: the mirrored crop's points, un-mirrored, averaged with the crop's; yaw and
            # the face probability are the crop's alone.
            lmf, _, _ = self._net(np.ascontiguousarray(crop[:, ::-1]))
            lm = 0.5 * (lm + unflip(lmf, self.indices))
        pts = D.apply(A, lm * self.size)
        return pts, yaw, 1.0 / (1.0 + np.exp(-fl))


def unflip(lm, indices):
    """Points a net gave for its mirrored input (net units 0..1, in `indices` order), mapped back:
    x -> 1 - x, and the estimate of point i is the mirrored input's point MIRROR68[i] (M3_IO.md)."""
    pos = {int(i): k for k, i in enumerate(indices)}
    out = lm[[pos[int(D.MIRROR68[i])] for i in indices]].copy()
    out[:, 0] = 1.0 - out[:, 0]
    return out


class M3:
    """`mirror_average`: the mode of M3_IO.md in which level 1 and the zones marked `mirror_average`
    in m3.json also run on their mirrored input and average (core::landmarks::M3::set_mirror_average)."""

    def __init__(self, model_dir, mirror_average=False):
        self.cfg = json.load(open(os.path.join(model_dir, "m3.json")))
        self.mirror_average = mirror_average
        l1 = self.cfg["level1"]
        self.l1 = Level1Runner(os.path.join(model_dir, l1["file"]), l1["input_size"], l1["crop_scale"],
                               l1["indices68"], mirror_average and l1.get("mirror_average", False))
        self.zones = {k: (z, _session(os.path.join(model_dir, z["file"]))) for k, z in self.cfg["zones"].items()}
        self.shape_prior = D.load_shape_prior(model_dir, self.cfg)

    def _zone(self, z, sess, gray, r0, r1, yaw, mirror):
        W, H = z["width"], z["height"]
        t = np.array(z["template"], float) * [W, H]
        if mirror:
            t[:, 0] = W - t[:, 0]
        A = D.similarity_map(r0, r1, t[0], t[1])
        if mirror:
            # patch u -> W - u: sample at A(W - u, v)
            A = A @ np.array([[-1.0, 0, W], [0, 1, 0], [0, 0, 1]])
        patch = D.zone_filter(z, D.sample(gray, A, W, H))

        def net(p, y):
            outs = sess.run(None, {"patch": (p / 255.0).astype(np.float32)[None, None],
                                   "yaw": y[None].astype(np.float32)})
            return outs[0].reshape(-1, 2).astype(np.float64), outs[-1][0].astype(np.float64)

        lm, g = net(patch, yaw)
        if self.mirror_average and z.get("mirror_average"):
            # M3_IO.md: the mirrored patch with the reversed yaw; points un-mirrored and averaged,
            # gesture probabilities averaged (returned as log-probabilities: softmax gives them back).
            lmf, gf = net(np.ascontiguousarray(patch[:, ::-1]), yaw[::-1])
            lm = 0.5 * (lm + unflip(lmf, z["indices68"]))
            if z.get("gestures"):
                g = np.log(0.5 * (softmax(g) + softmax(gf)))
        pts = D.apply(A, lm * [W, H])
        return pts, g, A

    def run(self, gray, box):
        pts32, yaw, face = self.l1.run(gray, box)
        out68 = np.zeros((68, 2))
        out68[self.cfg["level1"]["indices68"]] = pts32
        refs68 = out68.copy()  # level 1's points; the eye corners are replaced after the eye zone
        level1_68 = out68.copy()
        res = {"yaw_probs": yaw, "face_prob": face}
        # M3_IO.md: the eye zone runs first, and its eye corners replace level 1's as references; the
        # others run in name order, so where two give the same point the later name's wins.
        for name in sorted(self.zones, key=lambda n: (n != "eye", n)):
            z, sess = self.zones[name]
            r = z["ref68"]
            if name == "eye":
                gazes = {}
                for side, refs, idx, mirror in (("right", z["ref68"], z["indices68"], False),
                                                ("left", z["mirror_ref68"], z["mirror_indices68"], True)):
                    pts, g, A = self._zone(z, sess, gray, refs68[refs[0]], refs68[refs[1]], yaw, mirror)
                    out68[idx] = pts
                    phi = np.arctan2(A[1, 0], A[0, 0]) if not mirror else np.arctan2(-A[1, 0], -A[0, 0])
                    gx, gy = (-g[0], g[1]) if mirror else (g[0], g[1])
                    c, s = np.cos(phi), np.sin(phi)
                    v = np.array([c * gx - s * gy, s * gx + c * gy, g[2]])
                    gazes[side] = v / max(np.linalg.norm(v), 1e-9)
                comb = gazes["left"] + gazes["right"]
                res["gaze"] = {"left": gazes["left"], "right": gazes["right"],
                               "combined": comb / max(np.linalg.norm(comb), 1e-9)}
                corners = list(z["ref68"]) + list(z["mirror_ref68"])
                refs68[corners] = out68[corners]
            else:
                src = out68 if z.get("refs", "level1") == "merged" else refs68
                pts, g, _ = self._zone(z, sess, gray, src[r[0]], src[r[1]], yaw, False)
                # M3_IO.md: a landmarks-only zone may blend its points with level 1's or with the
                # points as they stood before it ran.
                idx = z["indices68"]
                if z.get("prior_weight"):
                    w, other = np.array(z["prior_weight"])[:, None], out68[idx]
                else:
                    w, other = np.array(z.get("level1_weight") or [0.0] * len(pts))[:, None], level1_68[idx]
                out68[idx] = (1 - w) * pts + w * other
                if z.get("gestures"):
                    res[name] = dict(zip(z["gestures"], softmax(g).tolist()))
        # M3_IO.md: the label-convention offset, along image x in units of the outer-eye-corner
        # distance of the merged points.
        out68 = D.with_x_offset(out68, self.cfg.get("x_offset_iod", 0.0))
        # M3_IO.md: the shape prior, on the offset points (it was fitted on them).
        if self.shape_prior is not None:
            out68 = D.apply_shape_prior(out68, *self.shape_prior)
        res["landmarks68"] = out68
        return res
