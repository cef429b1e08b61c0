"""Particles on the GPU heights: above the surface, on the terrain, following edits, drawn where they project."""

import numpy as np
import pytest

from hybrid.camera.view import default_view
from hybrid.errors import TerrabenchError
from hybrid.gl.brush import GpuHeights
from hybrid.gl.particles import ParticleParams, ParticleSystem, check_particles, surface_below
from hybrid.renderer import Renderer
from hybrid.terrain.datasets import puget
from hybrid.terrain.edits import Crater, Raise
from hybrid.terrain.heightfield import HeightField

TOL = 0.05  # metres: float32 positions over heights of a few hundred metres


@pytest.fixture
def hf():
    p = puget(size=129)  # 128 cells of 160 m
    return HeightField(p.heights.copy(), p.spacing, p.origin, p.name, p.texture, source_step=p.source_step)


@pytest.fixture
def gpu(ctx, hf):
    g = GpuHeights(ctx, hf)
    yield g
    g.release()


def _clearances(ps, gpu, params):
    pos, _ = ps.read()
    return pos[:, 2] - surface_below(gpu, pos[:, :2].astype(np.float64), params.reconstruction) - params.clearance


@pytest.mark.parametrize("reconstruction", ["triangles", "bilinear"])
def test_particles_stay_above_the_surface_and_on_the_terrain(ctx, hf, gpu, reconstruction):
    params = ParticleParams(count=4096, drop=30.0, reconstruction=reconstruction, substeps=8, seed=3)
    with ParticleSystem(ctx, gpu, params) as ps:
        start = ps.read()[0]
        for _ in range(240):
            ps.step()
        pos, vel = ps.read()
        gaps = _clearances(ps, gpu, params)
    assert np.isfinite(pos).all() and np.isfinite(vel).all()
    assert gaps.min() > -TOL  # every particle above the surface
    assert np.median(gaps) < 1.0  # and most have come down to it
    assert np.abs(pos - start).max() > 25.0  # they moved: fell 30 m
    w, d = hf.extent
    assert pos[:, 0].min() >= 0 and pos[:, 0].max() <= w and pos[:, 1].min() >= 0 and pos[:, 1].max() <= d


def _settled(ctx, gpu, params, steps=200):
    ps = ParticleSystem(ctx, gpu, params)
    for _ in range(steps):
        ps.step()
    return ps


def test_particles_rise_with_a_raise_and_fall_into_a_crater(ctx, hf, gpu):
    ox, oy, _ = hf.origin
    params = ParticleParams(count=8192, dt=0.25, substeps=8, drop=0.0, friction=0.9, restitution=0.0, seed=1)
    centre = np.array([10240.0, 10240.0])
    with _settled(ctx, gpu, params) as ps:
        before = ps.read()[0]
        near = np.linalg.norm(before[:, :2] - centre, axis=1) < 1000.0  # inside 1/3 of the radius
        far = np.linalg.norm(before[:, :2] - centre, axis=1) > 3500.0
        assert near.sum() > 20
        gpu.edit(Raise((ox + centre[0], oy + centre[1]), 3000.0, 200.0))
        ps.step()
        after = ps.read()[0]
        rise = after[:, 2] - before[:, 2]
        assert rise[near].min() > 0.7 * 200.0  # w >= 0.79 within r/3: pushed up with it
        assert np.abs(rise[far]).max() < 5.0  # the rest of the terrain did not move
        assert _clearances(ps, gpu, params).min() > -TOL
        gpu.edit(Crater((ox + centre[0], oy + centre[1]), 3000.0, 400.0))
        for _ in range(120):
            ps.step()
        fell = ps.read()[0][:, 2] - after[:, 2]
        assert fell[near].max() < -200.0  # the bowl is 400 m deep at its centre
        assert _clearances(ps, gpu, params).min() > -TOL


def test_65536_particles_step(ctx, gpu):
    params = ParticleParams(count=65536, seed=2)
    with ParticleSystem(ctx, gpu, params) as ps:
        times = [ps.timed_step() for _ in range(5)]
        pos, vel = ps.read()
        assert pos.shape == (65536, 3) and np.isfinite(pos).all() and np.isfinite(vel).all()
        assert all(t.wall_ms > 0 for t in times)
        assert ps.nbytes >= 3 * 65536 * 16
        assert _clearances(ps, gpu, params).min() > -TOL


def test_drawn_particles_appear_where_they_project(ctx, gpu):
    hf = gpu.hf
    view = default_view(hf, 320, 180)
    params = ParticleParams(count=64, drop=0.0, clearance=40.0, point_px=7.0, colour=(1.0, 0.0, 1.0), seed=5)
    with ParticleSystem(ctx, gpu, params) as ps, Renderer(ctx, hf, "raster", tile_size=32, adapt=False) as r:
        ps.step()
        plain = r.render(view)
        drawn = r.render(view, overlay=ps.draw)
        world = ps.world_positions()
    pts = view.project(world)

    def magenta(img):
        return (img[..., 1] < 30) & (img[..., 0] > 100) & (img[..., 2] > 100)

    assert not magenta(plain.colour).any()
    shown = magenta(drawn.colour)
    inside = (pts[:, 0] >= 4) & (pts[:, 0] < 316) & (pts[:, 1] >= 4) & (pts[:, 1] < 176)
    front = [
        np.linalg.norm(w - view.eye) < plain.distance[int(r), int(c)] - 100.0
        for w, (c, r, _) in zip(world[inside], pts[inside])
    ]
    hits = [bool(shown[int(r), int(c)]) for c, r, _ in pts[inside][front]]
    assert len(hits) > 10 and all(hits)  # each in front of the terrain: drawn there
    assert shown.sum() <= 64 * 49  # and nowhere else
    assert np.all(drawn.distance[shown] <= plain.distance[shown] + 1.0)  # depth-tested against the terrain


def test_bad_particle_parameters_are_refused_by_name():
    for kw, words in (
        ({"count": -1}, "particle count"),
        ({"substeps": 0}, "particle substeps"),
        ({"substeps": 1000}, "particle substeps"),
        ({"dt": float("nan")}, "particle dt"),
        ({"restitution": 1.5}, "particle restitution"),
        ({"reconstruction": "planes"}, "reconstruction"),
    ):
        with pytest.raises(TerrabenchError, match=words):
            check_particles(ParticleParams(**kw))
