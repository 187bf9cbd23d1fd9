"""The synthetic fabric library: thousands of seeded fabrics from five physical families.

What the leave-one-family-out evaluation (:mod:`kesbrdf.validate.lofo`) and a learned
prior draw from (issue 20).  Fabric ``k`` of a library with seed ``s`` is a pure
function of ``(s, k)``: its generator is ``SeedSequence(s, spawn_key=(k,))``, which is
exactly ``SeedSequence(s).spawn(N)[k]`` for every N > k, so a fabric never depends on
how many fabrics there are, how the work is split into shards, or which worker ran it.
Its children ``spawn_key=(k, 0)``, ``(k, 1)``, ``(k, 2)`` draw the parameters, the
paper-protocol noise and the dense-protocol noise.

Families (round robin: fabric k is of family ``families[k % len(families)]``, so every
prefix of the library is stratified); ranges are documented in docs/validation.md:

* ``irawan2012``: one of the six Irawan–Marschner weaves with its tilt range u_max,
  twist ψ, phase concentration β and colours k_d, k_s jittered;
* ``sadeghi2013``: one of the six Sadeghi et al. 2013 Table II presets with its lobe
  widths γ_s, γ_v, tangent offsets and thread colours A jittered;
* ``ward``: anisotropic Ward (roughness α_x, α_y, colour ρ_d, ρ_s);
* ``ashikhmin_shirley``: Ashikhmin–Shirley (exponents n_u, n_v, R_s, colour R_d);
* ``ggx``: anisotropic GGX over a Lambertian body (α_x, α_y, η, ρ_d, k_s).

Microflake / SGGX volumes (SpongeCake and relatives) are never a family here.

Per fabric, arrays (``C`` = 3 channels):

* ``paper``, ``dense``: the simulated measurement values (float64; 116 and 900
  samples, :func:`kesbrdf.measure.gonio.measure` with ``noise=lofo.NOISE``), equal bit
  for bit to ``measure(ref, protocol, noise=NOISE, rng=noise_seed(seed, k, protocol))``;
* ``paper_clean``, ``dense_clean``: the same samples without noise (float64; the
  measurement's σ is ``NOISE × |clean|``);
* ``held``: the noise-free truth at the held-out orientations
  (:data:`kesbrdf.validate.compare.HELD_OUT_DEG`, paper incidence line), float32;
* ``hemi90``, ``hemi45``: the noise-free truth on the two Fig. 6 hemispheres (2.5° grid),
  float32 — the truths :func:`kesbrdf.validate.lofo.score` scores against.

The directions of every array are the same for every fabric and are stored once
(``geometry.npz``).  On disk a library is a folder: ``geometry.npz``, shards
``shard-<start>-<stop>.npz`` (+ ``.json`` with the shard's fabric specs and digests) and
``manifest.json`` (seed, N, families, the parameter table and the content sha256).
The content sha256 (:func:`library_sha256`) hashes the header and every fabric's digest in
index order, so it is the same whatever the shard size.  Building on Dask:
:mod:`kesbrdf.batch.fabric_library`.
"""

from __future__ import annotations

import functools
import hashlib
import io
import json
import math
from pathlib import Path

import numpy as np

from kesbrdf._atomic import write_bytes, write_text
from kesbrdf.errors import KesbrdfError
from kesbrdf.io.files import sha256_file
from kesbrdf.geometry import in_plane_directions, spherical_to_cartesian
from kesbrdf.measure.gonio import measure, protocol_geometry
from kesbrdf.validate.compare import HELD_OUT_DEG, HEMISPHERE_LIGHTS_DEG, hemisphere_directions

__all__ = ["LIBRARY_FAMILIES", "FORMAT", "VERSION", "NOISE", "ARRAYS", "fabric_seed", "noise_seed", "draw_fabric",
           "build_reference", "compute_fabric", "fabric_digest", "library_sha256", "geometry", "write_geometry",
           "shard_name", "build_shard", "read_shard_meta", "shard_valid", "FabricLibrary", "load_library",
           "stratified", "truth_sets", "header", "check_families"]

#: The drawable families, in round-robin order.
LIBRARY_FAMILIES = ("irawan2012", "sadeghi2013", "ward", "ashikhmin_shirley", "ggx")
#: Never a family (kept for an independent held-out check).
FORBIDDEN = ("microflake", "sggx", "spongecake")
#: The artefact's format name and version (a change of what a fabric holds bumps it).
FORMAT = "kesbrdf-fabric-library"
VERSION = 1
#: Arrays of one fabric, in digest order: (name, dtype).
ARRAYS = (("paper", "<f8"), ("paper_clean", "<f8"), ("dense", "<f8"), ("dense_clean", "<f8"),
          ("held", "<f4"), ("hemi90", "<f4"), ("hemi45", "<f4"))
#: Multiplicative noise of the simulated measurements (σ = 2 % of the value), as
#: benchmarks/bench_selection.py; :data:`kesbrdf.validate.lofo.NOISE` is this one.
NOISE = 0.02
_PROTOCOL_STREAM = {"paper": 1, "dense": 2}


# -- seeds and draws ------------------------------------------------------------------------

def fabric_seed(seed: int, k: int) -> np.random.SeedSequence:
    """The generator of fabric ``k``: ``SeedSequence(seed).spawn(N)[k]`` for any N > k.

    >>> a = fabric_seed(0, 3); b = np.random.SeedSequence(0).spawn(5)[3]
    >>> a.generate_state(2).tolist() == b.generate_state(2).tolist()
    True
    """
    return np.random.SeedSequence(int(seed), spawn_key=(int(k),))


def noise_seed(seed: int, k: int, protocol: str) -> np.random.SeedSequence:
    """The noise generator of fabric ``k``'s measurement in ``protocol`` (its child 1 or 2)."""
    return np.random.SeedSequence(int(seed), spawn_key=(int(k), _PROTOCOL_STREAM[protocol]))


def _logu(rng, lo, hi, size=None):
    return np.exp(rng.uniform(math.log(lo), math.log(hi), size))


def _floats(x) -> list:
    return [float(v) for v in np.ravel(x)]


def _draw_irawan(rng) -> dict:
    from dataclasses import asdict

    from kesbrdf.references.irawan2012 import PRESET_NAMES, PRESETS

    preset = PRESET_NAMES[int(rng.integers(len(PRESET_NAMES)))]
    base = PRESETS[preset]
    yarns = {}
    for part in ("warp", "weft"):
        y = asdict(getattr(base, part))
        y["umax_deg"] = float(min(y["umax_deg"] * rng.uniform(0.7, 1.3), 80.0))
        if y["psi_deg"] != 0.0:  # staple yarns keep their twist's sign
            y["psi_deg"] = float(y["psi_deg"] * rng.uniform(0.8, 1.2))
        y["kd"] = _floats(np.minimum(np.asarray(y["kd"]) * rng.uniform(0.5, 1.5, 3), 0.6))
        y["ks"] = _floats(np.minimum(np.asarray(y["ks"]) * rng.uniform(0.5, 1.5), 0.5))
        yarns[part] = y
    return {"preset": preset, "warp": yarns["warp"], "weft": yarns["weft"], "warp_coverage": base.warp_coverage,
            "alpha": base.alpha, "beta": float(base.beta * _logu(rng, 0.5, 2.0)), "ss": base.ss}


def _draw_sadeghi(rng) -> dict:
    from kesbrdf.references.sadeghi2013 import PRESET_NAMES, PRESETS

    preset = PRESET_NAMES[int(rng.integers(len(PRESET_NAMES)))]
    base = PRESETS[preset]
    fams = {}
    for part in ("warp", "weft"):
        f = getattr(base, part)
        width = float(rng.uniform(0.6, 1.5))
        offsets = np.clip(np.asarray(f.offsets) * rng.uniform(0.8, 1.2), -math.pi / 2, math.pi / 2)
        fams[part] = {"eta": f.eta, "A": _floats(np.asarray(f.A) * rng.uniform(0.6, 1.6, 3)), "kd": f.kd,
                      "gamma_s": f.gamma_s * width, "gamma_v": f.gamma_v * width, "a": f.a,
                      "offsets": _floats(offsets), "lengths": list(f.lengths)}
    return {"preset": preset, **fams}


def _draw_ward(rng) -> dict:
    ax, ay = _logu(rng, 0.04, 0.5, 2)
    return {"alpha_x": float(ax), "alpha_y": float(ay), "rho_d": _floats(rng.uniform(0.02, 0.6, 3)),
            "rho_s": float(rng.uniform(0.02, 0.25))}


def _draw_ashikhmin_shirley(rng) -> dict:
    nu, nv = _logu(rng, 5.0, 1000.0, 2)
    return {"n_u": float(nu), "n_v": float(nv), "R_s": float(rng.uniform(0.02, 0.15)),
            "R_d": _floats(rng.uniform(0.05, 0.6, 3))}


def _draw_ggx(rng) -> dict:
    ax, ay = _logu(rng, 0.04, 0.7, 2)
    return {"alpha_x": float(ax), "alpha_y": float(ay), "eta": float(rng.uniform(1.3, 1.8)),
            "rho_d": _floats(rng.uniform(0.02, 0.8, 3)), "k_s": float(rng.uniform(0.3, 1.0))}


_DRAWS = {"irawan2012": _draw_irawan, "sadeghi2013": _draw_sadeghi, "ward": _draw_ward,
          "ashikhmin_shirley": _draw_ashikhmin_shirley, "ggx": _draw_ggx}


def check_families(families, flag: str = "families") -> tuple[str, ...]:
    """The families as a tuple; a one-line error for an unknown or forbidden name."""
    families = tuple(families)
    bad = [f for f in families if any(x in str(f).lower() for x in FORBIDDEN)]
    if bad:
        raise KesbrdfError(f"{flag}: microflake/SGGX cloth is kept for an independent check, got {', '.join(bad)}")
    unknown = [f for f in families if f not in _DRAWS]
    if unknown or not families or len(set(families)) != len(families):
        raise KesbrdfError(f"{flag}: expected distinct names from {', '.join(LIBRARY_FAMILIES)}, "
                           f"got {', '.join(map(str, families)) or 'none'}")
    return families


def draw_fabric(seed: int, k: int, families=LIBRARY_FAMILIES) -> dict:
    """Fabric ``k``'s spec ``{"index", "family", "name", "params"}`` (JSON-ready floats)."""
    family = families[k % len(families)]
    rng = np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(k), 0)))
    params = _DRAWS[family](rng)
    tag = params.get("preset")
    name = f"{family}_{tag}_{k:05d}" if tag else f"{family}_{k:05d}"
    return {"index": int(k), "family": family, "name": name, "params": params}


def build_reference(spec: dict):
    """The reference BRDF of a fabric spec (:func:`draw_fabric`)."""
    fam, p = spec["family"], spec["params"]
    if fam == "irawan2012":
        from kesbrdf.references.irawan2012 import Irawan2012, Weave, Yarn

        def yarn(d):
            return Yarn(**{**d, "kd": tuple(d["kd"]), "ks": tuple(d["ks"])})

        return Irawan2012(Weave(name=spec["name"], warp=yarn(p["warp"]), weft=yarn(p["weft"]),
                                warp_coverage=p["warp_coverage"], alpha=p["alpha"], beta=p["beta"], ss=p["ss"],
                                source=f"kesbrdf fabric library, jittered {p['preset']}"))
    if fam == "sadeghi2013":
        from kesbrdf.references.sadeghi2013 import Fabric, Family, Sadeghi2013

        fams = [Family(**{**p[part], "A": tuple(p[part]["A"]), "offsets": tuple(p[part]["offsets"]),
                          "lengths": tuple(p[part]["lengths"])}) for part in ("warp", "weft")]
        return Sadeghi2013(Fabric(spec["name"], warp=fams[0], weft=fams[1]))
    if fam == "ward":
        from kesbrdf.references.ward import AnisotropicWard

        return AnisotropicWard(p["alpha_x"], p["alpha_y"], p["rho_d"], p["rho_s"])
    if fam == "ashikhmin_shirley":
        from kesbrdf.references.ashikhmin_shirley import AshikhminShirley

        return AshikhminShirley(p["n_u"], p["n_v"], R_s=p["R_s"], R_d=p["R_d"])
    if fam == "ggx":
        from kesbrdf.references.ggx import AnisotropicGGX

        return AnisotropicGGX(p["alpha_x"], p["alpha_y"], eta=p["eta"], rho_d=p["rho_d"], k_s=p["k_s"])
    raise KesbrdfError(f"fabric {spec.get('name')}: expected a family of {', '.join(LIBRARY_FAMILIES)}, got {fam!r}")


# -- what is stored -------------------------------------------------------------------------

def geometry() -> dict:
    """The directions of every per-fabric array, float64: ``<array>_wi``, ``<array>_wr`` (n, 3),
    and ``<protocol>_psi`` / ``_theta_i`` / ``_theta_r`` of the measurements."""
    out = {}
    for protocol in ("paper", "dense"):
        psi, ti, tr = protocol_geometry(protocol)
        out[f"{protocol}_psi"], out[f"{protocol}_theta_i"], out[f"{protocol}_theta_r"] = psi, ti, tr
        out[f"{protocol}_wi"], out[f"{protocol}_wr"] = in_plane_directions(psi, ti, tr)
    psi, ti, tr = protocol_geometry("paper", orientations_deg=HELD_OUT_DEG)
    out["held_wi"], out["held_wr"] = in_plane_directions(psi, ti, tr)
    wr = hemisphere_directions()[0].reshape(-1, 3)
    for (t, p), tag in zip(HEMISPHERE_LIGHTS_DEG, ("hemi90", "hemi45")):
        out[f"{tag}_wi"] = np.broadcast_to(spherical_to_cartesian(math.radians(t), math.radians(p)), wr.shape).copy()
        out[f"{tag}_wr"] = wr
    return {k: np.ascontiguousarray(v, dtype=float) for k, v in out.items()}


def write_geometry(folder) -> Path:
    """Write ``geometry.npz`` into ``folder`` (atomically); returns its path."""
    buf = io.BytesIO()
    np.savez(buf, **geometry())
    return write_bytes(Path(folder) / "geometry.npz", buf.getvalue())


def compute_fabric(seed: int, spec: dict, geom: dict | None = None) -> dict:
    """The arrays of one fabric (module docstring), in :data:`ARRAYS` order and dtypes."""
    ref = build_reference(spec)
    geom = geom or geometry()
    k = spec["index"]
    out = {}
    for protocol in ("paper", "dense"):
        m = measure(ref, protocol=protocol, noise=NOISE, rng=noise_seed(seed, k, protocol))
        out[protocol] = m.values
        out[f"{protocol}_clean"] = np.asarray(ref(geom[f"{protocol}_wi"], geom[f"{protocol}_wr"]), float)
    for tag in ("held", "hemi90", "hemi45"):
        out[tag] = np.asarray(ref(geom[f"{tag}_wi"], geom[f"{tag}_wr"]), float)
    return {name: np.ascontiguousarray(out[name], dtype=dtype) for name, dtype in ARRAYS}


def _canonical(doc) -> bytes:
    return json.dumps(doc, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()


def fabric_digest(spec: dict, arrays: dict) -> str:
    """sha256 of a fabric: its spec (canonical JSON), then every array's name, dtype, shape, bytes."""
    h = hashlib.sha256(_canonical(spec))
    for name, _ in ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(f"\n{name}:{a.dtype.str}:{a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def header(seed: int, n: int, families) -> dict:
    """What identifies a library's content besides its fabrics."""
    return {"format": FORMAT, "version": VERSION, "seed": int(seed), "n": int(n), "families": list(families),
            "noise": NOISE}


def library_sha256(head: dict, digests) -> str:
    """The content sha256: the header and every fabric digest in index order (shard-size free)."""
    h = hashlib.sha256(_canonical(head))
    for d in digests:
        h.update(b"\n" + d.encode())
    return h.hexdigest()


# -- shards ---------------------------------------------------------------------------------

def shard_name(start: int, stop: int) -> str:
    """``shard-<start>-<stop>`` (fabrics start ≤ k < stop)."""
    return f"shard-{start:06d}-{stop:06d}"


def _shard_key(seed, families, start, stop) -> dict:
    # the directions the shard was measured on are part of it: a shard built on another
    # geometry (the code's protocols changed) is not reused
    return {"format": FORMAT, "version": VERSION, "seed": int(seed), "families": list(families),
            "start": int(start), "stop": int(stop), "noise": NOISE, "geometry": geometry_sha256()}


@functools.lru_cache(maxsize=1)
def geometry_sha256() -> str:
    """sha256 of :func:`geometry` (every array's name, shape and float64 bytes, sorted by name)."""
    h = hashlib.sha256()
    for name, a in sorted(geometry().items()):
        a = np.ascontiguousarray(a, dtype=np.float64)
        h.update(f"{name}:{a.shape}\n".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def build_shard(folder, seed: int, families, start: int, stop: int) -> dict:
    """Compute fabrics ``start ≤ k < stop`` and write ``<shard>.npz`` then ``<shard>.json``
    (atomically, the JSON last: it is the shard's commit).  Returns the JSON document."""
    import time

    folder = Path(folder)
    families = tuple(families)
    t0, c0 = time.perf_counter(), time.process_time()
    geom = geometry()
    specs, digests, arrays = [], [], {}
    for k in range(start, stop):
        spec = draw_fabric(seed, k, families)
        a = compute_fabric(seed, spec, geom)
        specs.append(spec)
        digests.append(fabric_digest(spec, a))
        for name, _ in ARRAYS:
            arrays[f"f{k:06d}.{name}"] = a[name]
    name = shard_name(start, stop)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    npz = write_bytes(folder / f"{name}.npz", buf.getvalue())
    doc = {"key": _shard_key(seed, families, start, stop), "file": npz.name, "sha256": sha256_file(npz),
           "fabrics": [{**s, "digest": d} for s, d in zip(specs, digests)],
           "seconds": time.perf_counter() - t0, "cpu_seconds": time.process_time() - c0}
    write_text(folder / f"{name}.json", json.dumps(doc, indent=1) + "\n")
    return doc


def read_shard_meta(folder, start: int, stop: int) -> dict | None:
    """The shard's JSON document, or None when missing or unreadable."""
    path = Path(folder) / f"{shard_name(start, stop)}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def shard_valid(folder, seed: int, families, start: int, stop: int) -> dict | None:
    """The shard's JSON when it is finished, of this key, and its npz still has its sha256."""
    doc = read_shard_meta(folder, start, stop)
    if not doc or doc.get("key") != _shard_key(seed, tuple(families), start, stop):
        return None
    npz = Path(folder) / doc.get("file", "")
    if not npz.is_file() or sha256_file(npz) != doc.get("sha256"):
        return None
    return doc


# -- reading --------------------------------------------------------------------------------

class FabricLibrary:
    """A built library folder (``manifest.json``, ``geometry.npz``, shards), read lazily.

    ``specs`` is the parameter table (one dict per fabric, index order); ``arrays(k)``
    the stored arrays of fabric k; ``reference(k)`` its BRDF; ``measurement(k,
    protocol)`` its simulated measurement; ``truths(k)`` the noise-free test sets in the
    form :func:`kesbrdf.validate.lofo.score` takes.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        path = self.folder / "manifest.json"
        try:
            self.manifest = json.loads(path.read_text())
        except OSError as exc:
            raise KesbrdfError(f"fabric library {self.folder}: expected a built library (manifest.json), "
                               f"got {exc.strerror or exc}") from None
        except ValueError as exc:
            raise KesbrdfError(f"fabric library {path}: expected JSON, got {exc}") from None
        if self.manifest.get("format") != FORMAT or self.manifest.get("version") != VERSION:
            raise KesbrdfError(f"fabric library {path}: expected format {FORMAT} version {VERSION}, got "
                               f"{self.manifest.get('format')} version {self.manifest.get('version')}")
        self.seed = int(self.manifest["seed"])
        self.n = int(self.manifest["n"])
        self.families = tuple(self.manifest["families"])
        self.specs = self.manifest["fabrics"]
        self._shard_of = {}
        for s in self.manifest["shards"]:
            for k in range(s["start"], s["stop"]):
                self._shard_of[k] = s["file"]
        self._cache: tuple[str, dict] | None = None
        self._geom: dict | None = None

    def __len__(self) -> int:
        return self.n

    @property
    def sha256(self) -> str:
        return self.manifest["sha256"]

    def geometry(self) -> dict:
        if self._geom is None:
            with np.load(self.folder / "geometry.npz") as z:
                self._geom = {k: z[k] for k in z.files}
        return self._geom

    def arrays(self, k: int) -> dict:
        """The stored arrays of fabric ``k`` ({name: array} of :data:`ARRAYS`)."""
        file = self._shard_of[int(k)]
        if self._cache is None or self._cache[0] != file:
            with np.load(self.folder / file) as z:
                self._cache = (file, {n: z[n] for n in z.files})
        data = self._cache[1]
        return {name: data[f"f{int(k):06d}.{name}"] for name, _ in ARRAYS}

    def indices(self, family: str) -> list[int]:
        return [s["index"] for s in self.specs if s["family"] == family]

    def reference(self, k: int):
        return build_reference(self.specs[int(k)])

    def measurement(self, k: int, protocol: str = "paper"):
        """Fabric ``k``'s stored measurement, equal to ``measure(reference(k), protocol,
        noise=NOISE, rng=noise_seed(seed, k, protocol))`` in values and σ."""
        from kesbrdf.measure.measurement import Measurement

        spec, a, g = self.specs[int(k)], self.arrays(k), self.geometry()
        generator = {**spec["params"], "reference": spec["family"], "protocol": protocol, "step_deg": None,
                     "noise": NOISE, "noise_floor": 0.0, "library_seed": self.seed, "library_index": int(k)}
        meta = {"sample": f"fabric library {spec['name']}", "instrument": "kesbrdf virtual gonioreflectometer",
                "quantity": "brdf", "simulated": "true", "generator": json.dumps(generator, sort_keys=True)}
        return Measurement.in_plane(g[f"{protocol}_psi"], g[f"{protocol}_theta_i"], g[f"{protocol}_theta_r"],
                                    a[protocol], channels=("R", "G", "B"),
                                    uncertainty=NOISE * np.abs(a[f"{protocol}_clean"]), metadata=meta)

    def truths(self, k: int) -> dict:
        """``{"held": (wi, wr, truth), "hemis": [(wi, wr, truth) × 2]}`` of fabric ``k``."""
        a, g = self.arrays(k), self.geometry()
        return truth_sets({tag: (g[f"{tag}_wi"], g[f"{tag}_wr"], np.asarray(a[tag], float))
                           for tag in ("held", "hemi90", "hemi45")})


def truth_sets(parts: dict) -> dict:
    """The lofo test-set structure from ``{"held", "hemi90", "hemi45": (wi, wr, values)}``."""
    return {"held": parts["held"], "hemis": [parts["hemi90"], parts["hemi45"]]}


def load_library(folder) -> FabricLibrary:
    """Open a built library folder (a one-line error when it is not one)."""
    return FabricLibrary(folder)


def stratified(library: FabricLibrary, per_family: int, seed: int = 0, families=None) -> dict:
    """``{family: [indices]}``: ``per_family`` fabrics drawn without replacement per family
    (seeded; sorted), the whole family when it has fewer."""
    if not (isinstance(per_family, int) and per_family >= 1):
        raise KesbrdfError(f"per_family: expected an integer >= 1, got {per_family!r}")
    families = library.families if families is None else tuple(families)
    unknown = [f for f in families if f not in library.families]
    if unknown:
        raise KesbrdfError(f"families: expected names from the library ({', '.join(library.families)}), "
                           f"got {', '.join(unknown)}")
    rng = np.random.default_rng(seed)
    out = {}
    for fam in families:
        idx = library.indices(fam)
        pick = rng.choice(len(idx), size=min(per_family, len(idx)), replace=False)
        out[fam] = sorted(int(idx[j]) for j in pick)
    return out
