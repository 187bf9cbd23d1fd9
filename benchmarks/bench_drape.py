"""Drape simulation time per frame (newton XPBD on the CPU), sphere and dress form.

``run()`` simulates each scene at the default resolution (48) in a temporary folder and
times the frames between the first and the last progress report, so model building and
(first-run) Warp kernel compilation are excluded; the demo's whole call (40 frames,
sphere) is timed too, build included, and the sphere once more without cloth
self-contact (the particle hash grid is about half the step time).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

FRAMES = 30


def _time_scene(scene: str, frames: int = FRAMES, resolution: int = 48, tag: str = "", **fabric) -> dict:
    from kesbrdf.cloth.drape import DrapeParameters, build_scene, simulate_drape, substeps_for

    stamps: list[float] = []
    with tempfile.TemporaryDirectory(prefix="kesbrdf-bench-drape-") as tmp:
        t0 = time.perf_counter()
        simulate_drape(scene, Path(tmp), frames, resolution=resolution,
                       progress=lambda d, t: stamps.append(time.perf_counter()), **fabric)
        total = time.perf_counter() - t0
    cloth = build_scene(DrapeParameters(scene=scene, resolution=resolution)).cloth
    n_sub, _ = substeps_for(cloth, 30.0)
    per_frame = (stamps[-1] - stamps[0]) / (len(stamps) - 1)
    scene = scene + tag
    return {
        f"{scene}_s_per_frame": per_frame,
        f"{scene}_substeps_per_frame": n_sub,
        f"{scene}_particles": int(len(cloth.positions)),
        f"{scene}_ms_per_substep": 1000.0 * per_frame / n_sub,
        f"{scene}_total_s_{frames}_frames": total,
    }


def run() -> dict:
    out: dict = {"resolution": 48, "fps": 30.0}
    # warm-up: compile / load the Warp kernels once so the timings below exclude it
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        from kesbrdf.cloth.drape import simulate_drape

        simulate_drape("sphere", Path(tmp), 2, resolution=4)
    out["warmup_compile_or_load_s"] = time.perf_counter() - t0
    out.update(_time_scene("sphere"))
    out.update(_time_scene("dressform"))
    out.update(_time_scene("sphere", tag="_no_self_contact", self_contact=False))
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        simulate_drape("sphere", Path(tmp), 40)
    out["demo_sphere_40_frames_s"] = time.perf_counter() - t0
    return out


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    print(json.dumps(run(), indent=1))
