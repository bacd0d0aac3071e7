"""The brush geometry: the ink model, the drips, and the pieces the brush is made of."""

from __future__ import annotations

import numpy as np
import pytest

from tagbot.model import Tag
from tagbot.render.brush import PRESETS, Brush, RenderError, dwell, paint
from tests.render.conftest import EXAMPLES, Table


def test_width_follows_laid_ink_and_saturates() -> None:
    brush = Brush()
    ink = np.linspace(0.0, 50.0, 500)
    w = brush.widths(ink, size=100.0)
    assert np.all(np.diff(w) >= 0) and w[100] > w[0]
    assert w[0] == pytest.approx(brush.thin * brush.nib * 100.0)
    assert w[-1] == pytest.approx(brush.cap * 100.0, rel=1e-6)
    # The documented law at the mean speed (r = 1, e = flow).
    fill = 1 - np.exp(-brush.flow)
    expected = brush.nib * 100.0 * (brush.thin + (1 + brush.spread - brush.thin) * fill)
    assert brush.widths(np.array([brush.flow]), 100.0)[0] == pytest.approx(expected)


def test_dwell_is_time_per_length_and_grows_while_the_pen_stays() -> None:
    t = np.arange(0.0, 1.0 + 1e-9, 0.002)
    xy = np.column_stack([50.0 * t, 0.0 * t])
    u = dwell(t, xy, 1.0)
    np.testing.assert_allclose(u[100:-100], 1.0 / 50.0, rtol=1e-6)  # 1 / speed
    stays = []
    for stay in (0.0, 0.1, 0.5, 2.0):
        tt = np.concatenate([t[:250], t[250:] + stay])
        stays.append(dwell(tt, np.concatenate([xy[:250], xy[249:-1]]), 1.0)[250])
    assert np.all(np.diff(stays) > 0)


def test_presets_are_named_brushes() -> None:
    assert set(PRESETS) == {"marker", "fineliner", "chisel", "spray"}
    assert Brush.preset("marker") == Brush()
    assert Brush.preset("spray").soft > 0 and Brush.preset("spray").overspray > 0
    assert Brush.preset("chisel").aspect < 1
    assert Brush.preset("fineliner").nib < Brush().nib
    with pytest.raises(RenderError, match="unknown preset"):
        Brush.preset("crayon")


def test_chisel_is_broad_across_its_angle() -> None:
    brush = Brush.preset("chisel")
    a = np.radians(brush.angle)
    along = np.array([[np.cos(a), np.sin(a)]])
    across = np.array([[-np.sin(a), np.cos(a)]])
    ink = np.array([5.0])
    round_ = brush.widths(ink, 100.0)[0]
    assert brush.widths(ink, 100.0, across)[0] == pytest.approx(round_)
    assert brush.widths(ink, 100.0, along)[0] == pytest.approx(brush.aspect * round_)


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


def test_drips_hang_from_pools_only(cae: Tag) -> None:
    motion = cae.sample(0.005)
    brush = Brush()
    found = 0
    for seed in range(10):
        painting = paint(motion, brush, drips=True, seed=seed)
        ink = np.empty(len(motion.t))
        for run in painting.runs:
            ink[run.rows] = run.ink
        for drip in painting.drips:
            found += 1
            assert motion.pen[drip.sample] == 1
            assert ink[drip.sample] > brush.drip_ink  # ink pooled beyond the threshold
            assert drip.y == pytest.approx(motion.xy[drip.sample, 1])
            w = brush.widths(ink[drip.sample : drip.sample + 1], painting.size)[0]
            assert abs(drip.x - motion.xy[drip.sample, 0]) <= 0.15 * w + 1e-12
            assert drip.length > 0 and drip.width < w
            body, bead = drip.shapes()
            assert body[..., 1].max() <= drip.y + 1e-12  # runs down, never up
            assert bead[..., 1].max() < drip.y
            # Irregular width along the drip, and a bead wider than the body above it.
            _, _, half = drip.outline()
            assert np.std(np.diff(half)) > 0
            assert drip.bulb > half[-1]
    assert found > 0


def test_drip_lengths_vary() -> None:
    """Over a seeded set, drip lengths vary (coefficient of variation >= 0.3)."""
    from tagbot.io.planfile import load_plan

    lengths = []
    for name in ("cae.json", "letter-b.json"):
        motion = load_plan(EXAMPLES / name).sample(0.005)
        for seed in range(12):
            lengths += [d.length for d in paint(motion, drips=True, seed=seed).drips]
    assert len(lengths) >= 20
    assert np.std(lengths) / np.mean(lengths) >= 0.3


def test_a_pen_that_never_lingers_never_drips() -> None:
    """Constant speed, the pen already moving at both ends: no pool, no drip, with any seed."""
    t = np.arange(0.0, 2.0 + 1e-9, 0.002)
    xy = np.column_stack([50.0 * t, 10.0 * np.sin(t)])
    v = np.gradient(xy, t, axis=0)
    motion = Table(t, xy, v, np.hypot(*v.T), np.ones(len(t)))
    brush = Brush(drip_chance=1.0)
    for seed in range(20):
        assert paint(motion, brush, drips=True, seed=seed).drips == ()


def lingering(stay: float) -> Table:
    """A stroke along x at constant speed that stops at its end for ``stay`` seconds."""
    t = np.arange(0.0, 0.6 + stay + 1e-9, 0.002)
    x = 100.0 * np.minimum(t / 0.6, 1.0)
    v = np.where(t < 0.6, 100.0 / 0.6, 0.0)
    return Table(t, np.column_stack([x, 0 * x]), np.column_stack([v, 0 * v]), v, np.ones(len(t)))


def test_longer_lingering_gives_longer_wider_drips() -> None:
    brush = Brush(drip_chance=1.0)
    a = paint(lingering(0.05), brush, drips=True, seed=3).drips
    b = paint(lingering(0.8), brush, drips=True, seed=3).drips
    assert len(a) == len(b) == 1
    assert b[0].ink > a[0].ink
    assert b[0].length > a[0].length
    assert b[0].width > a[0].width


def test_bad_brush_and_motion_are_refused() -> None:
    with pytest.raises(RenderError, match=r"brush\.nib"):
        Brush(nib=0)
    with pytest.raises(RenderError, match=r"brush\.spread"):
        Brush(spread=-1)
    with pytest.raises(RenderError, match=r"brush\.thin"):
        Brush(thin=1.5)
    empty = Table(np.arange(3.0), np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3), np.zeros(3))
    with pytest.raises(RenderError, match="no pen-down samples"):
        paint(empty)
