"""The brush geometry: the width law, the drips law, and the pieces the brush is made of."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.model import Tag
from tagbot.render.brush import Brush, RenderError, paint
from tests.render.conftest import Table


def test_width_falls_as_speed_rises() -> None:
    brush = Brush()
    speed = np.linspace(0.0, 500.0, 200)
    w = brush.widths(speed, size=100.0, mean_speed=50.0)
    assert np.all(np.diff(w) < 0)
    assert w[0] == pytest.approx(brush.width * 100.0)
    assert w[-1] == pytest.approx(brush.thin * brush.width * 100.0, rel=1e-3)
    # The documented law at the reference speed.
    w_max, w_min = brush.width * 100.0, brush.thin * brush.width * 100.0
    v_ref = brush.speed_ref * 50.0
    at_ref = brush.widths(np.array([v_ref]), 100.0, 50.0)[0]
    assert at_ref == pytest.approx(w_min + (w_max - w_min) * np.exp(-1.0))


def test_painting_is_unit_independent(cae: Tag) -> None:
    motion = cae.sample(0.005)
    scaled = Table(
        motion.t * 3.0, motion.xy * 10.0, motion.v * 10.0 / 3.0, motion.speed, motion.pen
    )
    a, b = paint(motion), paint(scaled)
    assert b.size == pytest.approx(10.0 * a.size)
    assert b.mean_speed == pytest.approx(a.mean_speed * 10.0 / 3.0)
    for ra, rb in zip(a.runs, b.runs, strict=True):
        np.testing.assert_allclose(rb.width, 10.0 * ra.width, rtol=1e-9)


def test_each_pen_down_run_is_painted_separately(cae: Tag) -> None:
    motion = cae.sample(0.005)
    painting = paint(motion)
    assert len(painting.runs) == len(cae.plans) == len(list(motion.runs()))
    for run, (_, rows) in zip(painting.runs, motion.runs(), strict=True):
        assert run.rows == rows
        assert np.all(motion.pen[rows] == 1)


def test_pieces_are_counter_clockwise_and_cover_every_sample(letter_b: Tag) -> None:
    run = paint(letter_b.sample(0.005)).runs[0]
    quads, discs = run.pieces()
    for polygons in (quads, discs):
        x, y = polygons[..., 0], polygons[..., 1]
        area = np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
        assert np.all(area >= -1e-12)
    assert len(discs) == len(run) and len(quads) == len(run) - 1
    # Each disc is centred on its sample and circumscribes the brush there.
    np.testing.assert_allclose(discs.mean(axis=1), run.xy, atol=1e-9)
    radius = np.hypot(*(discs[:, 0] - run.xy).T)
    assert np.all(radius >= 0.5 * run.width)


def test_drips_are_seeded(cae: Tag) -> None:
    motion = cae.sample(0.005)
    a = paint(motion, drips=True, seed=11).drips
    b = paint(motion, drips=True, seed=11).drips
    assert a == b
    variants = {paint(motion, drips=True, seed=s).drips for s in range(8)}
    assert len(variants) > 1


def test_drips_hang_from_slow_samples_only(cae: Tag) -> None:
    motion = cae.sample(0.005)
    brush = Brush()
    found = 0
    for seed in range(10):
        painting = paint(motion, brush, drips=True, seed=seed)
        v_drip = brush.drip_speed * painting.mean_speed
        for drip in painting.drips:
            found += 1
            assert motion.pen[drip.sample] == 1
            assert motion.speed[drip.sample] < v_drip
            assert drip.y == pytest.approx(motion.xy[drip.sample, 1])
            w = brush.widths(motion.speed[drip.sample], painting.size, painting.mean_speed)
            assert abs(drip.x - motion.xy[drip.sample, 0]) <= 0.15 * w + 1e-12
            assert 0 < drip.length <= brush.drip_length * painting.size
            body, bulb = drip.shapes()
            assert body[:, 1].max() <= drip.y + 1e-12  # hangs down, never up
            assert bulb[:, 1].max() < drip.y
    assert found > 0


def test_slower_lingering_gives_longer_drips() -> None:
    """Same motion but the pen lingers twice as long at the end: more ink, longer drips."""
    t = np.linspace(0.0, 1.0, 501)
    x = 100.0 * np.minimum(t / 0.6, 1.0)
    v = np.where(t < 0.6, 100.0 / 0.6, 0.0)
    short = Table(t, np.column_stack([x, 0 * x]), np.column_stack([v, 0 * v]), v, np.ones(501))
    t2 = np.linspace(0.0, 1.4, 701)
    x2 = 100.0 * np.minimum(t2 / 0.6, 1.0)
    v2 = np.where(t2 < 0.6, 100.0 / 0.6, 0.0)
    long = Table(t2, np.column_stack([x2, 0 * x2]), np.column_stack([v2, 0 * v2]), v2, np.ones(701))
    brush = Brush(drip_chance=1.0, drip_time=1.0)
    a = paint(short, brush, drips=True, seed=3).drips
    b = paint(long, brush, drips=True, seed=3).drips
    assert len(a) == len(b) == 1
    assert b[0].ink > a[0].ink
    assert b[0].length > a[0].length
    assert b[0].width > a[0].width


def test_bad_brush_and_motion_are_refused() -> None:
    with pytest.raises(RenderError, match=r"brush\.width"):
        Brush(width=0)
    with pytest.raises(RenderError, match=r"brush\.thin"):
        Brush(thin=1.5)
    empty = Table(np.arange(3.0), np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), np.zeros(3))
    with pytest.raises(RenderError, match="no pen-down samples"):
        paint(empty)
