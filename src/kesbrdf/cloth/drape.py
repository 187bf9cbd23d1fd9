"""Dressing simulation: satin draped over a sphere or a dress form with newton (XPBD, CPU).

The paper's application step (docs/method.md, "The paper's steps") renders "arbitrarily coloured satin" in a
dressing simulation.  :func:`simulate_drape` runs the cloth with the ``newton`` package's
:class:`newton.solvers.SolverXPBD` on Warp's CPU device and writes a folder that
``kesbrdf render --animation`` reads (layout in ``docs/drape.md``)::

    drape.json                 manifest ("format": "kesbrdf-drape", version 1)
    frame_0000.ply ...         cloth at t = k / fps (binary PLY: x y z nx ny nz u v)
    collider_0.ply ...         the collision primitives, triangulated
    drape_state.npz            checkpoint: positions and velocities after the last frame

Physical model
--------------
The fabric is a grid of particles with lumped masses (areal density ρ) joined by
springs assembled per cell so that a square cell gives the sheet a tensile stiffness
E·t (``stretch_stiffness``, N/m) along warp and weft and ``shear_ratio``·E·t across
the diagonals; bending is newton's dihedral constraint with stiffness 3·B/h² for a
bending rigidity B (N·m) and cell size h.  newton's XPBD sums constraint corrections
Jacobi-style, which diverges when a particle's summed ``k·dt²/m`` is too large
(the "too small particle mass made XPBD explode" of docs/architecture.md, "Tools it runs on").  The substep is
therefore chosen from the stability number

.. math::  \\Delta t = \\sqrt{\\beta / \\max_i (\\textstyle\\sum_{s \\ni i} k_s / m_i)}

with β = :data:`STABILITY_BETA`, i.e. a CFL-like condition on the stretch-wave speed
√(E·t/ρ).  Real satin (E·t of several hundred N/m) would need hundreds of substeps a
frame; the default E·t = 40 N/m keeps the sag strain of a 1 m sheet to a few percent.

Resumption
----------
Every frame is written atomically, then the checkpoint (positions and velocities,
float32, exactly as newton holds them), then the manifest.  A re-run with the same
parameters (the frame count may grow) restarts from the checkpoint.  XPBD keeps no
other state between steps (constraint multipliers and contacts are rebuilt every
substep) and Warp's CPU kernels run serially, so a resumed run reproduces the
uninterrupted one bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from kesbrdf._atomic import atomic_path, write_text
from kesbrdf._version import __version__
from kesbrdf.cloth import scenes as _scenes
from kesbrdf.cloth.ply import vertex_normals, write_ply
from kesbrdf.errors import KesbrdfError, where, validate_choice

__all__ = ["DrapeError", "DrapeParameters", "SCENES", "simulate_drape", "frame_name", "load_checkpoint"]

SCENES = ("sphere", "dressform", "garment")
FORMAT = "kesbrdf-drape"
VERSION = 1
MANIFEST = "drape.json"
CHECKPOINT = "drape_state.npz"

#: Summed per-particle k·dt²/m that newton's Jacobi XPBD spring solve tolerates with a
#: margin: a 48×48 sheet ran stably at 1.8 and diverged at ≥ 3 on this machine.
STABILITY_BETA = 1.5
#: Most substeps a frame we accept; more means the fabric is too stiff for the grid.
MAX_SUBSTEPS = 2000
#: Cells per axis of the (periodic) particle hash grid used for cloth self-contact.
HASH_GRID_DIM = 64


class DrapeError(KesbrdfError):
    """Bad drape parameters, or an output folder holding a different simulation."""


@dataclass(frozen=True)
class DrapeParameters:
    """Everything that determines a drape simulation (frame count excluded).

    Attributes
    ----------
    scene : {"sphere", "dressform"}
    fps : frames per second of the output, (0, 240].
    resolution : cloth cells along the warp of the sheet (skirt: 2× around, ½× down), [4, 256].
    seed : seeds the initial perturbation (≤ 0.2 mm normal jitter, ≤ 2 cm sheet offset).
    density_kg_m2 : areal density ρ, [0.02, 1] kg/m² (satin ≈ 0.06–0.15).
    stretch_stiffness_n_m : tensile stiffness E·t of the sheet, [1, 2000] N/m.
    shear_ratio : diagonal (shear) stiffness as a fraction of E·t, [0, 1].
    bending_rigidity_nm : bending rigidity B, [0, 1e-3] N·m (satin ≈ 1e-6–1e-5).
    friction : Coulomb friction against the colliders, [0, 2].
    damping_per_s : air damping of particle velocities, [0, 10] 1/s.
    particle_radius_m : contact thickness, [0.0005, 0.02] m.
    self_contact : particle-particle contacts within 2 × particle_radius_m (cloth on
        cloth at the vertices); off halves the step time.
    turn_deg : ``garment`` only: the mannequin turns about its vertical axis by this
        angle [deg], [-720, 720], counter-clockwise seen from above, the waistband with it.
    turn_start_s, turn_duration_s : when the turn starts and how long it takes [s]; the
        angle follows (1 − cos πx)/2 of the elapsed fraction x (smooth start and stop).
    contact_interval : substeps between refreshes of the cloth-collider contact list,
        [1, 16].  Contacts are found within a 1 cm gap and re-projected every substep
        against the tangent plane found, so a refresh is needed only before a particle
        can travel 1 cm (at 2 m/s and 66 substeps a frame that is 10 substeps).
    self_contact_interval : substeps between cloth self-contact solves, [1, 8].  Two
        particles pass through each other only by closing twice the 6 mm contact
        distance between two solves: 12 mm in 8 substeps of 0.5 ms (64²) is a closing
        speed of 3 m/s, and folds settle onto the cloth below far slower than that
        (measured, docs/drape.md "Speed": every 8th substep leaves no pair of
        non-neighbouring vertices closer than 6 mm and moves the settled sheet less
        than solving on every substep does).
    bending_interval : substeps between bending (dihedral) solves, [1, 8], with the
        stiffness scaled by its square so that the XPBD compliance per unit time is
        unchanged (bending is soft: k Δt² ≪ the stability bound).
    """

    scene: str = "sphere"
    fps: float = 30.0
    resolution: int = 48
    seed: int = 0
    density_kg_m2: float = 0.12
    stretch_stiffness_n_m: float = 40.0
    shear_ratio: float = 0.1
    bending_rigidity_nm: float = 5e-6
    friction: float = 0.5
    damping_per_s: float = 0.5
    particle_radius_m: float = 0.003
    self_contact: bool = True
    turn_deg: float = 0.0
    turn_start_s: float = 0.8
    turn_duration_s: float = 1.2
    contact_interval: int = 4
    bending_interval: int = 3
    self_contact_interval: int = 8

    def validate(self) -> "DrapeParameters":
        validate_choice("drape scene", self.scene, SCENES, error=DrapeError)
        checks = (
            ("fps", self.fps, 0.0, 240.0, False),
            ("resolution", self.resolution, 4, 256, True),
            ("density_kg_m2", self.density_kg_m2, 0.02, 1.0, True),
            ("stretch_stiffness_n_m", self.stretch_stiffness_n_m, 1.0, 2000.0, True),
            ("shear_ratio", self.shear_ratio, 0.0, 1.0, True),
            ("bending_rigidity_nm", self.bending_rigidity_nm, 0.0, 1e-3, True),
            ("friction", self.friction, 0.0, 2.0, True),
            ("damping_per_s", self.damping_per_s, 0.0, 10.0, True),
            ("particle_radius_m", self.particle_radius_m, 5e-4, 0.02, True),
            ("contact_interval", self.contact_interval, 1, 16, True),
            ("self_contact_interval", self.self_contact_interval, 1, 8, True),
            ("bending_interval", self.bending_interval, 1, 8, True),
            ("turn_deg", self.turn_deg, -720.0, 720.0, True),
            ("turn_start_s", self.turn_start_s, 0.0, 1000.0, True),
            ("turn_duration_s", self.turn_duration_s, 0.0, 1000.0, False),
        )
        for name, value, lo, hi, closed_lo in checks:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            ok = ok and (value >= lo if closed_lo else value > lo) and value <= hi
            if not ok:
                bracket = "[" if closed_lo else "("
                raise DrapeError(f"drape: expected {name} in {bracket}{lo:g}, {hi:g}], got {value!r}")
        if not isinstance(self.resolution, int) or isinstance(self.resolution, bool):
            raise DrapeError(f"drape: expected an integer resolution, got {self.resolution!r}")
        for name in ("contact_interval", "self_contact_interval", "bending_interval"):
            if not isinstance(getattr(self, name), int) or isinstance(getattr(self, name), bool):
                raise DrapeError(f"drape: expected an integer {name}, got {getattr(self, name)!r}")
        if self.turn_deg != 0.0 and self.scene != "garment":
            raise DrapeError(f"drape: turn_deg needs scene 'garment' (a body that can turn), got scene {self.scene!r}")
        if not isinstance(self.self_contact, bool):
            raise DrapeError(f"drape: expected self_contact True or False, got {self.self_contact!r}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise DrapeError(f"drape: expected a non-negative integer seed, got {self.seed!r}")
        return self

    def to_json(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}

    def body_angle(self, t) -> np.ndarray:
        """Rotation of the mannequin about z at times t [s], radians."""
        x = np.clip((np.asarray(t, float) - self.turn_start_s) / self.turn_duration_s, 0.0, 1.0)
        return math.radians(self.turn_deg) * 0.5 * (1.0 - np.cos(np.pi * x))

    def body_rate(self, t) -> np.ndarray:
        """Angular velocity of the mannequin at times t [rad/s]."""
        x = (np.asarray(t, float) - self.turn_start_s) / self.turn_duration_s
        inside = (x > 0.0) & (x < 1.0)
        return np.where(inside, math.radians(self.turn_deg) * 0.5 * np.pi * np.sin(np.pi * x) / self.turn_duration_s, 0.0)

    def key(self) -> str:
        """SHA-256 of the canonical JSON: equal keys mean the same simulation."""
        blob = json.dumps(self.to_json(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()


def frame_name(k: int) -> str:
    """``frame_0000.ply`` style name of frame ``k``."""
    return f"frame_{k:04d}.ply"


def build_scene(params: DrapeParameters) -> _scenes.SceneSpec:
    """The cloth (with its seeded initial perturbation) and colliders of a scene."""
    make = {"sphere": _scenes.sphere_scene, "dressform": _scenes.dressform_scene,
            "garment": _scenes.garment_scene}[params.scene]
    spec = make(params.resolution, params.density_kg_m2, params.stretch_stiffness_n_m, params.shear_ratio)
    rng = np.random.default_rng(params.seed)
    cloth = spec.cloth
    free = ~cloth.pinned
    normals = vertex_normals(cloth.positions, cloth.faces)
    jitter = rng.uniform(-2e-4, 2e-4, len(cloth.positions))[:, None] * normals
    offset = np.zeros(3)
    if params.scene == "sphere":
        offset[:2] = rng.uniform(-0.02, 0.02, 2)
    cloth.positions = (cloth.positions + np.where(free[:, None], jitter + offset, 0.0)).astype(np.float32)
    return spec


def _resume_key(params: DrapeParameters, spec: _scenes.SceneSpec) -> str:
    """SHA-256 over what decides the frames: parameters, initial cloth, colliders, versions.

    A folder resumes only under the same key, so a changed scene geometry or another
    kesbrdf / newton / warp version starts over instead of splicing two simulations.
    """
    h = hashlib.sha256(params.key().encode())
    h.update(np.ascontiguousarray(spec.cloth.positions, dtype=np.float32).tobytes())
    h.update(json.dumps([c.to_json() for c in spec.colliders], sort_keys=True).encode())
    h.update(json.dumps([__version__, _version_of("newton"), _version_of("warp")]).encode())
    return h.hexdigest()


def substeps_for(cloth: _scenes.ClothPiece, fps: float) -> tuple[int, float]:
    """Substeps per frame and the stability-limited substep length (module docstring)."""
    k_sum = np.zeros(len(cloth.masses))
    for col in (0, 1):
        np.add.at(k_sum, cloth.springs[:, col], cloth.spring_ke)
    free = ~cloth.pinned
    worst = float(np.max(k_sum[free] / cloth.masses[free]))
    dt_max = math.sqrt(STABILITY_BETA / worst)
    n = max(1, math.ceil((1.0 / fps) / dt_max))
    if n > MAX_SUBSTEPS:
        raise DrapeError(
            f"drape: the fabric needs {n} substeps a frame (> {MAX_SUBSTEPS}) for a stable XPBD solve; "
            "lower stretch_stiffness_n_m or resolution, or raise density_kg_m2 or fps")
    return n, dt_max


def _import_newton():
    try:
        import warp as wp
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError(f"kesbrdf drape needs warp-lang and newton: install kesbrdf[cloth] ({exc})") from None
    wp.config.log_level = wp.LOG_WARNING  # no per-module compile/load lines
    # kesbrdf never differentiates the simulation: without backward passes newton's
    # kernels compile in about a third of the time (80 s -> 24 s on a fresh 2-core
    # machine) and the forward code, hence every position, is bit-identical.  Warp
    # reads this when each module is created, i.e. when newton is imported.
    if "newton" not in sys.modules:
        wp.config.enable_backward = False
    _init_warp_quietly(wp)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import newton
    except ImportError as exc:  # pragma: no cover
        raise ImportError(f"kesbrdf drape needs newton: install kesbrdf[cloth] ({exc})") from None
    return wp, newton


def _init_warp_quietly(wp) -> None:
    """Initialise Warp with file descriptor 2 muted.

    On a machine without a GPU, Warp's native library prints "Warp CUDA warning: Could
    not find or load the NVIDIA CUDA driver" to stderr at initialisation; the library
    must not print, so that one call runs with stderr pointed at /dev/null.  Errors
    still surface as Python exceptions.
    """
    try:
        from warp._src import context
    except ImportError:  # pragma: no cover - another warp layout: initialise normally
        wp.init()
        return
    if getattr(context, "runtime", None) is not None:
        return
    import os
    import sys

    sys.stderr.flush()
    saved = os.dup(2)
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
        wp.init()
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class _Simulator:
    """newton model, XPBD solver and collision pipeline for one scene on the CPU."""

    def __init__(self, spec: _scenes.SceneSpec, params: DrapeParameters):
        wp, newton = _import_newton()
        self.wp = wp
        self.device = "cpu"
        cloth = spec.cloth
        builder = newton.ModelBuilder()  # z up, gravity 9.81 m/s² downward
        cfg = builder.default_shape_cfg.copy()
        cfg.mu = params.friction
        self.body = -1
        for c in spec.colliders:
            xform = wp.transform(wp.vec3(*c.center), _quat_z_to(wp, c.axis))
            if c.kind == "mesh":
                # the mannequin: a triangle mesh on a kinematic body whose pose we prescribe
                v, _, _, f = _scenes.collider_mesh(c)
                mesh = newton.Mesh(v, f.ravel(), compute_inertia=False)
                self.body = builder.add_link(xform=wp.transform_identity(), mass=0.0, is_kinematic=True, label=c.label)
                body_cfg = cfg.copy()
                body_cfg.has_shape_collision = False  # cloth only: no rigid contacts with the stand or floor
                builder.add_shape_mesh(self.body, mesh=mesh, cfg=body_cfg, label=c.label)
            elif c.kind == "sphere":
                builder.add_shape_sphere(-1, xform=xform, radius=c.radius, cfg=cfg, label=c.label)
            elif c.kind == "capsule":
                builder.add_shape_capsule(-1, xform=xform, radius=c.radius, half_height=c.half_height, cfg=cfg, label=c.label)
            elif c.kind == "box":
                hx, hy, hz = c.half_extents
                builder.add_shape_box(-1, xform=xform, hx=hx, hy=hy, hz=hz, cfg=cfg, label=c.label)
        builder.add_ground_plane(height=spec.ground_height, cfg=cfg)
        h = cloth.min_spring_length
        start = len(builder.particle_q)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            builder.add_cloth_mesh(
                pos=wp.vec3(0.0, 0.0, 0.0), rot=wp.quat_identity(), scale=1.0, vel=wp.vec3(0.0, 0.0, 0.0),
                vertices=[wp.vec3(*map(float, p)) for p in cloth.positions],
                indices=cloth.faces.ravel().tolist(), density=params.density_kg_m2,
                edge_ke=3.0 * params.bending_rigidity_nm / (h * h), edge_kd=0.0,
                particle_radius=params.particle_radius_m,
            )
        for k, (m, pinned) in enumerate(zip(cloth.masses, cloth.pinned)):
            builder.particle_mass[start + k] = 0.0 if pinned else float(m)
        if cloth.seams is not None and cloth.seam_radius is not None:
            # stitched vertices sit seam_radius·2 apart: their contact distance must agree
            for k in np.unique(cloth.seams).tolist():
                builder.particle_radius[start + k] = float(cloth.seam_radius)
        for (i, j), ke in zip(cloth.springs.tolist(), cloth.spring_ke.tolist()):
            builder.add_spring(start + i, start + j, ke, 0.0, 0.0)
        self.start = start
        self.count = len(cloth.positions)
        self.model = builder.finalize(device=self.device)
        if cloth.spring_rest is not None:  # rest lengths of the flat pattern, not of the placed panels
            self.model.spring_rest_length.assign(np.asarray(cloth.spring_rest, np.float32))
        if cloth.flat_rest and self.model.edge_count:  # flat cloth: every hinge rests at 0
            self.model.edge_rest_angle.zero_()
        self.model.particle_mu = params.friction
        self.model.soft_contact_mu = params.friction
        self.solver = newton.solvers.SolverXPBD(self.model, iterations=1)
        self.state_0 = self.model.state()
        self.state_1 = self.model.state()
        self.control = self.model.control()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.pipeline = newton.CollisionPipeline(self.model, soft_contact_gap=0.01)
        self.contacts = self.pipeline.contacts()
        self.grid = None
        self.max_radius = self.model.particle_max_radius
        if params.self_contact:
            # newton allocates a 128³ hash grid and clears all 2 M cells on every rebuild
            # (each substep): a fifth of the step time on a 64² cloth.  The grid is
            # periodic, so a smaller one only aliases far-apart particles into the same
            # cell, and the exact distance test drops them again: the contacts, hence the
            # positions, are bit-identical (tested in benchmarks/bench_drape.py).
            self.grid = wp.HashGrid(HASH_GRID_DIM, HASH_GRID_DIM, HASH_GRID_DIM, device=self.device)
            self.grid.reserve(self.model.particle_count)
        self.model.particle_grid = None
        self.model.particle_max_radius = 0.0
        self.params = params
        self.pinned = np.flatnonzero(cloth.pinned) + start
        self.pinned_rest = np.asarray(cloth.positions, np.float64)[cloth.pinned]
        self.substeps, _ = substeps_for(cloth, params.fps)
        self.dt = 1.0 / params.fps / self.substeps
        self.decay = math.exp(-params.damping_per_s * self.dt)
        self.contact_interval = params.contact_interval
        self.bending_interval = params.bending_interval
        self.edge_count = self.model.edge_count
        self.bending = None
        if self.edge_count and self.bending_interval > 1:
            # XPBD's compliance is 1 / (k Δt²): solving the hinge every n-th substep with
            # n² k gives it the compliance of one step of length n Δt (same stiffness in time)
            props = self.model.edge_bending_properties.numpy().copy()
            props[:, 0] *= self.bending_interval ** 2
            self.bending = wp.array(props, dtype=self.model.edge_bending_properties.dtype, device=self.device)
            self.model.edge_bending_properties = self.bending
        self.self_contact_interval = params.self_contact_interval

    def get(self) -> tuple[np.ndarray, np.ndarray]:
        sl = slice(self.start, self.start + self.count)
        return self.state_0.particle_q.numpy()[sl].copy(), self.state_0.particle_qd.numpy()[sl].copy()

    def set(self, q: np.ndarray, qd: np.ndarray) -> None:
        wp = self.wp
        all_q = self.state_0.particle_q.numpy().copy()
        all_qd = self.state_0.particle_qd.numpy().copy()
        all_q[self.start:self.start + self.count] = q
        all_qd[self.start:self.start + self.count] = qd
        for state in (self.state_0, self.state_1):
            state.particle_q.assign(wp.array(all_q, dtype=wp.vec3, device=self.device))
            state.particle_qd.assign(wp.array(all_qd, dtype=wp.vec3, device=self.device))

    def _pose_body(self, t0: float, t1: float) -> None:
        """Prescribe the mannequin's turn for the substep [t0, t1].

        The kinematic body is posed at t1 (newton copies a kinematic body's state through
        the solve); the pinned waistband starts at its t0 position with the rigid
        velocity ω × r, which newton integrates to t1 (zero-mass particles keep their
        velocity).  Both are set afresh every substep, so nothing drifts.
        """
        if self.body < 0 or self.params.turn_deg == 0.0:
            return
        ang1 = float(self.params.body_angle(t1))
        rate1 = float(self.params.body_rate(t1))
        for state in (self.state_0, self.state_1):
            bq = state.body_q.numpy()  # views of the CPU arrays
            bq[self.body] = (0.0, 0.0, 0.0, 0.0, 0.0, math.sin(0.5 * ang1), math.cos(0.5 * ang1))
            state.body_qd.numpy()[self.body] = (0.0, 0.0, 0.0, 0.0, 0.0, rate1)
        ang0 = float(self.params.body_angle(t0))
        rate = (ang1 - ang0) / (t1 - t0)  # secant rate over the substep
        c, s = math.cos(ang0), math.sin(ang0)
        p = self.pinned_rest
        q = self.state_0.particle_q.numpy()
        qd = self.state_0.particle_qd.numpy()
        x = c * p[:, 0] - s * p[:, 1]
        y = s * p[:, 0] + c * p[:, 1]
        q[self.pinned, 0], q[self.pinned, 1], q[self.pinned, 2] = x, y, p[:, 2]
        qd[self.pinned, 0], qd[self.pinned, 1], qd[self.pinned, 2] = -rate * y, rate * x, 0.0

    def step_frame(self, k: int = 1) -> None:
        """Advance from frame k − 1 to frame k."""
        t0 = (k - 1) / self.params.fps
        for s in range(self.substeps):
            self._pose_body(t0 + s * self.dt, t0 + (s + 1) * self.dt)
            self.state_0.clear_forces()
            if s % self.contact_interval == 0:
                self.pipeline.collide(self.state_0, self.contacts)
            if self.bending is not None:  # bending on every bending_interval-th substep
                on = s % self.bending_interval == 0
                self.model.edge_count = self.edge_count if on else 0
            if self.grid is not None:  # self-contact on every self_contact_interval-th substep
                on = s % self.self_contact_interval == 0
                self.model.particle_grid = self.grid if on else None
                self.model.particle_max_radius = self.max_radius if on else 0.0
            self.solver.step(self.state_0, self.state_1, self.control, self.contacts, self.dt)
            self.state_0, self.state_1 = self.state_1, self.state_0
            if self.decay != 1.0:
                qd = self.state_0.particle_qd.numpy()  # a view of the CPU array
                qd *= np.float32(self.decay)


def _quat_z_to(wp, axis):
    """Quaternion rotating +z onto ``axis`` (capsules extend along their local z)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, a))
    if c > 1 - 1e-9:
        return wp.quat_identity()
    if c < -1 + 1e-9:
        return wp.quat_from_axis_angle(wp.vec3(1.0, 0.0, 0.0), math.pi)
    r = np.cross(z, a)
    r /= np.linalg.norm(r)
    return wp.quat_from_axis_angle(wp.vec3(*map(float, r)), math.acos(c))


def _write_frame(path: Path, cloth: _scenes.ClothPiece, q: np.ndarray, k: int, fps: float) -> None:
    normals = vertex_normals(q, cloth.faces)
    idx = cloth.output_index
    write_ply(path, q[idx], cloth.output_faces, normals[idx], cloth.output_uv,
              comment=f"kesbrdf {__version__} drape frame {k} t={k / fps:.6g}s u=warp v=weft metres z-up")


def load_checkpoint(out_dir) -> dict | None:
    """The checkpoint of a drape folder: ``{"frame", "key", "q", "qd"}``, or None."""
    path = Path(out_dir) / CHECKPOINT
    if not path.is_file():
        return None
    try:
        with np.load(path) as z:
            return {"frame": int(z["frame"]), "key": str(z["key"]), "q": z["q"].copy(), "qd": z["qd"].copy()}
    except (OSError, ValueError, KeyError) as exc:
        raise DrapeError(f"{where(path)}expected a drape checkpoint (frame, key, q, qd), got an unreadable file ({exc})") from None


def _save_checkpoint(out_dir: Path, frame: int, key: str, q: np.ndarray, qd: np.ndarray) -> None:
    with atomic_path(out_dir / CHECKPOINT) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, frame=np.int64(frame), key=np.str_(key), q=q, qd=qd)


def _manifest(params, frames_total, done, spec, collider_files, sim_info, resume_key) -> dict:
    return {
        "format": FORMAT,
        "version": VERSION,
        "scene": params.scene,
        "fps": params.fps,
        "up_axis": "z",
        "units": "m",
        "frames": [frame_name(k) for k in range(done + 1)],
        "frames_requested": frames_total,
        "complete": done + 1 >= frames_total,
        "colliders": [{"file": f, **c.to_json()} for f, c in zip(collider_files, spec.colliders)],
        "ground": {"kind": "plane", "height": spec.ground_height, "normal": [0.0, 0.0, 1.0]},
        "body_rotation_deg": [round(math.degrees(float(params.body_angle(k / params.fps))), 6) for k in range(done + 1)],
        "uv": ({"u": "warp: distance down each panel's grain line in the flat pattern, metres",
                "v": "weft: distance across the panel in the flat pattern, metres"} if spec.cloth.seams is not None else
               {"u": "warp (cloth grid's first axis), rest-state arc length in metres",
                "v": "weft (cloth grid's second axis), rest-state arc length in metres"}),
        "cloth": {"grid": list(spec.cloth.shape), "closed_weft": spec.cloth.closed, "panels": spec.cloth.panels,
                  "seams": None if spec.cloth.seams is None else spec.cloth.seams.tolist(),
                  "vertices": int(len(spec.cloth.output_index)), "faces": int(len(spec.cloth.output_faces))},
        "parameters": params.to_json(),
        "parameters_sha256": params.key(),
        "resume_key": resume_key,
        "simulation": sim_info,
        "kesbrdf_version": __version__,
    }


def _owned_files(out_dir: Path) -> list[Path]:
    pats = ("frame_*.ply", "collider_*.ply", MANIFEST, CHECKPOINT)
    return [p for pat in pats for p in out_dir.glob(pat)]


def simulate_drape(scene: str, out_dir, frames: int = 120, *, fps: float = 30.0, resolution: int = 48,
                   seed: int = 0, overwrite: bool = False,
                   progress: Callable[[int, int], None] | None = None, **fabric) -> Path:
    """Simulate a drape with newton's XPBD on the CPU and write the frame sequence.

    Parameters
    ----------
    scene : {"sphere", "dressform"}
        A satin sheet falling onto a sphere, or an A-line skirt on a dress form.
    out_dir : path-like
        Output folder (created).  If it already holds a drape with the same parameters,
        the run resumes after its last finished frame.
    frames : int, ≥ 1
        Number of frames written, ``frame_0000.ply`` (t = 0) … ``frame_{frames-1}``.
    fps, resolution, seed :
        See :class:`DrapeParameters`.
    overwrite : bool
        Replace a drape with different parameters in ``out_dir`` instead of raising.
    progress : callable(done, total), optional
        Called after every finished frame (and once at the start with the frames
        already done).
    **fabric :
        Other :class:`DrapeParameters` fields (``density_kg_m2``, ``stretch_stiffness_n_m``,
        ``shear_ratio``, ``bending_rigidity_nm``, ``friction``, ``damping_per_s``,
        ``particle_radius_m``).

    Returns
    -------
    Path
        ``out_dir`` (it holds ``drape.json``).

    Raises
    ------
    DrapeError
        A parameter outside its range (the message names it and the range), or
        ``out_dir`` holds a different drape and ``overwrite`` is false.
    ImportError
        newton / warp-lang missing ("install kesbrdf[cloth]").
    """
    unknown = sorted(set(fabric) - set(DrapeParameters.__dataclass_fields__) - {"scene", "fps", "resolution", "seed"})
    if unknown:
        raise DrapeError(f"drape: unknown parameter(s) {', '.join(unknown)}; expected some of "
                         f"{', '.join(DrapeParameters.__dataclass_fields__)}")
    params = DrapeParameters(scene=scene, fps=fps, resolution=resolution, seed=seed, **fabric).validate()
    if not isinstance(frames, int) or isinstance(frames, bool) or not 1 <= frames <= 100000:
        raise DrapeError(f"drape: expected frames an integer in [1, 100000], got {frames!r}")
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise DrapeError(f"{where(out_dir)}expected an output folder, got a file")
    spec = build_scene(params)
    cloth = spec.cloth
    n_sub, _ = substeps_for(cloth, params.fps)  # refuses an unstable request before writing
    key = _resume_key(params, spec)
    out_dir.mkdir(parents=True, exist_ok=True)

    # resume or start over
    start_frame, state = -1, None
    manifest_path = out_dir / MANIFEST
    existing = None
    if manifest_path.is_file():
        try:
            existing = json.loads(manifest_path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise DrapeError(f"{where(manifest_path, exc.lineno)}expected JSON, got {exc.msg}") from None
    checkpoint = load_checkpoint(out_dir)
    other = (existing is not None and existing.get("resume_key") != key) or \
        (checkpoint is not None and checkpoint["key"] != key)
    if other:
        if not overwrite:
            raise DrapeError(f"{where(out_dir)}holds a drape with different parameters (or scene geometry, "
                             "or from another kesbrdf/newton/warp version); choose another folder or pass --overwrite")
        for p in _owned_files(out_dir):
            p.unlink()
        checkpoint = None
    if checkpoint is not None and (out_dir / frame_name(checkpoint["frame"])).is_file():
        start_frame, state = checkpoint["frame"], checkpoint

    if state is not None and state["q"].shape != cloth.positions.shape:
        raise DrapeError(f"{where(out_dir / CHECKPOINT)}expected {cloth.positions.shape} positions, got {state['q'].shape}")

    collider_files = []
    for k, c in enumerate(spec.colliders):
        name = f"collider_{k}.ply"
        if not (out_dir / name).is_file():
            p, n, uv, f = _scenes.collider_mesh(c)
            write_ply(out_dir / name, p, f, n, uv, comment=f"kesbrdf drape collider {c.kind} {c.label}")
        collider_files.append(name)

    sim_info = {
        "solver": "newton.solvers.SolverXPBD", "device": "cpu", "iterations": 1,
        "substeps_per_frame": n_sub, "dt_s": 1.0 / params.fps / n_sub, "stability_beta": STABILITY_BETA,
        "gravity_m_s2": [0.0, 0.0, -9.81], "newton_version": _version_of("newton"),
        "warp_version": _version_of("warp"),
        "bending_edge_ke": 3.0 * params.bending_rigidity_nm / cloth.min_spring_length ** 2,
    }

    def finish(done: int) -> None:
        write_text(manifest_path, json.dumps(_manifest(params, frames, done, spec, collider_files, sim_info, key), indent=1) + "\n")

    if start_frame >= frames - 1:  # already done (possibly more frames than asked)
        finish(frames - 1)
        if progress:
            progress(frames, frames)
        return out_dir

    wp, _ = _import_newton()
    with wp.ScopedDevice("cpu"):  # the velocity damping below edits CPU arrays in place
        return _run(spec, params, out_dir, key, frames, start_frame, state, finish, progress)


def _run(spec, params, out_dir, key, frames, start_frame, state, finish, progress) -> Path:
    cloth = spec.cloth
    sim = _Simulator(spec, params)
    if state is not None:
        sim.set(state["q"], state["qd"])
    else:
        q, qd = sim.get()
        q[:] = cloth.positions
        qd[:] = 0.0
        sim.set(q, qd)
        _write_frame(out_dir / frame_name(0), cloth, cloth.positions, 0, params.fps)
        _save_checkpoint(out_dir, 0, key, *sim.get())
        finish(0)
        start_frame = 0
    if progress:
        progress(start_frame + 1, frames)
    for k in range(start_frame + 1, frames):
        sim.step_frame(k)
        q, qd = sim.get()
        if not np.isfinite(q).all():
            raise DrapeError(f"drape: the simulation diverged at frame {k} (non-finite positions); "
                             "lower stretch_stiffness_n_m or raise density_kg_m2")
        _write_frame(out_dir / frame_name(k), cloth, q, k, params.fps)
        _save_checkpoint(out_dir, k, key, q, qd)
        finish(k)
        if progress:
            progress(k + 1, frames)
    return out_dir


def _version_of(module: str) -> str | None:
    try:
        from importlib.metadata import version

        return version({"warp": "warp-lang"}.get(module, module))
    except Exception:  # pragma: no cover - metadata missing
        return None

