"""Drape simulation time per frame (newton XPBD on the CPU): sheet at 48² and 64², garment.

``run()`` measures, kernels already compiled (a warm-up run compiles or loads them from
Warp's cache, ``~/.cache/warp``; its time is reported separately):

* ``sphere_48`` / ``sphere_64``: the 1 m sheet falling onto the sphere, s per simulated
  frame (the frames between the first and the last progress report, so model building
  and compilation are excluded; PLY + checkpoint writing included);
* ``sphere_64_newton_defaults``: the same with newton's defaults (128³ hash grid rebuilt
  and self-contact, bending and collision detection on every substep), the baseline of
  the speed-ups in kesbrdf.cloth.drape;
* ``hash_grid_bit_identical``: 10 frames of a 24² sheet with a 128³ and a 64³ grid,
  largest position difference (0.0 expected: the grid size only changes aliasing);
* ``garment_40``: the demo's sewn skirt on the turning mannequin, s per frame, and the
  widest seam gap at the end;
* ``demo_drape_steps_s``: the demo's two drape calls (sheet 40 frames, garment 66).

Every time is given as wall time and as this process's CPU time (``*_cpu_*``): on the
shared development machine the wall time depends on the other jobs (×2–×20), the CPU
time much less.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

FRAMES = 30


def _time_scene(scene: str, frames: int = FRAMES, resolution: int = 48, tag: str = "", **fabric) -> dict:
    from kesbrdf.cloth.drape import DrapeParameters, build_scene, simulate_drape, substeps_for

    stamps: list[float] = []
    cpu: list[float] = []

    def stamp(done, total):
        stamps.append(time.perf_counter())
        cpu.append(time.process_time())

    with tempfile.TemporaryDirectory(prefix="kesbrdf-bench-drape-") as tmp:
        t0 = time.perf_counter()
        simulate_drape(scene, Path(tmp), frames, resolution=resolution, progress=stamp, **fabric)
        total = time.perf_counter() - t0
    cloth = build_scene(DrapeParameters(scene=scene, resolution=resolution)).cloth
    n_sub, _ = substeps_for(cloth, 30.0)
    per_frame = (stamps[-1] - stamps[0]) / (len(stamps) - 1)
    name = f"{scene}_{resolution}{tag}"
    return {
        f"{name}_s_per_frame": per_frame,
        # CPU time of this process (Warp's CPU kernels run serially on the calling thread):
        # what a frame costs on an unshared core, whatever the other jobs on the machine do
        f"{name}_cpu_s_per_frame": (cpu[-1] - cpu[0]) / (len(cpu) - 1),
        f"{name}_substeps_per_frame": n_sub,
        f"{name}_particles": int(len(cloth.positions)),
        f"{name}_ms_per_substep": 1000.0 * per_frame / n_sub,
        f"{name}_total_s_{frames}_frames": total,
    }


NEWTON_DEFAULTS = dict(contact_interval=1, self_contact_interval=1, bending_interval=1)


def _hash_grid_identity() -> float:
    import numpy as np

    from kesbrdf.cloth import drape

    out = []
    saved = drape.HASH_GRID_DIM
    try:
        for dim in (128, 64):
            drape.HASH_GRID_DIM = dim
            with tempfile.TemporaryDirectory() as tmp:
                drape.simulate_drape("sphere", Path(tmp), 10, resolution=24)
                out.append(drape.load_checkpoint(tmp)["q"])
    finally:
        drape.HASH_GRID_DIM = saved
    return float(np.abs(out[0] - out[1]).max())


def _garment() -> dict:
    import numpy as np

    from kesbrdf.cloth.drape import DrapeParameters, build_scene, load_checkpoint, simulate_drape

    kw = dict(resolution=40, turn_deg=90.0, turn_start_s=0.6, turn_duration_s=1.2)
    stamps: list[float] = []
    cpu: list[float] = []

    def stamp(done, total):
        stamps.append(time.perf_counter())
        cpu.append(time.process_time())

    with tempfile.TemporaryDirectory() as tmp:
        simulate_drape("garment", Path(tmp), 40, progress=stamp, **kw)
        q = load_checkpoint(tmp)["q"]
    seams = build_scene(DrapeParameters(scene="garment", **kw)).cloth.seams
    return {"garment_40_s_per_frame": (stamps[-1] - stamps[0]) / (len(stamps) - 1),
            "garment_40_cpu_s_per_frame": (cpu[-1] - cpu[0]) / (len(cpu) - 1),
            "garment_40_seam_gap_max_mm": 1000.0 * float(np.linalg.norm(q[seams[:, 0]] - q[seams[:, 1]], axis=1).max())}


def run() -> dict:
    out: dict = {"fps": 30.0}
    # warm-up: compile / load the Warp kernels once so the timings below exclude it
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        from kesbrdf.cloth.drape import simulate_drape

        simulate_drape("sphere", Path(tmp), 2, resolution=4)
        simulate_drape("garment", Path(tmp) / "g", 2, resolution=8, turn_deg=10.0, turn_start_s=0.0)
    out["warmup_compile_or_load_s"] = time.perf_counter() - t0
    out.update(_time_scene("sphere", resolution=48))
    out.update(_time_scene("sphere", resolution=64))
    out.update(_time_scene("sphere", frames=12, resolution=64, tag="_newton_defaults", **NEWTON_DEFAULTS))
    out["sphere_64_speedup_vs_newton_defaults"] = (out["sphere_64_newton_defaults_cpu_s_per_frame"]
                                                   / out["sphere_64_cpu_s_per_frame"])
    out["hash_grid_128_vs_64_max_abs_diff_m"] = _hash_grid_identity()
    out.update(_garment())
    t0, c0 = time.perf_counter(), time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        simulate_drape("sphere", Path(tmp) / "s", 40)
        simulate_drape("garment", Path(tmp) / "g", 66, resolution=40, turn_deg=90.0, turn_start_s=0.6,
                       turn_duration_s=1.2)
    out["demo_drape_steps_s"] = time.perf_counter() - t0
    out["demo_drape_steps_cpu_s"] = time.process_time() - c0
    return out


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
    print(json.dumps(run(), indent=1))
