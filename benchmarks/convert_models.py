"""Convert legacy ``.pt`` checkpoints (trajpref-checkpoint/1) to ``.safetensors`` files with
half-precision weights, the format published under models/ since the re-layering.

    python benchmarks/convert_models.py models/zara1/generator.pt [...]   # writes .safetensors
    python benchmarks/convert_models.py --all                            # every models/*/*.pt

A generator keeps naming its denoiser by relative path (now ``.safetensors``) and the hash of
the denoiser's rounded weights. Old files are left in place; remove them once converted.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from trajpref.models import checkpoint as ckpt

ROOT = Path(__file__).resolve().parent.parent


def convert(path: Path) -> Path:
    """Write ``path`` (a legacy ``.pt``) as ``path.with_suffix('.safetensors')``."""
    dst = path.with_suffix(ckpt.SUFFIX)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)  # legacy files warn on load
        payload = ckpt.load(path)
        ref = payload.get("denoiser_ref")
        if ref is None:
            ckpt.publish(path, dst)
        else:
            ckpt.publish(path, dst, denoiser_name=Path(ref["path"]).with_suffix(ckpt.SUFFIX).name)
    return dst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", type=Path, help="legacy .pt checkpoints")
    parser.add_argument("--all", action="store_true", help="every models/*/*.pt")
    args = parser.parse_args()
    paths = sorted((ROOT / "models").glob("*/*.pt")) if args.all else args.paths
    if not paths:
        parser.error("name .pt files or pass --all")
    # denoisers first: generators then find their converted denoiser beside them
    for path in sorted(paths, key=lambda p: not p.name.startswith("denoiser")):
        dst = convert(path)
        print(f"{path} ({path.stat().st_size / 2**20:.1f} MB) -> {dst} "
              f"({dst.stat().st_size / 2**20:.1f} MB)")  # fmt: skip


if __name__ == "__main__":
    main()
