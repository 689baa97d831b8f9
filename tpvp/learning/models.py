"""The two networks, scaled down from the published ones to train on 2 CPU cores (docs/learning.md#networks).

* :class:`ViewSetNet` (MA-SCVP layout): 32^3 grid -> stem -> the view state tiled into one 16^3
  channel -> three residual blocks (two groups of ``units`` [Conv3d, BatchNorm, LeakyReLU(0.1)],
  group 2 + group 1) at 8^3, 4^3, 2^3 -> head on the last map and max-pooled earlier maps (dense
  skips) -> FC with dropout 0.5 -> 32 logits (sigmoid = "this view belongs to the minimum set").
  The published net runs its first block at 16^3 with widths 32..256 (20 M parameters, 6 GMAC);
  here the stem and the first downsampling are strided convolutions and the widths are
  ``widths`` (defaults: 0.9 M parameters).
* :class:`GainNet` (PC-NBV layout): the accumulated cloud (normalised: centroid, max radius) ->
  dense EdgeConv stages on k-nearest neighbours in feature space -> global max feature and the view
  state tiled to every point -> self-attention over the points (learned gate, zero at start) ->
  point MLP -> global max -> FC -> one coverage gain per view.

Both take plain tensors and hold their architecture in ``spec`` (a dict of ints) so that a weight
file can rebuild them (:mod:`tpvp.learning.weights`).
"""

from __future__ import annotations

import torch
from torch import nn

VIEWS = 32


def _unit(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv3d(c_in, c_out, 3, 1, 1, bias=False), nn.BatchNorm3d(c_out), nn.LeakyReLU(0.1))


class _ResidualBlock(nn.Module):
    def __init__(self, c_in: int, c_out: int, units: int):
        super().__init__()
        self.group1 = nn.Sequential(_unit(c_in, c_out), *[_unit(c_out, c_out) for _ in range(units - 1)])
        self.group2 = nn.Sequential(*[_unit(c_out, c_out) for _ in range(units)])
        self.act = nn.LeakyReLU(0.1)

    def forward(self, x):
        first = self.group1(x)
        return self.act(self.group2(first) + first)


class ViewSetNet(nn.Module):
    """MA-SCVP-style view-set network: ``(grid (B, 32, 32, 32), view state (B, 32)) -> logits (B, 32)``."""

    def __init__(self, widths=(8, 16, 32, 64), units: int = 2, head=(256, 128, 64), views: int = VIEWS):
        super().__init__()
        if (16 ** 3) % views:
            raise ValueError(f"the view state is tiled into a 16^3 map: {views} views do not divide 4096")
        self.spec = {"widths": [int(w) for w in widths], "units": int(units), "head": [int(h) for h in head],
                     "views": int(views)}
        c0, c1, c2, c3 = widths
        self.views = views
        self.stem = nn.Conv3d(1, c0, 2, 2)  # 32^3 -> 16^3
        self.down0 = nn.Conv3d(c0 + 1, c1, 2, 2)  # 16^3 -> 8^3 (the view-state channel included)
        self.block1 = _ResidualBlock(c1, c1, units)
        self.down1 = nn.Conv3d(c1, c2, 2, 2)
        self.block2 = _ResidualBlock(c2, c2, units)
        self.down2 = nn.Conv3d(c2, c3, 2, 2)
        self.block3 = _ResidualBlock(c3, c3, units)
        features = (c3 + c2 + c1 + c0 + 1) * 8
        layers = []
        for width in head:
            layers += [nn.Linear(features, width), nn.LeakyReLU(0.1), nn.Dropout(0.5)]
            features = width
        self.head = nn.Sequential(*layers, nn.Linear(features, views))

    def forward(self, grid: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        x = self.stem(grid.unsqueeze(1))
        n = x.shape[0]
        # MA-SCVP's injection: cell p of the 16^3 map holds state[p mod views]
        tiled = state.to(x.dtype).repeat(1, 16 ** 3 // self.views).reshape(n, 1, 16, 16, 16)
        x0 = torch.cat([x, tiled], 1)
        x1 = self.block1(self.down0(x0))
        x2 = self.block2(self.down1(x1))
        x3 = self.block3(self.down2(x2))
        pool = nn.functional.max_pool3d
        features = torch.cat([x3, pool(x2, 2), pool(x1, 4), pool(x0, 8)], 1).flatten(1)
        return self.head(features)


def _knn(features: torch.Tensor, k: int) -> torch.Tensor:
    """Indices (B, N, k) of each point's k nearest neighbours in feature space (itself included)."""
    distance = torch.cdist(features, features)
    return distance.topk(k, dim=-1, largest=False).indices


class _DenseEdgeConv(nn.Module):
    """PU-GAN's dense EdgeConv: edge features ``[x_j - x_i, x_i]`` -> ``layers`` dense 1x1 layers of
    ``growth`` channels each (layer i also reads layers < i) -> max over the k neighbours; output =
    input + layers x growth channels. The edge term of each layer, ``W [x_j - x_i, x_i]``, is
    computed as ``A x_j + B x_i`` on the points and then gathered: the same function without
    building the (N, k, 2C) edge tensor."""

    def __init__(self, c_in: int, growth: int, layers: int, k: int):
        super().__init__()
        self.k = k
        self.neighbour = nn.ModuleList(nn.Linear(c_in, growth, bias=False) for _ in range(layers))
        self.centre = nn.ModuleList(nn.Linear(c_in, growth) for _ in range(layers))
        self.dense = nn.ModuleList(nn.Linear(i * growth, growth, bias=False) if i else None for i in range(layers))

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (B, C, N)
        b, c, n = x.shape
        points = x.transpose(1, 2)  # (B, N, C)
        idx = _knn(points, self.k)
        flat = (idx + torch.arange(b, device=x.device).view(b, 1, 1) * n).reshape(-1)
        outs = []
        for i, (neighbour, centre, dense) in enumerate(zip(self.neighbour, self.centre, self.dense)):
            projected = neighbour(points)
            h = projected.reshape(b * n, -1)[flat].reshape(b, n, self.k, -1) + centre(points).unsqueeze(2)
            if dense is not None:
                h = h + dense(torch.cat(outs, -1))
            outs.append(torch.relu(h) if i < len(self.neighbour) - 1 else h)
        grown = torch.cat(outs, -1).amax(dim=2)  # (B, N, layers x growth)
        return torch.cat([x, grown.transpose(1, 2)], 1)


class GainNet(nn.Module):
    """PC-NBV-style gain network: ``(cloud (B, N, 3), view state (B, 32)) -> predicted gain (B, 32)``."""

    def __init__(self, stem: int = 16, growth: int = 12, layers: int = 2, stages: int = 2, k: int = 16,
                 code: int = 128, head=(128, 64), views: int = VIEWS):
        super().__init__()
        self.spec = {"stem": int(stem), "growth": int(growth), "layers": int(layers), "stages": int(stages),
                     "k": int(k), "code": int(code), "head": [int(h) for h in head], "views": int(views)}
        self.stem = nn.Conv1d(3, stem, 1)
        stages_list, transitions = [], []
        channels = stem
        for i in range(stages):
            if i:
                transitions.append(nn.Sequential(nn.Conv1d(channels, stem, 1), nn.ReLU()))
                stages_list.append(_DenseEdgeConv(stem, growth, layers, k))
                channels = channels + stem + layers * growth
            else:
                transitions.append(nn.Identity())
                stages_list.append(_DenseEdgeConv(stem, growth, layers, k))
                channels = stem + layers * growth
        self.transitions = nn.ModuleList(transitions)
        self.stages = nn.ModuleList(stages_list)
        self.norm = nn.BatchNorm1d(channels)
        joint = 2 * channels + views
        self.query = nn.Conv1d(joint, max(joint // 4, 1), 1)
        self.key = nn.Conv1d(joint, max(joint // 4, 1), 1)
        self.value = nn.Conv1d(joint, joint, 1)
        self.gamma = nn.Parameter(torch.zeros(1))
        self.attention_norm = nn.BatchNorm1d(joint)
        self.point_mlp = nn.Sequential(nn.Conv1d(joint, code, 1), nn.BatchNorm1d(code), nn.ReLU(),
                                       nn.Conv1d(code, code, 1), nn.BatchNorm1d(code))
        layers_head, features = [], code
        for width in head:
            layers_head += [nn.Linear(features, width), nn.BatchNorm1d(width), nn.ReLU()]
            features = width
        self.head = nn.Sequential(*layers_head, nn.Linear(features, views))

    @staticmethod
    def normalise(cloud: torch.Tensor) -> torch.Tensor:
        centred = cloud - cloud.mean(dim=1, keepdim=True)
        radius = centred.norm(dim=-1).amax(dim=1).clamp_min(1e-9)
        return centred / radius[:, None, None]

    def forward(self, cloud: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        x = self.stem(self.normalise(cloud).transpose(1, 2))  # (B, C, N)
        features = None
        for transition, stage in zip(self.transitions, self.stages):
            out = stage(transition(x if features is None else features))
            features = out if features is None else torch.cat([features, out], 1)
        features = self.norm(features)
        n = features.shape[-1]
        pooled = features.amax(dim=-1, keepdim=True).expand(-1, -1, n)
        tiled = state.to(features.dtype).unsqueeze(-1).expand(-1, -1, n)
        joint = torch.relu(torch.cat([features, pooled, tiled], 1))
        q, k, v = self.query(joint), self.key(joint), self.value(joint)
        weights = torch.softmax(torch.bmm(q.transpose(1, 2), k), dim=-1)  # (B, N, N)
        joint = self.attention_norm(joint + self.gamma * torch.bmm(v, weights.transpose(1, 2)))
        code = self.point_mlp(joint).amax(dim=-1)
        return self.head(code)


ARCHITECTURES = {"ma-scvp": ViewSetNet, "pc-nbv": GainNet}


def build_model(kind: str, spec: dict | None = None) -> nn.Module:
    """A fresh network of ``kind`` (``ma-scvp`` or ``pc-nbv``) with ``spec`` (its defaults when None)."""
    return ARCHITECTURES[kind](**(spec or {}))


def parameter_count(model: nn.Module) -> int:
    return int(sum(p.numel() for p in model.parameters()))
