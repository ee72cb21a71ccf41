"""M3 network definitions (thesis Fig. 3.5-3.9): level 1 on the face crop, level-2 zone nets.

Plain 3x3 convolutions + BatchNorm (folded by tract at load) + ReLU, then fully connected layers.
A trunk is written as a spec string, one layer per item: "16s" = 16 channels, stride 2; "16p" =
stride 1 then 2x2 max pooling (the thesis' layout); "16c" = stride 1, same size. Strided layers are
what tract runs fast: measured with tract on this machine's CPU, the same channels cost 4.6x less
time as "s" than as "p" (2x2 max pooling and full-resolution first layers dominate the "p" nets).
"""
import torch
import torch.nn as nn


def parse_trunk(spec):
    """"16s-32s-48c" -> [(16, "s"), (32, "s"), (48, "c")]; a bare number means "p"."""
    layers = []
    for item in spec.split("-"):
        mode = item[-1] if item[-1] in "spc" else "p"
        layers.append((int(item.rstrip("spc")), mode))
    return layers


def out_side(n, spec):
    """Side of the trunk's output map for an input side n: a stride-2 3x3 convolution with padding 1
    gives ceil(n / 2), a 2x2 max-pool floor(n / 2), so sides need not be multiples of 16."""
    for _, mode in parse_trunk(spec):
        n = (n + 1) // 2 if mode == "s" else n // 2 if mode == "p" else n
    return n


def trunk(spec):
    layers, cin = [], 1
    for c, mode in parse_trunk(spec):
        layers += [nn.Conv2d(cin, c, 3, stride=2 if mode == "s" else 1, padding=1, bias=False),
                   nn.BatchNorm2d(c), nn.ReLU(inplace=True)]
        if mode == "p":
            layers.append(nn.MaxPool2d(2))
        cin = c
    return nn.Sequential(*layers)


def last_channels(spec):
    return parse_trunk(spec)[-1][0]


class Level1(nn.Module):
    """Face crop (1 x S x S) -> 32 landmarks (crop units), 5 yaw logits, face logit."""

    def __init__(self, size=64, spec="16s-32s-48s-64s", hidden=128, n_points=32):
        super().__init__()
        self.trunk = trunk(spec)
        r = out_side(size, spec)
        self.fc = nn.Sequential(nn.Flatten(), nn.Linear(last_channels(spec) * r * r, hidden), nn.ReLU(inplace=True))
        self.landmarks = nn.Linear(hidden, 2 * n_points)
        self.yaw = nn.Linear(hidden, 5)
        self.face = nn.Linear(hidden, 1)
        with torch.no_grad():
            self.landmarks.bias.fill_(0.5)

    def forward(self, image):
        h = self.fc(self.trunk(image))
        return self.landmarks(h), self.yaw(h), self.face(h)


class Level2(nn.Module):
    """Zone patch (1 x H x W) + level-1 yaw probabilities (5) -> zone landmarks (patch units) and
    gesture logits or a gaze vector. The yaw enters in an extra fully connected layer (thesis)."""

    def __init__(self, width, height, n_points, n_gestures=0, gaze=False, spec="8s-16s-32s-48s", hidden=64,
                 n_scores=0):
        super().__init__()
        self.trunk = trunk(spec)
        features = last_channels(spec) * out_side(width, spec) * out_side(height, spec)
        self.fc1 = nn.Sequential(nn.Flatten(), nn.Linear(features, hidden),
                                 nn.ReLU(inplace=True))
        self.fc2 = nn.Sequential(nn.Linear(hidden + 5, hidden), nn.ReLU(inplace=True))
        self.landmarks = nn.Linear(hidden, 2 * n_points)
        self.gestures = nn.Linear(hidden, n_gestures) if n_gestures else None
        self.gaze = nn.Linear(hidden, 3) if gaze else None
        # Training-only head (not in forward, so not exported): the teacher's continuous gesture
        # scores, a denser signal for the shared features than the rare thresholded classes.
        self.scores = nn.Linear(hidden, n_scores) if n_scores else None
        with torch.no_grad():
            self.landmarks.bias.fill_(0.5)
            if self.gaze is not None:
                self.gaze.bias.copy_(torch.tensor([0.0, 0.0, -1.0]))

    def features(self, patch, yaw):
        return self.fc2(torch.cat([self.fc1(self.trunk(patch)), yaw], dim=1))

    def heads(self, h):
        if self.gestures is not None:
            return self.landmarks(h), self.gestures(h)
        if self.gaze is not None:
            return self.landmarks(h), self.gaze(h)
        return (self.landmarks(h),)

    def forward(self, patch, yaw):
        return self.heads(self.features(patch, yaw))


def n_params(m):
    return sum(p.numel() for p in m.parameters())
