"""M3 network definitions (thesis Fig. 3.5-3.9): level 1 on the face crop, level-2 zone nets.

Plain 3x3 convolutions + BatchNorm (folded by tract at load) + ReLU + 2x2 max pooling, then fully
connected layers: shapes tract runs well on a phone CPU. Sizes keep all four nets under 1.5 MB of
float32 weights together.
"""
import torch
import torch.nn as nn


def trunk(channels):
    layers, cin = [], 1
    for c in channels:
        layers += [nn.Conv2d(cin, c, 3, padding=1, bias=False), nn.BatchNorm2d(c), nn.ReLU(inplace=True),
                   nn.MaxPool2d(2)]
        cin = c
    return nn.Sequential(*layers)


class Level1(nn.Module):
    """Face crop (1 x S x S) -> 32 landmarks (crop units), 5 yaw logits, face logit."""

    def __init__(self, size=64, channels=(8, 16, 32, 64), hidden=96, n_points=32):
        super().__init__()
        self.trunk = trunk(channels)
        r = size // 2 ** len(channels)
        self.fc = nn.Sequential(nn.Flatten(), nn.Linear(channels[-1] * r * r, hidden), nn.ReLU(inplace=True))
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

    def __init__(self, width, height, n_points, n_gestures=0, gaze=False, channels=(8, 16, 32, 48),
                 hidden=64):
        super().__init__()
        self.trunk = trunk(channels)
        k = 2 ** len(channels)
        self.fc1 = nn.Sequential(nn.Flatten(), nn.Linear(channels[-1] * (width // k) * (height // k), hidden),
                                 nn.ReLU(inplace=True))
        self.fc2 = nn.Sequential(nn.Linear(hidden + 5, hidden), nn.ReLU(inplace=True))
        self.landmarks = nn.Linear(hidden, 2 * n_points)
        self.gestures = nn.Linear(hidden, n_gestures) if n_gestures else None
        self.gaze = nn.Linear(hidden, 3) if gaze else None
        with torch.no_grad():
            self.landmarks.bias.fill_(0.5)
            if self.gaze is not None:
                self.gaze.bias.copy_(torch.tensor([0.0, 0.0, -1.0]))

    def forward(self, patch, yaw):
        h = self.fc2(torch.cat([self.fc1(self.trunk(patch)), yaw], dim=1))
        if self.gestures is not None:
            return self.landmarks(h), self.gestures(h)
        if self.gaze is not None:
            return self.landmarks(h), self.gaze(h)
        return (self.landmarks(h),)


def n_params(m):
    return sum(p.numel() for p in m.parameters())
