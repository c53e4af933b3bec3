"""Where one diffusion-score step spends its time, and whether an exact rewrite of the
denoiser's residual MLP makes it cheaper (issue 12's cost bar), on a split's largest scenes.

    python benchmarks/score_step_profile.py --dataset univ --scenes 20 --repeats 5 \
        --data-root ../shared/data

Times, interleaved scene by scene (ms per scene): the prediction (K = 20 leapfrog samples), the
scorer's context (the denoiser's social encoder, once per scene), one denoiser pass over the K
samples (one score step), and two rewrites of that pass: ``fused`` (the LayerNorm's affine
folded into the FiLM per agent, in-place SiLU and residual: the same arithmetic up to float
rounding) and ``chunks`` (the samples in chunks of ``--chunk``, so the activations stay in
cache: every row is computed alone, so the same numbers up to how the matrix-product kernel
blocks its rows; the run says whether they were bitwise equal). Also the throughput of one
[K * P, W] x [W, W] matrix product of the MLP beside a large one, which says how far the
products, most of the step, are from what this CPU gives. Writes
benchmarks/results/meta/score_step_profile_<dataset>.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from selection_cost import add_scene_arguments, largest_scenes

from trajpref.data.transforms import to_model_frame
from trajpref.models.denoiser import Denoiser
from trajpref.models.encoder import scene_features
from trajpref.models.layers import timestep_embedding
from trajpref.results import command_line, machine
from trajpref.types import collate

ROOT = Path(__file__).resolve().parent.parent


def fused_pass(denoiser: Denoiser, y: torch.Tensor, s: int, context: torch.Tensor):
    """``denoiser(y, s, context)`` for one step s and y [M, N, T_f, 2], with each block's
    LayerNorm affine folded into its FiLM per agent ([N, W] scale and shift, one pass over the
    [M, N, W] rows instead of three) and the SiLU and residual in place. No autograd."""
    cfg = denoiser.cfg
    t_emb = denoiser.t_embed(timestep_embedding(torch.as_tensor(s), cfg.hidden))  # [H]
    c = torch.cat([context, t_emb.expand(context.shape[0], -1)], -1)  # [N, 2H]
    x = denoiser.inp(y.flatten(-2))  # [M, N, W]
    for block in denoiser.blocks:
        gain, bias = block.film(c).chunk(2, -1)  # [N, W] each
        g1 = gain + 1
        scale = block.norm.weight * g1  # [N, W]
        shift = torch.addcmul(bias, block.norm.bias, g1)  # [N, W]
        h = F.layer_norm(x, block.norm.normalized_shape, None, None, block.norm.eps)
        h = torch.addcmul(shift, h, scale)  # [M, N, W]
        first, _, second = block.ff
        h = F.silu(F.linear(h, first.weight, first.bias), inplace=True)  # [M, N, W]
        x = F.linear(h, second.weight, second.bias).add_(x)  # [M, N, W]
    return denoiser.out(x).view(y.shape)  # [M, N, T_f, 2]


def chunked_pass(denoiser: Denoiser, y: torch.Tensor, s: int, context: torch.Tensor,
                 chunk: int) -> torch.Tensor:  # fmt: skip
    """``denoiser(y, s, context)`` over ``chunk`` samples of y [M, N, T_f, 2] at a time."""
    return torch.cat([denoiser(y[i : i + chunk], s, context) for i in range(0, len(y), chunk)])


def gemm_rate(rows: int, width: int, inner: int, repeats: int = 50) -> float:
    """GFLOP/s of addmm [rows, inner] x [inner, width] plus a bias, on random numbers."""
    a, w, b = torch.randn(rows, inner), torch.randn(width, inner), torch.randn(width)
    for _ in range(5):
        torch.addmm(b, a, w.t())
    t0 = time.perf_counter()
    for _ in range(repeats):
        torch.addmm(b, a, w.t())
    return 2 * rows * width * inner * repeats / (time.perf_counter() - t0) / 1e9


@torch.no_grad()
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_arguments(parser, repeats=5)
    parser.add_argument("--chunk", type=int, default=5, help="samples per chunk")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    model, largest = largest_scenes(args)
    den = model.denoiser.eval()
    batches = [collate([s]) for s in largest]
    ms = dict.fromkeys(("predict", "context", "step", "fused", "chunks"), 0.0)
    fused_diff, chunks_equal = 0.0, True
    for _ in range(args.repeats):
        for i, batch in enumerate(batches):
            t0 = time.perf_counter()
            pred = model.predict(batch, args.samples, torch.Generator().manual_seed(i))
            ms["predict"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            context = den.context(scene_features(batch, model.scale))  # [N, H]
            ms["context"] += time.perf_counter() - t0
            y = to_model_frame(pred, batch, model.scale)  # [K, N, T_f, 2]
            t0 = time.perf_counter()
            ref = den(y, 0, context)
            ms["step"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            fused = fused_pass(den, y, 0, context)
            ms["fused"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            chunks = chunked_pass(den, y, 0, context, args.chunk)
            ms["chunks"] += time.perf_counter() - t0
            fused_diff = max(fused_diff, float((fused - ref).abs().max()))
            chunks_equal &= bool(torch.equal(chunks, ref))
    calls = args.repeats * len(batches)
    ms = {k: 1000 * v / calls for k, v in ms.items()}
    width = den.cfg.denoiser_width
    rows = args.samples * max(s.num_agents for s in largest)
    mlp_rate, big_rate = gemm_rate(rows, width, width), gemm_rate(4096, 1024, 1024, 5)
    sizes = [s.num_agents for s in largest]
    print(f"{args.dataset} test, the {len(largest)} largest scenes ({min(sizes)}-{max(sizes)} "
          f"agents), K = {args.samples}, {torch.get_num_threads()} threads, "
          f"{args.repeats} repeats, ms per scene:")  # fmt: skip
    print(f"  predict {ms['predict']:.2f}, score context {ms['context']:.2f}, one score step "
          f"{ms['step']:.2f}")  # fmt: skip
    print(f"  fused step {ms['fused']:.2f} ({ms['fused'] / ms['step']:.3f}x, largest difference "
          f"{fused_diff:.2e}); chunks of {args.chunk} {ms['chunks']:.2f} "
          f"({ms['chunks'] / ms['step']:.3f}x, bitwise equal: {chunks_equal})")  # fmt: skip
    print(f"  matrix products: [{rows}, {width}] x [{width}, {width}] {mlp_rate:.0f} GFLOP/s, "
          f"[4096, 1024] x [1024, 1024] {big_rate:.0f} GFLOP/s")  # fmt: skip
    out = {"dataset": args.dataset, "scene_sizes": sizes, "samples": args.samples,
           "ms": ms, "fused_max_abs_difference": fused_diff, "chunk": args.chunk,
           "chunks_bitwise_equal": chunks_equal, "gflops_mlp_shape": mlp_rate,
           "gflops_large": big_rate, "command": command_line(),
           "machine": machine()}  # fmt: skip
    path = args.out or ROOT / "benchmarks" / "results" / "meta" / (
        f"score_step_profile_{args.dataset}.json")  # fmt: skip
    path.write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
