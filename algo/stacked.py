"""The policy network as plain matrix products, for an actor that keeps its acting work.

``algo.policy.Policy`` is the reference: ``nn.Conv2d`` layers, one set of weights. An actor needs
more: every car acts with its own local weights (paper, "Related works": each agent updates a
local copy), and the local update every ``update_interval`` steps needs the gradient over the
segment just driven. Computing that update by running the whole network again over the segment
would repeat the most expensive part of the acting work. This module instead

- lays each observation out once as the first layer's patches: the 4x4 stride-4 convolution over
  84x84 planes has non-overlapping windows, so it is one matrix product ``[441, 256] @ [256, 16]``
  per head (``patches``, ``conv1``);
- keeps that layer's output (pre-activation) from acting, for both heads;
- at update time replays only the cheap rest of the network (the 3x3 stride-2 convolution and
  the fully connected layers, about a fifth of the forward cost) with autograd on top of the kept
  outputs, and gets the first layer's weight gradient as one product of the kept patches and the
  gradient that reaches the kept outputs (``conv1_gradients``).

The weights stay in ``Policy``'s layout and names (``acc.conv1.weight`` and so on), with an
optional leading dimension for stacked weight sets, so gradients go to the learner unchanged.
Pixel values stay 0..255 in the patches; the 1/255 scale of ``algo.policy.preprocess`` is folded
into the first layer's weights.
"""

from __future__ import annotations

import torch

from algo.policy import SPEED_SCALE, VIEW_SHAPE

HEADS = ("acc", "sa")
PATCH = 4  # first-layer kernel and stride [px]
GRID = VIEW_SHAPE[1] // PATCH  # 21 windows per side
PATCH_FEATURES = VIEW_SHAPE[0] * PATCH * PATCH  # 256: 16 planes x 4 x 4 pixels
PIXEL_SCALE = 1.0 / 255.0


def patches(views: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """uint8 views [..., 16, 84, 84] to float patches [..., 441, 256] (values 0..255).

    Patch features are ordered (plane, row, column), the order of a flattened
    ``conv1.weight[out_channel]``; patches are ordered row-major over the 21x21 grid.
    """
    lead = views.shape[:-3]
    windows = views.reshape(*lead, VIEW_SHAPE[0], GRID, PATCH, GRID, PATCH)
    n = len(lead)
    windows = windows.permute(*range(n), n + 1, n + 3, n, n + 2, n + 4)  # grid row, grid col, plane, y, x
    if out is None:
        out = torch.empty(*lead, GRID * GRID, PATCH_FEATURES, dtype=torch.float32)
    out.view(*lead, GRID, GRID, VIEW_SHAPE[0], PATCH, PATCH).copy_(windows)
    return out


def conv1(patch_rows: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor,
          out: torch.Tensor | None = None) -> torch.Tensor:
    """First layer's pre-activation [..., 441, C1] from patches [..., 441, 256] of one weight set."""
    matrix = weight.reshape(weight.shape[0], PATCH_FEATURES).t() * PIXEL_SCALE
    flat = patch_rows.reshape(-1, PATCH_FEATURES)
    if out is None:
        return torch.addmm(bias, flat, matrix).reshape(*patch_rows.shape[:-1], weight.shape[0])
    torch.addmm(bias, flat, matrix, out=out.view(-1, weight.shape[0]))
    return out


def conv1_gradients(patch_rows: torch.Tensor, grad_pre: torch.Tensor,
                    weight_shape: torch.Size) -> tuple[torch.Tensor, torch.Tensor]:
    """Gradients of the first layer's weight and bias from its input patches [N, 441, 256] and
    the gradient at its pre-activation output [N, 441, C1]."""
    g = grad_pre.reshape(-1, grad_pre.shape[-1])
    weight = (g.t() @ patch_rows.reshape(-1, PATCH_FEATURES)).mul_(PIXEL_SCALE)
    return weight.reshape(weight_shape), g.sum(0)


def _linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """x [B, N, in] with weight [B, out, in] and bias [B, out] (B weight sets)."""
    return torch.baddbmm(bias.unsqueeze(1), x, weight.transpose(1, 2))


def head_after_conv1(pre1: torch.Tensor, scalars: torch.Tensor, params: dict[str, torch.Tensor],
                     head: str) -> tuple[torch.Tensor, torch.Tensor]:
    """The rest of one sub-module, from the first layer's pre-activation, for B weight sets.

    ``pre1`` [B, N, 441, C1], ``scalars`` [B, N, 2] in m/s, ``params`` with leading dimension B.
    Returns the Gaussian mean and the value, each [B, N]; the same function as
    ``algo.policy.SubModule.forward`` after its first convolution.
    """
    b, n = pre1.shape[:2]
    c1 = pre1.shape[-1]
    h1 = torch.relu(pre1).reshape(b, n, GRID, GRID, c1)
    # 3x3 stride-2 windows [B, N, 10, 10, C1, 3, 3], features in conv2.weight's (in, y, x) order
    windows = h1.unfold(2, 3, 2).unfold(3, 3, 2)
    side = windows.shape[2]
    rows = windows.reshape(b, n * side * side, c1 * 9)
    w2 = params[f"{head}.conv2.weight"]
    h2 = torch.relu(_linear(rows, w2.reshape(b, w2.shape[1], c1 * 9), params[f"{head}.conv2.bias"]))
    # [B, N*100, C2] -> channel-major [B, N, C2*100], the order of Policy's flatten
    features = h2.reshape(b, n, side * side, w2.shape[1]).transpose(2, 3).reshape(b, n, -1)
    x = torch.cat([features, scalars / SPEED_SCALE], dim=2)
    h3 = torch.relu(_linear(x, params[f"{head}.hidden.weight"], params[f"{head}.hidden.bias"]))
    mu = torch.tanh(_linear(h3, params[f"{head}.mu.weight"], params[f"{head}.mu.bias"])).squeeze(2)
    value = _linear(h3, params[f"{head}.value.weight"], params[f"{head}.value.bias"]).squeeze(2)
    return mu, value
