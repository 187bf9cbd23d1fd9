"""The synthetic fabric library (kesbrdf.validate.library) and lofo drawing from it.

A small library (10 fabrics, two of each family) is built serially once per module
(~2 s); the bit-identity of a rebuild on a Dask cluster is tests/batch/test_fabric_library_dask.py.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from kesbrdf.errors import KesbrdfError
from kesbrdf.measure.gonio import measure
from kesbrdf.validate import library as L
from kesbrdf.validate.lofo import NOISE, family_library_from, library_inputs, run_lofo, score

#: float32 storage of the truths: a relative rounding of 2^-24 ≈ 6e-8 per value.
FLOAT32_RTOL = 1e-6


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    from kesbrdf.batch.fabric_library import build_fabric_library

    out = tmp_path_factory.mktemp("fablib")
    man = build_fabric_library(out, 10, seed=5, shard_size=4, workers=0)
    return out, man


def test_fabric_seed_is_the_spawned_child_whatever_n():
    """Fabric k's generators are SeedSequence(seed).spawn(N)[k] (and its children) for any N > k."""
    for n in (4, 2000):
        child = np.random.SeedSequence(9).spawn(n)[3]
        assert L.fabric_seed(9, 3).generate_state(4).tolist() == child.generate_state(4).tolist()
        params, paper, dense = child.spawn(3)
        got = np.random.SeedSequence(9, spawn_key=(3, 0)).generate_state(4).tolist()
        assert got == params.generate_state(4).tolist()
        assert L.noise_seed(9, 3, "paper").generate_state(4).tolist() == paper.generate_state(4).tolist()
        assert L.noise_seed(9, 3, "dense").generate_state(4).tolist() == dense.generate_state(4).tolist()
    assert L.draw_fabric(9, 3) == L.draw_fabric(9, 3)
    assert L.draw_fabric(9, 3) != L.draw_fabric(10, 3)


def test_families_round_robin_and_never_microflake():
    fams = [L.draw_fabric(0, k)["family"] for k in range(10)]
    assert fams == list(L.LIBRARY_FAMILIES) * 2
    assert len(L.LIBRARY_FAMILIES) >= 5
    with pytest.raises(KesbrdfError, match="microflake/SGGX"):
        L.check_families(("ward", "sggx_cloth"))
    with pytest.raises(KesbrdfError, match="expected distinct names"):
        L.check_families(("ward", "ward"))


def test_draws_stay_in_their_documented_ranges():
    """docs/validation.md "The fabric library" lists these ranges; 200 draws per family."""
    for k in range(1000):
        s = L.draw_fabric(1, k)
        p = s["params"]
        if s["family"] == "ward":
            assert 0.04 <= p["alpha_x"] <= 0.5 and 0.04 <= p["alpha_y"] <= 0.5 and 0.02 <= p["rho_s"] <= 0.25
        elif s["family"] == "ashikhmin_shirley":
            assert 5 <= p["n_u"] <= 1000 and 5 <= p["n_v"] <= 1000 and p["R_s"] + max(p["R_d"]) <= 1
        elif s["family"] == "ggx":
            assert 0.04 <= min(p["alpha_x"], p["alpha_y"]) and max(p["alpha_x"], p["alpha_y"]) <= 0.7
            assert 1.3 <= p["eta"] <= 1.8 and 0.3 <= p["k_s"] <= 1.0 and max(p["rho_d"]) <= 0.8
        elif s["family"] == "irawan2012":
            for y in (p["warp"], p["weft"]):
                assert 0 < y["umax_deg"] <= 80 and max(y["kd"]) <= 0.6 and max(y["ks"]) <= 0.5
        else:
            for part in ("warp", "weft"):
                assert all(abs(o) <= np.pi / 2 for o in p[part]["offsets"]) and p[part]["gamma_s"] > 0


def test_stored_measurements_and_truths_are_the_references(built):
    out, man = built
    lib = L.load_library(out)
    assert lib.sha256 == man["sha256"] and len(lib) == 10
    for k in (0, 1, 4):  # Irawan, Sadeghi, GGX
        ref = lib.reference(k)
        for protocol, n in (("paper", 116), ("dense", 900)):
            want = measure(ref, protocol, noise=NOISE, rng=L.noise_seed(5, k, protocol))
            got = lib.measurement(k, protocol)
            assert len(got) == n
            np.testing.assert_array_equal(got.values, want.values)        # bit for bit
            np.testing.assert_array_equal(got.uncertainty, want.uncertainty)
            np.testing.assert_array_equal(got.wi, want.wi)
        from kesbrdf.validate.lofo import scoring_truths

        fresh, stored = scoring_truths(ref), lib.truths(k)
        np.testing.assert_allclose(stored["held"][2], fresh["held"][2], rtol=FLOAT32_RTOL)
        for a, b in zip(stored["hemis"], fresh["hemis"]):
            np.testing.assert_array_equal(a[0], b[0])
            np.testing.assert_array_equal(a[1], b[1])
            np.testing.assert_allclose(a[2], b[2], rtol=FLOAT32_RTOL)


def test_content_hash_is_recomputable_from_the_stored_arrays(built):
    """The manifest's sha256 is what its fabrics' arrays hash to (nothing else enters it)."""
    out, man = built
    lib = L.load_library(out)
    digests = [L.fabric_digest({k: v for k, v in s.items() if k != "digest"}, lib.arrays(s["index"]))
               for s in lib.specs]
    assert digests == [s["digest"] for s in lib.specs]
    assert L.library_sha256(L.header(5, 10, L.LIBRARY_FAMILIES), digests) == man["sha256"]


def test_cache_skips_finished_shards_and_rebuilds_a_damaged_one(built, tmp_path):
    import shutil

    from kesbrdf.batch.fabric_library import build_fabric_library

    out, man = built
    copy = tmp_path / "lib"
    shutil.copytree(out, copy)
    again = build_fabric_library(copy, 10, seed=5, shard_size=4, workers=0)
    assert again["run"]["shards_built"] == 0 and again["run"]["shards_cached"] == 3
    assert again["build"] == man["build"]  # a run that builds nothing keeps the build's record
    # a truncated shard and a missing one are rebuilt, to the same content
    first = copy / man["shards"][0]["file"]
    first.write_bytes(first.read_bytes()[:100])
    (copy / man["shards"][2]["file"]).unlink()
    fixed = build_fabric_library(copy, 10, seed=5, shard_size=4, workers=0)
    assert fixed["run"]["shards_built"] == 2 and fixed["sha256"] == man["sha256"]
    # another shard size replaces the shard files, same content hash
    other = build_fabric_library(copy, 10, seed=5, shard_size=3, workers=0)
    assert other["sha256"] == man["sha256"]
    assert sorted(p.name for p in copy.glob("shard-*.npz")) == [s["file"] for s in other["shards"]]


def test_a_shard_measured_on_other_directions_is_not_reused(built, tmp_path, monkeypatch):
    """The shard's key holds the geometry's digest: after a change of the protocols'
    directions, every shard is measured again (it was reused, with the old values)."""
    import shutil

    from kesbrdf.batch.fabric_library import build_fabric_library

    out, man = built
    copy = tmp_path / "lib"
    shutil.copytree(out, copy)
    assert all(L.shard_valid(copy, 5, tuple(man["families"]), s["start"], s["stop"]) for s in man["shards"])
    monkeypatch.setattr(L, "geometry_sha256", lambda: "0" * 64)  # as after a change of the directions
    assert not any(L.shard_valid(copy, 5, tuple(man["families"]), s["start"], s["stop"]) for s in man["shards"])
    again = build_fabric_library(copy, 10, seed=5, shard_size=4, workers=0)
    assert again["run"]["shards_built"] == 3 and again["run"]["shards_cached"] == 0


def test_family_library_from_draws_a_stratified_subsample(built):
    out, _ = built
    lib = family_library_from(out, per_family=1, seed=0, families=("ward", "ggx"))
    assert list(lib) == ["ward", "ggx"] and all(len(v) == 1 for v in lib.values())
    assert lib == {f: dict(v) for f, v in lib.items()}  # plain dicts, as family_library
    assert family_library_from(out, 1, seed=0, families=("ward", "ggx")).keys() == lib.keys()
    whole = family_library_from(out, per_family=5)
    assert {f: len(v) for f, v in whole.items()} == {f: 2 for f in L.LIBRARY_FAMILIES}
    with pytest.raises(KesbrdfError, match="per_family: expected an integer >= 1"):
        family_library_from(out, per_family=0)


def test_run_lofo_uses_the_librarys_measurements_and_truths(built):
    """A fitter that returns the noise-free reference scores ~0 against the stored
    truths (float32 rounding only); one that returns zeros scores NRMSE = RMS/mean ≥ 1
    (Cauchy–Schwarz), so the harness still fails a wrong model on library fabrics."""
    out, _ = built
    refs = family_library_from(out, per_family=1, families=("ggx", "ward"))
    data = library_inputs(out, refs)
    seen = []

    def truth(m):
        seen.append(m.metadata["sample"])
        name = m.metadata["sample"].split()[-1]
        return next(r for f in refs.values() for n, r in f.items() if n == name)

    def zeros(m):
        return lambda wi, wr: np.zeros(np.broadcast_shapes(np.shape(wi), np.shape(wr))[:-1] + (3,))

    res = run_lofo(refs, {"truth": truth, "zeros": zeros}, data=data)
    assert all(s.startswith("fabric library ") for s in seen) and len(seen) == 4  # 2 fabrics × 2 protocols
    for fam in res.values():
        for rows in fam.values():
            for p in ("paper", "dense"):
                assert rows[p]["truth"]["orientations"] < 1e-6 and rows[p]["truth"]["hemispheres"] < 1e-6
                assert rows[p]["zeros"]["orientations"] >= 1.0 and rows[p]["zeros"]["hemispheres"] >= 1.0


def test_manifest_records_the_parameter_table(built):
    out, man = built
    doc = json.loads((out / "manifest.json").read_text())
    assert doc["seed"] == 5 and doc["n"] == 10 and doc["families"] == list(L.LIBRARY_FAMILIES)
    assert [f["index"] for f in doc["fabrics"]] == list(range(10))
    assert all(set(f) == {"index", "family", "name", "params", "digest"} for f in doc["fabrics"])
    assert L.build_reference(doc["fabrics"][2]).params()["alpha_x"] == doc["fabrics"][2]["params"]["alpha_x"]
    with pytest.raises(KesbrdfError, match="expected a built library"):
        L.load_library(out / "nowhere")


def test_library_score_path_matches_a_fresh_score(built):
    """score() against the stored truths equals score() against fresh ones (to float32 rounding)."""
    out, _ = built
    lib = L.load_library(out)
    ref = lib.reference(2)
    pred = lambda wi, wr: 1.1 * ref(wi, wr)  # noqa: E731 - 10 % too bright: NRMSE = 0.1 RMS/mean ≥ 0.1
    a, b = score(pred, ref, lib.truths(2)), score(pred, ref)
    for key in ("orientations", "hemispheres"):
        assert a[key] >= 0.1 and a[key] == pytest.approx(b[key], rel=FLOAT32_RTOL)
