"""A fake renderer implementing grisx.render.driver's interface: noisy copies of a known image.

Frame f of method ``noisy`` is ``ref · (1 + σ·n_f / √spp)`` with n_f standard normal per pixel and
channel, so each frame is unbiased and the error of the running average is known in closed form;
``rho`` makes n_f an AR(1) sequence over frames (temporal correlation, stationary variance 1);
``offset`` adds a constant bias. Each frame sleeps ``delay`` seconds to have a measurable cost, or,
with ``cost`` > 0, the clock handed to ``on_frame`` is virtual: ``cost`` seconds per frame plus the
real time spent inside earlier ``on_frame`` calls (as a real renderer's clock would include them),
which makes timings deterministic on a busy machine.
Broken renderers for error tests: ``nan_frame=k`` puts a NaN into frame k, ``half=1`` renders at
half resolution.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

import numpy as np

RES = (16, 12)  # W, H


def known_image(res: tuple[int, int] | None = None) -> np.ndarray:
    w, h = res or RES
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.stack([0.05 + x / w, 0.05 + y / h, 0.5 + 0.4 * np.sin(x + y)], axis=-1)
    img[h // 3 : h // 2, w // 2 :, :] *= 8.0  # a bright patch (HDR values above 1)
    return img.astype(np.float32)


@dataclasses.dataclass
class FakeReference:
    image: np.ndarray
    variance: np.ndarray


@dataclasses.dataclass
class FakeResult:
    image: np.ndarray
    frames: int
    spp: int
    seconds: float
    pass_seconds: dict
    device: str
    settings: dict


class FakeRenderer:
    """Callable with render()'s signature; counts its calls."""

    def __init__(self, reference_variance: float | None = None) -> None:
        self.calls: list[dict] = []
        self.reference_variance = reference_variance

    def reference(self, scene: str, *, res=None, spp: int = 1, device: str = "cpu", seed: int = 0):
        """The known image, or with ``reference_variance`` a record (image, variance) as grisx.render.reference gives."""
        self.calls.append({"reference": scene, "seed": seed, "spp": spp})
        if self.reference_variance is None:
            return known_image(res)
        image = known_image(res)
        return FakeReference(image, np.full(image.shape, self.reference_variance, dtype=np.float32))

    def __call__(self, scene: str, method: str, *, spp: int = 1, frames: int = 1, accumulate: bool = False,
                 res=None, device: str = "cpu", seed: int = 0, params: dict | None = None,
                 on_frame: Callable[[int, np.ndarray, float], None] | None = None) -> FakeResult:
        if method != "noisy":
            raise ValueError(f"fake renderer knows only 'noisy', got {method}")
        p = {"sigma": 0.5, "rho": 0.0, "offset": 0.0, "delay": 0.0, "nan_frame": -1, "half": 0, "cost": 0.0, **(params or {})}
        sigma, rho, offset, delay = (float(p[k]) for k in ("sigma", "rho", "offset", "delay"))
        self.calls.append({"render": scene, "method": method, "frames": frames, "seed": seed, "accumulate": accumulate})
        ref = known_image(res).astype(np.float64)
        if int(p["half"]):
            ref = ref[::2, ::2]
        rng = np.random.default_rng(seed)
        noise = rng.standard_normal(ref.shape)
        acc = np.zeros_like(ref)
        start = time.perf_counter()
        cost, in_callbacks = float(p["cost"]), 0.0
        for f in range(frames):
            if f:
                noise = rho * noise + math.sqrt(1 - rho * rho) * rng.standard_normal(ref.shape)
            img = ref * (1 + sigma * noise / math.sqrt(spp)) + offset
            if f == int(p["nan_frame"]):
                img[0, 0, 0] = np.nan
            acc += img
            if delay:
                time.sleep(delay)
            image = (acc / (f + 1) if accumulate else img).astype(np.float32)  # the running average, as render()
            if on_frame is not None:
                clock = (f + 1) * cost + in_callbacks if cost > 0 else time.perf_counter() - start
                entered = time.perf_counter()
                try:
                    on_frame(f, image, clock)
                finally:
                    in_callbacks += time.perf_counter() - entered
        seconds = time.perf_counter() - start
        return FakeResult(image, frames, spp, seconds, {"fake": seconds}, device, {"method": method, **p})
