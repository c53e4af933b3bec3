"""Is the RL reward worth maximising for minADE/minFDE? For a dataset's pretrained generator,
on its validation split: how the per-sample reward that fine-tuning maximises (the summed
diffusion score r of `rl.stage`, with the default fine-tuning settings) ranks the K samples of
each agent against their ADE/FDE and their travelled distance.

    python benchmarks/reward_alignment.py --dataset zara1 --data-root ../shared/data
    # the same statistics for a fine-tuned model (did fine-tuning raise the reward, and at
    # what cost in spread?)
    python benchmarks/reward_alignment.py --dataset zara1 --name rlhf-res-s0 \
        --model runs/zara1-rlhf-res-s0/finetune.pt --data-root ../shared/data

Per agent (over its K samples), averaged over agents:
- Spearman correlation of the reward with -ADE, -FDE and with the distance travelled;
- FDE of the reward's top sample, of an average sample and of the best sample (oracle);
- minFDE over the reward's top M samples against the exact expectation over M random ones:
  what reweighting the K samples toward the reward could at best buy for minFDE_M;
- the mean reward and the spread of the K endpoints (mean distance to their centroid);
- where the reward's variation comes from, as fine-tuning's policy gradient sees it: each
  generator sample Y^tau_k is perturbed by the exploration noise +xi and -xi (the same
  ancestral noise in the tau denoising steps) and by +xi with fresh ancestral noise. The
  variance of (R(+xi) - R(-xi)) / 2 is the part the action (xi) explains, the one the
  gradient can learn from; (R(+xi) - R'(+xi)) / sqrt 2 the denoising noise's part; both as
  fractions of the variance of R over the K samples of an agent.

Writes benchmarks/results/meta/reward_alignment_<dataset>[_<name>].json.
"""

from __future__ import annotations

import argparse
import math
from datetime import date
from pathlib import Path

import torch

from trajpref.config import FinetuneConfig
from trajpref.data import load_dataset
from trajpref.data.loader import SceneLoader
from trajpref.data.transforms import to_model_frame
from trajpref.io import write_json
from trajpref.metrics import ade_fde
from trajpref.models import checkpoint as ckpt
from trajpref.results import command_line, machine
from trajpref.rl.objective import step_reward
from trajpref.score.scorer import TrajectoryScorer, score_timesteps

ROOT = Path(__file__).resolve().parent.parent


def spearman(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Rank correlation along dim 0 (no ties expected for continuous values): x, y [K, N]
    -> [N]."""
    rx = x.argsort(0).argsort(0).double()
    ry = y.argsort(0).argsort(0).double()
    rx, ry = rx - rx.mean(0), ry - ry.mean(0)
    return (rx * ry).sum(0) / (rx.pow(2).sum(0) * ry.pow(2).sum(0)).sqrt().clamp_min(1e-12)


def expected_min_of_random(values: torch.Tensor, m: int) -> torch.Tensor:
    """E[min over m of the K values drawn without replacement], exactly: values [K, N] ->
    [N]. The i-th smallest (0-based) is the minimum with probability C(K-1-i, m-1)/C(K, m)."""
    k = values.shape[0]
    w = torch.tensor([math.comb(k - 1 - i, m - 1) / math.comb(k, m) for i in range(k)],
                     dtype=values.dtype)  # fmt: skip
    return (values.sort(0).values * w[:, None]).sum(0)


def variance_sources(model, scorer, batch, cond, target, samples: int, rl: FinetuneConfig,
                     seed: int):  # fmt: skip
    """Per agent: variance of the summed reward over its K samples, and the shares of it
    explained by the exploration action and by the ancestral noise of the tau steps."""
    y_tau = model.generator(cond.features).initial_sample()[:samples]  # [K, N, T_f, 2]
    xi = torch.randn(y_tau.shape, generator=torch.Generator().manual_seed(seed)) * rl.explore_std

    def reward(start: torch.Tensor, noise_seed: int) -> torch.Tensor:
        gen = torch.Generator().manual_seed(noise_seed)
        y = model.denoise(cond, start, gen)  # [K, N, T_f, 2]
        return step_reward(scorer, cond.context, y, target, rl.reward_clip).sum(-1)  # [K, N]

    r_plus, r_minus = reward(y_tau + xi, seed + 1), reward(y_tau - xi, seed + 1)  # [K, N]
    r_fresh = reward(y_tau + xi, seed + 2)
    total = r_plus.var(0).clamp_min(1e-12)  # [N]
    return {
        "reward_var_over_k": total,
        "share_action": ((r_plus - r_minus) / 2).pow(2).mean(0) / total,
        "share_denoising_noise": ((r_plus - r_fresh).pow(2) / 2).mean(0) / total,
    }


@torch.no_grad()
def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", required=True)
    parser.add_argument("--data-root", default=None)
    parser.add_argument("--samples", type=int, default=20)
    parser.add_argument("--max-scenes", type=int, default=400)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--model", default=None, help="default models/<dataset>/generator.safetensors"
    )
    parser.add_argument("--name", default="", help="names the output for a --model")
    args = parser.parse_args()

    path = (
        Path(args.model)
        if args.model
        else ROOT / "models" / args.dataset / f"generator{ckpt.SUFFIX}"
    )
    model = ckpt.load_predictor(path, sampler="leapfrog")
    cfg = ckpt.load(path)["config"]
    val = load_dataset(cfg["data"].get("val_dataset") or cfg["data"]["dataset"], "val",
                       args.data_root).evenly_spaced(args.max_scenes)  # fmt: skip
    rl = FinetuneConfig()
    steps = score_timesteps(model.schedule.num_steps, rl.score_every)
    scorer = TrajectoryScorer(model.denoiser, model.schedule, model.scale, steps)
    gen = torch.Generator().manual_seed(args.seed)
    cols: dict[str, list[torch.Tensor]] = {}
    for batch in SceneLoader(val, max_agents=1024):
        pred = model.predict(batch, args.samples, gen)  # [K, N, T_f, 2]
        cond = model.condition(batch)
        target = to_model_frame(batch.future, batch, model.scale)  # [N, T_f, 2]
        y = to_model_frame(pred, batch, model.scale)  # [K, N, T_f, 2]
        # what fine-tuning maximises, per sample
        reward = step_reward(scorer, cond.context, y, target, rl.reward_clip).sum(-1)  # [K, N]
        ade, fde = ade_fde(pred, batch.future)  # [K, N]
        travelled = (pred[..., -1, :] - batch.history[None, :, -1, :]).norm(dim=-1)  # [K, N]
        top = reward.argmax(0)  # [N]
        order = reward.argsort(0, descending=True)  # [K, N]
        n = torch.arange(pred.shape[1])
        ends = pred[..., -1, :]  # [K, N, 2]
        spread = (ends - ends.mean(0, keepdim=True)).norm(dim=-1).mean(0)  # [N]
        new = {
            "rho_reward_neg_ade": spearman(reward, -ade),
            "rho_reward_neg_fde": spearman(reward, -fde),
            "rho_reward_travelled": spearman(reward, travelled),
            "fde_top_reward": fde[top, n],
            "fde_mean_sample": fde.mean(0),
            "fde_best_sample": fde.min(0).values,
            "ade_top_reward": ade[top, n],
            "ade_mean_sample": ade.mean(0),
            "reward_mean": reward.mean(0),
            "endpoint_spread": spread,
            "min_fde": fde.min(0).values,
            "min_ade": ade.min(0).values,
        }
        new |= variance_sources(model, scorer, batch, cond, target, args.samples, rl, args.seed)
        for m in (1, 5, 10):
            new[f"min_fde_top{m}_by_reward"] = fde.gather(0, order[:m]).min(0).values
            new[f"min_fde_random{m}"] = expected_min_of_random(fde, m)
        for key, v in new.items():
            cols.setdefault(key, []).append(v.double())
    out = {k: float(torch.cat(v).mean()) for k, v in cols.items()}
    agents = int(torch.cat(cols["fde_top_reward"]).numel())
    print(f"{args.dataset} val ({agents} agents, K={args.samples}, reward: score_every="
          f"{rl.score_every}, clip {rl.reward_clip}):")  # fmt: skip
    for k, v in out.items():
        print(f"  {k:24s} {v:.3f}")
    suffix = f"_{args.name}" if args.name else ""
    write_json(ROOT / "benchmarks" / "results" / "meta"
               / f"reward_alignment_{args.dataset}{suffix}.json",
               {"dataset": args.dataset, "model": str(path), "split": "val", "agents": agents,
                "samples": args.samples, **out, "command": command_line(),
                "date": date.today().isoformat(), "machine": machine()})  # fmt: skip


if __name__ == "__main__":
    main()
