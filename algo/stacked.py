"""The policy network for an actor: many weight sets at once, and acting work kept for updates.

``algo.policy.Policy`` is the reference: ``nn.Conv2d`` layers, one set of weights. An actor needs
more: every car acts with its own local weights (paper, "Related works": each agent updates a
local copy), and the local update every ``update_interval`` steps needs the gradient over the
segment just driven. Running the whole network again over the segment would repeat the most
expensive part of the acting work, the first layer (about 70% of a forward pass). This module
instead

- lays each observation out once as the first layer's patches: the 4x4 stride-4 convolution over
  84x84 planes has non-overlapping windows, so for both heads it is one matrix product
  ``[441, 256] @ [256, 2 x 16]`` (``patches``, ``first_layer_matrix``, ``conv1``);
- keeps that layer's output (pre-activation, both heads) from acting;
- at update time replays only the cheap rest of the network with autograd on top of the kept
  outputs (``after_conv1``), and gets the first layer's weight gradient as one product of the
  kept patches and the gradient that reaches the kept outputs (``conv1_gradients``).

``after_conv1`` runs B weight sets at once (a grouped convolution, batched matrix products), so
neighbouring cars act in one call. Weights stay in ``Policy``'s layout and names
(``acc.conv1.weight`` and so on), with a leading dimension for stacked weight sets, so gradients
go to the learner unchanged. Pixel values stay 0..255 in the patches; the 1/255 scale of
``algo.policy.preprocess`` is folded into the first layer's weights.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from algo.policy import VIEW_SHAPE, first_scalars, scale_scalars

HEADS = ("acc", "sa")
PATCH = 4  # first-layer kernel and stride [px]
GRID = VIEW_SHAPE[1] // PATCH  # 21 windows per side
PATCH_FEATURES = VIEW_SHAPE[0] * PATCH * PATCH  # 256: 16 planes x 4 x 4 pixels
PIXEL_SCALE = 1.0 / 255.0


def patches(views: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """uint8 views [..., 16, 84, 84] (contiguous) to float patches [..., 441, 256] (values 0..255).

    Patch features are ordered (plane, row, column), the order of a flattened
    ``conv1.weight[out_channel]``; patches are ordered row-major over the 21x21 grid. The four
    pixels of a window row are contiguous, so they move as one 32-bit word (8x faster than
    moving bytes), then one contiguous pass converts to float.
    """
    lead = views.shape[:-3]
    n = len(lead)
    words = views.contiguous().view(torch.int32)  # [..., 16, 84, 21]: 4 pixels per word
    words = words.reshape(*lead, VIEW_SHAPE[0], GRID, PATCH, GRID)  # plane, grid row, y, grid col
    ordered = words.permute(*range(n), n + 1, n + 3, n, n + 2).contiguous()  # grid row, grid col, plane, y
    if out is None:
        out = torch.empty(*lead, GRID * GRID, PATCH_FEATURES, dtype=torch.float32)
    out.copy_(ordered.view(torch.uint8).view(out.shape))
    return out


def first_layer_matrix(params: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Both heads' first layers as one matrix [256, 2*C1] (1/255 folded in) and bias [2*C1]."""
    weights = [params[f"{head}.conv1.weight"] for head in HEADS]
    matrix = torch.cat([w.reshape(w.shape[0], PATCH_FEATURES) for w in weights]).t() * PIXEL_SCALE
    bias = torch.cat([params[f"{head}.conv1.bias"] for head in HEADS])
    return matrix, bias


def conv1(patch_rows: torch.Tensor, matrix: torch.Tensor, bias: torch.Tensor,
          out: torch.Tensor | None = None) -> torch.Tensor:
    """Both heads' first-layer pre-activation [..., 441, 2*C1] from patches [..., 441, 256]."""
    flat = patch_rows.reshape(-1, PATCH_FEATURES)
    if out is None:
        return torch.addmm(bias, flat, matrix).reshape(*patch_rows.shape[:-1], matrix.shape[1])
    torch.addmm(bias, flat, matrix, out=out.view(-1, matrix.shape[1]))
    return out


def conv1_gradients(patch_rows: torch.Tensor, grad_pre: torch.Tensor,
                    weight_shape: torch.Size) -> dict[str, torch.Tensor]:
    """Both heads' first-layer weight and bias gradients from the input patches [N, 441, 256]
    and the gradient at the pre-activation output [N, 441, 2*C1]."""
    g = grad_pre.reshape(-1, grad_pre.shape[-1])
    weight = (g.t() @ patch_rows.reshape(-1, PATCH_FEATURES)).mul_(PIXEL_SCALE)  # [2*C1, 256]
    bias = g.sum(0)
    c1 = weight_shape[0]
    grads = {}
    for h, head in enumerate(HEADS):
        grads[f"{head}.conv1.weight"] = weight[h * c1:(h + 1) * c1].reshape(weight_shape)
        grads[f"{head}.conv1.bias"] = bias[h * c1:(h + 1) * c1]
    return grads


def after_conv1(pre1: torch.Tensor, scalars: torch.Tensor, params: dict[str, torch.Tensor],
                squash: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
    """The rest of both sub-modules from the first layer's pre-activation, for B weight sets.

    ``pre1`` [B, N, 441, 2*C1] (acc channels first), ``scalars`` [B, N, >= 2] as the simulator gives
    them (m/s, s; the network reads as many as its hidden layer takes), ``params``
    with leading dimension B. Returns Gaussian means and values, each [B, N, 2] (acc, sa): the
    same function as ``algo.policy.Policy`` after its first convolutions; with ``squash`` False
    the means before their tanh.
    """
    b, n = pre1.shape[:2]
    channels = pre1.shape[-1]  # 2*C1
    # NCHW with one group of C1 channels per (weight set, head): [N, B*2*C1, 21, 21]
    x = torch.relu(pre1).reshape(b, n, GRID, GRID, channels).permute(1, 0, 4, 2, 3)
    x = x.reshape(n, b * channels, GRID, GRID)
    w2 = torch.stack([params[f"{head}.conv2.weight"] for head in HEADS], dim=1)  # [B, 2, C2, C1, 3, 3]
    b2 = torch.stack([params[f"{head}.conv2.bias"] for head in HEADS], dim=1)  # [B, 2, C2]
    h2 = torch.relu(F.conv2d(x, w2.reshape(-1, *w2.shape[3:]), b2.reshape(-1), stride=2, groups=2 * b))
    h2 = h2.reshape(n, b, 2, -1)  # per head, channel-major: the order of Policy's flatten
    read = params["acc.hidden.weight"].shape[-1] - h2.shape[-1]  # 2, or 3 with the standing-time input
    inputs = first_scalars(scale_scalars(scalars), read)
    mus, values = [], []
    for h, head in enumerate(HEADS):
        x3 = torch.cat([h2[:, :, h].transpose(0, 1), inputs], dim=2)  # [B, N, C2*100 + 2 or 3]
        h3 = torch.relu(_linear(x3, params[f"{head}.hidden.weight"], params[f"{head}.hidden.bias"]))
        mu = _linear(h3, params[f"{head}.mu.weight"], params[f"{head}.mu.bias"])
        mus.append(torch.tanh(mu) if squash else mu)
        values.append(_linear(h3, params[f"{head}.value.weight"], params[f"{head}.value.bias"]))
    return torch.cat(mus, dim=2), torch.cat(values, dim=2)


def _linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """x [B, N, in] with weight [B, out, in] and bias [B, out] (B weight sets)."""
    return torch.baddbmm(bias.unsqueeze(1), x, weight.transpose(1, 2))
