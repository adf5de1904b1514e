#!/usr/bin/env python
"""The README's three pictures (``docs/images/``): RIS histograms, seed 000's gradient histograms, an equal-time scene.

The first two come from the toys through the demo's own plotting functions; the third is
the door-ajar row of ReSTIR GI's equal-time benchmark on an H200
(``benchmarks/reference/restir_gi_h200_1920x1080.png``, see ``benchmarks/README.md``).

    python docs/make_readme_pictures.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from PIL import Image  # noqa: E402

from grisx.demo import plot_gradient_histograms, plot_ris_histograms  # noqa: E402
from grisx.theory.toys import run_toy  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "images"


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5, 3.6))
    plot_ris_histograms(ax, {m: run_toy("ris-1d", "ris", trials=200_000, params={"candidates": m}, return_samples=True).samples for m in (1, 4, 32)})
    fig.tight_layout()
    fig.savefig(OUT / "ris_histogram.png", dpi=100)
    fig, ax = plt.subplots(figsize=(5, 3.6))
    plot_gradient_histograms(ax, *(run_toy("f1-f2", m, trials=200_000, return_values=True) for m in ("gradient-after-restir", "gradient-with-restir")))
    fig.tight_layout()
    fig.savefig(OUT / "gradient_histogram.png", dpi=100)
    plt.close("all")
    Image.open(ROOT / "benchmarks" / "reference" / "restir_gi_h200_1920x1080.png").crop((0, 345, 1090, 595)).save(OUT / "equal_time_door_ajar.png")
    print(f"wrote {sorted(p.name for p in OUT.glob('*.png'))}")


if __name__ == "__main__":
    main()
