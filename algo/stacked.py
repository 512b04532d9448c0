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
neighbouring cars act in one call. Evaluation, which needs no gradient, acts with
``forward_distinct``: semantic views are mostly flat, so it multiplies only the distinct patches
and the distinct 3x3 windows of patches (an output ensemble's forward pass about twice as fast).

Weights stay in ``Policy``'s layout and names (``acc.conv1.weight`` and so on), with a leading
dimension for stacked weight sets, so gradients go to the learner unchanged. Pixel values stay
0..255 in the patches; the 1/255 scale of ``algo.policy.preprocess`` is folded into the first
layer's weights.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from algo.policy import CONV2_CELLS, VIEW_SHAPE, first_scalars, scale_scalars

HEADS = ("acc", "sa")
PATCH = 4  # first-layer kernel and stride [px]
GRID = VIEW_SHAPE[1] // PATCH  # 21 windows per side
PATCH_FEATURES = VIEW_SHAPE[0] * PATCH * PATCH  # 256: 16 planes x 4 x 4 pixels
PIXEL_SCALE = 1.0 / 255.0


def patch_bytes(views: torch.Tensor) -> torch.Tensor:
    """uint8 views [..., 16, 84, 84] (contiguous) to uint8 patches [..., 441, 256], ordered as ``patches``.

    The four pixels of a window row are contiguous, so they move as one 32-bit word (8x faster
    than moving bytes).
    """
    lead = views.shape[:-3]
    n = len(lead)
    words = views.contiguous().view(torch.int32)  # [..., 16, 84, 21]: 4 pixels per word
    words = words.reshape(*lead, VIEW_SHAPE[0], GRID, PATCH, GRID)  # plane, grid row, y, grid col
    ordered = words.permute(*range(n), n + 1, n + 3, n, n + 2).contiguous()  # grid row, grid col, plane, y
    return ordered.view(torch.uint8).view(*lead, GRID * GRID, PATCH_FEATURES)


def patches(views: torch.Tensor, out: torch.Tensor | None = None) -> torch.Tensor:
    """uint8 views [..., 16, 84, 84] (contiguous) to float patches [..., 441, 256] (values 0..255).

    Patch features are ordered (plane, row, column), the order of a flattened
    ``conv1.weight[out_channel]``; patches are ordered row-major over the 21x21 grid. One
    contiguous pass converts ``patch_bytes`` to float.
    """
    rows = patch_bytes(views)
    if out is None:
        out = torch.empty(rows.shape, dtype=torch.float32)
    out.copy_(rows.view(out.shape))
    return out


# one odd 64-bit weight per word of a row (a patch is 32 words of 8 bytes), fixed: the hash only groups rows
_WORD_WEIGHTS = torch.randint(-(1 << 62), 1 << 62, (PATCH_FEATURES // 8,), dtype=torch.int64,
                              generator=torch.Generator().manual_seed(0x5EED)) | 1


def _shift_right(x: torch.Tensor, bits: int) -> torch.Tensor:
    """Logical right shift of signed 64-bit integers (torch's ``>>`` copies the sign bit)."""
    return (x >> bits) & ((1 << (64 - bits)) - 1)


def _row_hashes(words: torch.Tensor) -> torch.Tensor:
    """One 64-bit hash per row of ``words`` [R, W] int64 (W <= 32): each word folded onto itself
    (w ^ w >>> 29, a bijection that brings high bytes down to low bits, which a product by an odd
    weight keeps), then a weighted sum. Two rows that differ in one word never share a hash; it
    only groups rows, which ``_group_rows`` then checks."""
    return ((words ^ _shift_right(words, 29)) * _WORD_WEIGHTS[: words.shape[1]]).sum(1)


def _group_rows(words: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Equal rows of ``words`` [R, W] int64: the distinct rows [U, W] and, for every row, the index
    of its distinct row [R]. Grouped by a 64-bit hash, then checked word for word; should two
    different rows ever share a hash, an exact (slower) grouping takes over, so the result never
    depends on the hash."""
    if len(words) == 0:
        return words, torch.zeros(0, dtype=torch.long)
    _, inverse = torch.unique(_row_hashes(words), return_inverse=True)
    first = torch.empty(int(inverse.max()) + 1, dtype=torch.long)
    first.scatter_(0, inverse, torch.arange(len(inverse)))  # one row of each group
    distinct = words[first]
    if not torch.equal(distinct[inverse], words):  # a hash collision: group exactly
        distinct, inverse = torch.unique(words, dim=0, return_inverse=True)
    return distinct, inverse


def unique_patches(views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The distinct patches of uint8 views [..., 16, 84, 84]: float rows [U, 256] (values 0..255)
    and, for every patch in order, the index of its row [prod(...) * 441].

    Semantic views are mostly flat: on hard about one patch in nine is distinct (half of all
    patches are zero; 'crossway bench policy' reports the share), so the first layer need only
    multiply those; each row of a matrix product is its own dot products.
    """
    distinct, inverse = _group_rows(patch_bytes(views).reshape(-1, PATCH_FEATURES).view(torch.int64))
    return distinct.view(torch.uint8).float(), inverse


def forward_full(views: torch.Tensor, scalars: torch.Tensor, params: dict[str, torch.Tensor],
                 first_layer: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """``forward_distinct``'s outputs with every patch multiplied (``conv1``, then ``after_conv1``):
    the faster form for one network of the paper's sizes, whose first layer is cheap."""
    b = params["acc.conv1.weight"].shape[0]
    pre1 = conv1(patches(views), *first_layer)
    pre1 = pre1.reshape(len(views), GRID * GRID, b, -1).permute(2, 0, 1, 3)  # [B, N, 441, 2*C1]
    return after_conv1(pre1, scalars.expand(b, *scalars.shape), params, squash=False)


def conv2_matrices(params: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Both heads' second layers for B weight sets as ``forward_distinct`` takes them: weights
    [2B, 9 * C1, C2] with inputs ordered (kernel row, kernel column, channel), biases [2B, 1, C2];
    group g = 2 * weight set + head."""
    w2 = torch.stack([params[f"{head}.conv2.weight"] for head in HEADS], dim=1)  # [B, 2, C2, C1, 3, 3]
    b2 = torch.stack([params[f"{head}.conv2.bias"] for head in HEADS], dim=1)  # [B, 2, C2]
    c2, c1 = w2.shape[2:4]
    weights = w2.permute(0, 1, 4, 5, 3, 2).reshape(-1, 9 * c1, c2).contiguous()
    return weights, b2.reshape(-1, 1, c2).contiguous()


def forward_distinct(views: torch.Tensor, scalars: torch.Tensor, params: dict[str, torch.Tensor],
                     first_layer: tuple[torch.Tensor, torch.Tensor],
                     second_layer: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Acting without gradients, for B weight sets on the same N cars: means before their tanh and
    values, each [B, N, 2] (acc, sa), as ``after_conv1(conv1(patches(views)), ...)`` with
    ``squash=False`` gives them.

    ``views`` uint8 [N, 16, 84, 84]; ``scalars`` [N, >= 2] as the simulator gives them;
    ``first_layer`` the first-layer matrix of every weight set, columns ordered (weight set, head,
    channel); ``second_layer`` from ``conv2_matrices``. The work follows what is distinct: the
    first layer multiplies the distinct patches (``unique_patches``), and the second the distinct
    3x3 windows of patches (about a third of them on hard), as one batched product per weight set
    and head. Both may sum their terms in another order than the full product and ``F.conv2d``
    (tests/test_algo.py bounds the difference; on session 39's machine the outputs were the same
    bits, and a hard evaluation gave the same episodes). Views in which
    most patches are distinct (noise, not a simulator's) take ``after_conv1`` after the first layer.
    """
    b = params["acc.conv1.weight"].shape[0]
    c1 = params["acc.conv1.weight"].shape[1]
    n = views.shape[0]
    rows, inverse = unique_patches(views)
    pre1 = torch.addmm(first_layer[1], rows, first_layer[0])  # [U1, B * 2 * C1]
    if 2 * len(rows) > len(inverse):  # views that are not mostly flat (noise): gathering windows would cost more
        pre1 = pre1[inverse].view(n, GRID * GRID, b, 2 * c1).permute(2, 0, 1, 3)
        return after_conv1(pre1, scalars.expand(b, *scalars.shape), params, squash=False)
    out1 = torch.relu_(pre1)
    # each second-layer output cell reads a 3x3 window (stride 2) of patches: [N * 100, 9] patch rows
    windows = inverse.view(n, GRID, GRID).unfold(1, 3, 2).unfold(2, 3, 2).reshape(-1, 9)
    distinct, inverse2 = _group_rows(windows)
    x = out1.index_select(0, distinct.flatten()).view(len(distinct), 9, 2 * b, c1)
    x = x.permute(2, 0, 1, 3).reshape(2 * b, len(distinct), 9 * c1)  # per group: (kernel row, column, channel)
    h2 = torch.relu_(torch.baddbmm(second_layer[1], x, second_layer[0]))  # [2B, U2, C2]
    h2 = h2[:, inverse2].view(b, 2, n, CONV2_CELLS, -1).transpose(3, 4).reshape(b, 2, n, -1)  # channel-major, as Policy
    read = params["acc.hidden.weight"].shape[-1] - h2.shape[-1]  # 2, or 3 with the standing-time input
    inputs = first_scalars(scale_scalars(scalars), read).expand(b, n, read)
    mus, values = [], []
    for h, head in enumerate(HEADS):
        h3 = torch.relu_(_linear(torch.cat([h2[:, h], inputs], dim=2), params[f"{head}.hidden.weight"],
                                 params[f"{head}.hidden.bias"]))
        mus.append(_linear(h3, params[f"{head}.mu.weight"], params[f"{head}.mu.bias"]))
        values.append(_linear(h3, params[f"{head}.value.weight"], params[f"{head}.value.bias"]))
    return torch.cat(mus, dim=2), torch.cat(values, dim=2)


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
