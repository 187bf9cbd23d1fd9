"""Filmic tone curve, OIDN denoising and the studio lighting (kesbrdf.render.post / studio)."""

import numpy as np
import pytest

from kesbrdf.render import post

#: Denoised 4-spp RMSE against a 512-spp reference, as a fraction of the noisy 4-spp
#: RMSE.  OIDN with albedo + normal removes most of the Monte Carlo noise of this
#: smooth scene (measured 0.16); 0.6 still fails a denoiser that does nothing (1.0) or
#: one fed Gaussian-filtered, pixel-correlated noise (0.96 measured before the box filter).
DENOISE_GAIN = 0.6


def test_tone_curve_maps_zero_to_zero_and_is_monotone():
    x = np.concatenate([[0.0], np.geomspace(1e-6, 1e4, 4000)])
    y = post.aces_filmic(x)
    assert y[0] == 0.0
    assert (np.diff(y) >= 0).all()
    rising = x < 10  # strictly increasing until the shoulder reaches the clip at 1 (x ≈ 12)
    assert (np.diff(y[rising]) > 0).all()
    assert 0.0 <= y.min() and y.max() <= 1.0
    # the fit's known anchors: 0.18 grey -> 0.140, 1 -> 0.673
    assert post.aces_filmic(0.18) == pytest.approx(0.1401, abs=1e-3)
    assert post.aces_filmic(1.0) == pytest.approx(0.6733, abs=1e-3)
    img = np.zeros((2, 2, 3))
    assert (post.to_srgb8(img) == 0).all()
    assert (post.to_srgb8(img + 1e6) == 255).all()
    with pytest.raises(ValueError, match="tone curve"):
        post.tonemap(img, curve="reinhard")


def test_studio_environment_is_finite_hdr():
    from kesbrdf.render.studio import environment_map

    env = environment_map(128)
    assert env.shape == (64, 128, 3) and np.isfinite(env).all() and env.min() > 0
    assert env.max() > 2.0  # the soft boxes: HDR, not a clipped LDR room
    assert np.median(env) < 0.05  # a dark room around them


@pytest.mark.render
def test_denoise_reduces_error_against_a_high_spp_reference(model_files, render_module):
    pytest.importorskip("pyoidn")
    from kesbrdf.render import scenes

    path, _ = model_files["rgb"]
    kw = dict(resolution=(64, 48), env="studio-hdr", light="studio", base_color=(0.4, 0.05, 0.05), denoise=True)
    import mitsuba as mi

    def raw(spp, seed):  # the aov integrator's channels on the same box-filtered film
        opts = scenes.RenderOptions(spp=spp, seed=seed, **kw)
        return np.array(mi.render(scenes.load_scene(path, "sphere", opts), spp=spp, seed=seed), np.float32)

    ref = raw(512, 7)[..., :3]
    low = raw(4, 1)
    assert low.shape[-1] == 9  # colour, albedo, shading normal
    noisy = low[..., :3]
    den = post.denoise(noisy, low[..., 3:6], low[..., 6:9])
    rmse = lambda a: float(np.sqrt(np.mean((a - ref) ** 2)))  # noqa: E731
    assert np.isfinite(den).all() and den.shape == noisy.shape
    assert rmse(den) < DENOISE_GAIN * rmse(noisy), (rmse(den), rmse(noisy))
