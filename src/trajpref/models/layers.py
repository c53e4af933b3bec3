"""Building blocks shared by the denoiser, the generator and the critic."""

from __future__ import annotations

import math

import torch
from torch import nn

from trajpref.errors import ConfigError


def mlp(
    sizes: list[int], act: type[nn.Module] = nn.SiLU, final_act: bool = False,
    dropout: float = 0.0,
) -> nn.Sequential:  # fmt: skip
    """Linear layers with ``act`` between them (and after the last when ``final_act``); with
    ``dropout`` > 0, each hidden activation is followed by dropout, in the activation's slot,
    so the parameter names are those of the same MLP without dropout."""
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2 and dropout > 0:
            layers.append(nn.Sequential(act(), nn.Dropout(dropout)))
        elif i < len(sizes) - 2 or final_act:
            layers.append(act())
    return nn.Sequential(*layers)


class ResidualBlock(nn.Module):
    """Pre-norm residual MLP block with FiLM conditioning: x + f(LN(x) * (1 + g) + b)."""

    def __init__(self, width: int, cond: int):
        super().__init__()
        self.norm = nn.LayerNorm(width)
        self.film = nn.Linear(cond, 2 * width)
        self.ff = nn.Sequential(nn.Linear(width, width), nn.SiLU(), nn.Linear(width, width))

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        gain, bias = self.film(c).chunk(2, -1)  # [..., W] each
        return x + self.ff(self.norm(x) * (1 + gain) + bias)


def timestep_embedding(s: torch.Tensor, dim: int, max_period: float = 1000.0) -> torch.Tensor:
    """Sinusoidal embedding of integer steps: s [...] -> [..., dim], in float32 (also where a
    host has set ``torch.set_default_dtype(torch.float64)``)."""
    half = dim // 2
    steps = torch.arange(half, dtype=torch.float32, device=s.device)  # float32 whatever the default
    freqs = torch.exp(-math.log(max_period) * steps / half)  # [D/2]
    args = s.float()[..., None] * freqs  # [..., D/2]
    return torch.cat([torch.cos(args), torch.sin(args)], -1)


class SocialAttention(nn.Module):
    """Attention across the agents of one scene, with pairwise geometry on keys and values.

    Agent i attends to agent j (itself included) with logits q_i . (k_j + e_ij) and reads
    v_j + e_ij, where e_ij embeds j's position and velocity relative to i. Works on the padded
    per-scene layout [B, P, H]; ``mask`` [B, P] hides padding, so no agent sees another scene,
    and a pair mask [B, P, P] (padding and a neighbour radius in one) hides j from i alone.
    With ``dropout`` > 0, the attention's and the feed-forward's residual updates are dropped
    during training (a transformer's residual dropout; no parameters, so the names stay).
    """

    def __init__(self, hidden: int, heads: int, edge_features: int = 4, dropout: float = 0.0):
        super().__init__()
        if hidden % heads:
            raise ConfigError("hidden must be divisible by heads")
        self.heads = heads
        self.drop = nn.Dropout(dropout) if dropout > 0 else nn.Identity()
        self.qkv = nn.Linear(hidden, 3 * hidden)
        self.edge = mlp([edge_features, hidden, hidden])
        self.out = nn.Linear(hidden, hidden)
        self.norm1 = nn.LayerNorm(hidden)
        self.norm2 = nn.LayerNorm(hidden)
        self.ff = mlp([hidden, 2 * hidden, hidden])

    def forward(self, h: torch.Tensor, geom: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """h [B, P, H], geom [B, P, P, F] (features of j relative to i), mask [B, P] (True:
        j is an agent; every agent attends to all of them) or [B, P(i), P(j)] (True: i
        attends to j; each row needs a True, e.g. i itself, or its output is NaN).

        The edge embedding e_ij = W2 s_ij + b2, s_ij = SiLU(W1 g_ij + b1), is never formed:
        W2 is folded into the query for the logits (q_i . W2 s_ij = (W2^T q_i) . s_ij) and
        applied once per agent after the attention for the values (the weights over j sum to
        one), so the per-pair work is at width C of s_ij with no H x C product per pair. Same
        parameters and outputs as the direct formula (``direct_social_attention``); a layer
        alone runs 1.2-1.8x faster on the CPU, whole training steps up to about 1.2x
        (docs/pretraining.md, "oneDNN's kernel cache, and attention without per-pair edge
        embeddings")."""
        b, p, hid = h.shape
        nh, d = self.heads, hid // self.heads
        q, k, v = self.qkv(self.norm1(h)).view(b, p, 3, nh, d).unbind(2)  # [B, P, nh, d] each
        first, act, second = self.edge
        s = act(first(geom))  # [B, P(i), P(j), C]
        w2 = second.weight.view(nh, d, -1).to(q.dtype)  # [nh, d, C]: each head's rows of W2
        b2 = second.bias.view(nh, d).to(q.dtype)  # [nh, d]
        u = torch.einsum("bihd,hdc->bihc", q, w2)  # [B, P, nh, C]: W2^T q_i per head
        logits = (
            torch.einsum("bihd,bjhd->bijh", q, k)  # q_i . k_j
            + torch.einsum("bihc,bijc->bijh", u, s)  # q_i . W2 s_ij
            + (q * b2).sum(-1)[:, :, None]  # q_i . b2, [B, P(i), 1, nh]
        ) / d**0.5  # [B, P(i), P(j), nh]
        logits = logits.masked_fill(~_pair_mask(mask)[..., None], float("-inf"))
        att = torch.softmax(logits, dim=2)  # over j
        read = torch.einsum("bijh,bijc->bihc", att, s)  # [B, P, nh, C]: sum_j a_ij s_ij
        out = (
            torch.einsum("bijh,bjhd->bihd", att, v)  # sum_j a_ij v_j
            + torch.einsum("bihc,hdc->bihd", read, w2)  # W2 sum_j a_ij s_ij
            + b2  # sum_j a_ij b2 = b2
        )  # [B, P, nh, d]
        h = h + self.drop(self.out(out.reshape(b, p, hid)))
        return h + self.drop(self.ff(self.norm2(h)))


def _pair_mask(mask: torch.Tensor) -> torch.Tensor:
    """The attention's mask as [B, P(i) or 1, P(j)]: a per-slot mask [B, P] (True: an agent)
    holds for every i; a pair mask [B, P, P] is itself."""
    return mask[:, None, :] if mask.ndim == 2 else mask


def direct_social_attention(layer: SocialAttention, h: torch.Tensor, geom: torch.Tensor,
                            mask: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """``layer``'s output computed by its formula as written, with every per-pair edge
    embedding e_ij formed ([B, P, P, H]): the reference that ``SocialAttention.forward``
    reproduces (tests) and is timed against (``benchmarks/attention_speed.py``)."""
    b, p, hid = h.shape
    nh, d = layer.heads, hid // layer.heads
    q, k, v = layer.qkv(layer.norm1(h)).chunk(3, -1)  # [B, P, H] each
    e = layer.edge(geom)  # [B, P(i), P(j), H]
    q = q.view(b, p, 1, nh, d)  # [B, P(i), 1, nh, d]
    k = (k[:, None] + e).view(b, p, p, nh, d)  # k_j + e_ij
    v = (v[:, None] + e).view(b, p, p, nh, d)  # v_j + e_ij
    logits = (q * k).sum(-1) / d**0.5  # [B, P(i), P(j), nh]
    logits = logits.masked_fill(~_pair_mask(mask)[..., None], float("-inf"))
    att = torch.softmax(logits, dim=2)  # over j
    out = (att[..., None] * v).sum(2).reshape(b, p, hid)  # [B, P, H]
    h = h + layer.drop(layer.out(out))
    return h + layer.drop(layer.ff(layer.norm2(h)))


class SetAttention(nn.Module):
    """A pre-norm transformer layer over a set of tokens (no positions, no mask):
    x + out(attention(LN(x))), then + ff(LN(.)); no dropout (its masks on the [S, K, 4W]
    hidden layer cost more than the layer itself on the CPU). Written with einsums, which run about
    twice as fast on the CPU as ``nn.TransformerEncoderLayer`` for many small sets."""

    def __init__(self, width: int, heads: int):
        super().__init__()
        if width % heads:
            raise ConfigError("width must be divisible by heads")
        self.heads = heads
        self.norm1 = nn.LayerNorm(width)
        self.qkv = nn.Linear(width, 3 * width)
        self.out = nn.Linear(width, width)
        self.norm2 = nn.LayerNorm(width)
        self.ff = mlp([width, 4 * width, width], act=nn.GELU)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """x [S, K, W]: S independent sets of K tokens each."""
        s, k, w = x.shape
        nh, d = self.heads, w // self.heads
        q, key, v = self.qkv(self.norm1(x)).view(s, k, 3, nh, d).unbind(2)  # [S, K, nh, d] each
        att = torch.softmax(torch.einsum("skhd,sjhd->shkj", q, key) / d**0.5, -1)  # [S, nh, K, K]
        mixed = torch.einsum("shkj,sjhd->skhd", att, v).reshape(s, k, w)  # [S, K, W]
        x = x + self.out(mixed)
        return x + self.ff(self.norm2(x))
