"""Physics of the synthetic rig's histogram model, asserted with noise off."""

import dataclasses

import numpy as np
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.core.meshes import front_samples, object_mesh, sample_spacing
from denali_pipe.report import paper
from denali_pipe.rig import histograms as H
from denali_pipe.rig.measure import early_share, measure, zone_shape
from denali_pipe.rig.scene import design_scene, mount_scatterer, object_scatterer

# A measured-like time axis (docs/sensor.md): 93 ps a bin, zero path at bin 16.
AXIS_93 = geo.TimeAxis(bin_width_ps=93.0, zero_bin=16.0)


@pytest.fixture(scope="module")
def phot(demo_config, time_axis):
    return H.Photometry.from_config(demo_config["rig"]["photometry"], time_axis)


def plate(centre, normal, side=0.2, spacing=0.01, rho_diffuse=0.0, rho_retro=0.6):
    """A square plate facing `normal`, in a vertical plane (tests only)."""
    u = np.cross([0, 0, 1.0], normal)
    u /= np.linalg.norm(u)
    xs = np.arange(-side / 2 + spacing / 2, side / 2, spacing)
    X, Z = np.meshgrid(xs, xs)
    pts = centre + X.ravel()[:, None] * u + Z.ravel()[:, None] * np.array([0, 0, 1.0])
    n = len(pts)
    return H.Scatterer(pts, np.tile(normal, (n, 1)), np.full(n, spacing**2), rho_diffuse, rho_retro)


def object_only(res, scene, phot, light_on=True):
    return H.expected_counts(res, light_on, scene, phot) - H.expected_counts(res, light_on, [], phot)


def peak_bin(h):
    """Sub-bin peak position by a parabola through the maximum and its neighbours."""
    i = int(np.argmax(h))
    a, b, c = h[i - 1], h[i], h[i + 1]
    return i + 0.5 * (a - c) / (a - 2 * b + c)


@pytest.mark.parametrize("shift", [0.05, 0.1, 0.2])
def test_bump_arrives_later_with_distance(phot, shift):
    # a plate straight in front of the centre zone's wall patch, facing the wall
    ws = H.wall_samples("3x3")
    patch = ws.q[4].mean(0)
    near = patch + np.array([0, -0.3, 0])
    far = near + np.array([0, -shift, 0])
    normal = -geo.WALL.normal
    h_near = object_only("3x3", [plate(near, normal)], phot)[1, 1]
    h_far = object_only("3x3", [plate(far, normal)], phot)[1, 1]
    expected = 2 * shift / phot.time_axis.bin_width_opl
    assert peak_bin(h_far) - peak_bin(h_near) == pytest.approx(expected, abs=1.0)


def test_bump_moves_with_the_gantry(phot, catalogue):
    # moving one row away from the wall delays the return in every zone's sum
    spec = catalogue["square"]
    peaks = []
    for row in range(0, 10, 3):
        k = row * 10 + (0 if row % 2 == 0 else 9)  # physical column 0 on every row
        h = object_only("3x3", [object_scatterer(spec, "8inch", geo.object_pose(k))], phot).sum((0, 1))
        peaks.append(peak_bin(h))
    assert np.all(np.diff(peaks) > 0)


def test_signal_bigger_for_8in_and_for_retroreflective(phot, catalogue):
    k = 44

    def total(name, size):
        # lights off: with lights on the object also shades the wall from room light
        return object_only("3x3", [object_scatterer(catalogue[name], size, geo.object_pose(k))], phot, light_on=False).sum()

    assert total("1", "8inch") > 2 * total("1", "4inch")
    assert total("1", "8inch") > 2 * total("generalization1white", "8inch")
    assert total("generalization1white", "8inch") > total("generalization1cardstock", "8inch") > 0


def test_lights_on_raise_the_floor_through_the_vignetted_lens(phot):
    on = H.expected_counts("3x3", True, [], phot)
    off = H.expected_counts("3x3", False, [], phot)
    extra = (on[..., 2:20] - off[..., 2:20]).mean(-1).ravel()
    assert np.all(extra > 0)
    # room light reaches every zone's wall patch alike; the lens passes it
    # as cos^n of the field angle, integrated over the zone's solid angle
    ws = H.wall_samples("3x3")
    d = ws.d_cam
    weight = (ws.omega * d[..., 2] ** phot.vignetting_power).sum(1)
    assert extra / extra[4] == pytest.approx(weight / weight[4], rel=0.03)
    # the centre zone's is the configured one, less the combiner's compression (~7 % at this floor)
    assert extra[4] == pytest.approx(phot.ambient_counts, rel=0.1)


def test_8x8_zones_hold_far_fewer_counts(phot):
    z3 = H.expected_counts("3x3", True, [mount_scatterer(geo.object_pose(50).t)], phot).sum(-1)
    z8 = H.expected_counts("8x8", True, [mount_scatterer(geo.object_pose(50).t)], phot).sum(-1)
    assert z8.max() * 100 <= z3.min()


# REFERENCE Part 4: what real 3x3 captures look like. A mid-gantry location
# (row 4, the middle of the grid) and the plain 8 in plate, lights off.
MID = 45


@pytest.fixture(scope="module")
def mid_scene(catalogue):
    def scene(name, size, k=MID):
        return design_scene(catalogue[name], size, k)

    return scene


def centre(phot, scene, light_on=False):
    return H.expected_counts("3x3", light_on, scene, phot)[1, 1]


def test_a_pooled_log_counts_match_the_release(phot, mid_scene):
    # the release's pooled log1p(counts) over 3x3 data: mean 7.1, sigma 0.78
    rng = np.random.default_rng(0)
    logs = [
        np.log1p(H.sample_counts(H.expected_counts("3x3", light, mid_scene(name, size, k), phot), phot, rng))
        for k in (5, 27, 45, 72, 94)
        for name in ("A", "square", "1")
        for size in ("8inch", "4inch")
        for light in (True, False)
    ]
    assert np.mean(logs) == pytest.approx(7.1, abs=0.3)
    assert 0.6 < np.std(logs) < 1.1


def test_b_floor_is_a_few_percent_and_lower_after_the_direct_return(phot):
    bg = centre(phot, [mount_scatterer(geo.object_pose(MID).t)])
    m = measure(bg, bg)
    # capture_setup.png's centre panel: floor 2 px under a 123 px peak
    # (1.2-2.4 %), digital_twin.png's real histogram ~2 %, the zoom ~5 %
    assert 0.012 <= m.floor_fraction <= 0.05
    assert m.floor_after < 0.9 * m.floor_before


def test_c_bump_of_an_8in_object_is_plain_in_one_capture(phot, mid_scene):
    bg = centre(phot, mid_scene("square", "8inch")[:1])
    capture = H.sample_counts(centre(phot, mid_scene("square", "8inch")), phot, np.random.default_rng(1))
    m = measure(capture, bg)
    assert 0.03 <= m.bump_fraction <= 0.08
    assert m.bump_over_floor >= 1.5
    # per-bin SNR of order 10-30: the excess against the shot noise of the capture
    assert m.bump_excess / np.sqrt(capture[m.bump_bin]) > 10


def test_c_4in_object_returns_a_quarter_from_area(phot, mid_scene):
    bg = centre(phot, mid_scene("square", "8inch")[:1])
    big = centre(phot, mid_scene("square", "8inch")) - bg
    small = centre(phot, mid_scene("square", "4inch")) - bg
    # integrated over the bump, the return follows the plate's area (1/4);
    # its peak is higher than that because a smaller plate spreads over fewer bins
    assert small.sum() / big.sum() == pytest.approx(0.25, rel=0.25)
    assert 0.25 <= small.max() / big.max() < 0.5


def test_object_shades_the_wall_from_room_light(phot, mid_scene):
    # with lights on, the object blocks room light from the wall patches it
    # faces: the floor before the direct return drops where no laser path can reach
    bg = H.transport("3x3", mid_scene("square", "8inch")[:1], phot)
    obj = H.transport("3x3", mid_scene("square", "8inch"), phot)
    assert np.all(bg.ambient > 0.95)  # the mount post is narrow
    assert np.all(obj.ambient < bg.ambient)
    on = H.counts_from_transport("3x3", True, obj, phot) - H.counts_from_transport("3x3", True, bg, phot)
    off = H.counts_from_transport("3x3", False, obj, phot) - H.counts_from_transport("3x3", False, bg, phot)
    assert np.all(on[..., :20] < 0)
    assert np.allclose(off[..., :20], 0, atol=1e-6)


def test_direct_return_sits_at_the_wall_distance(phot):
    h = H.expected_counts("3x3", False, [], phot)[1, 1]
    r = H.wall_samples("3x3").r[4]
    # pulse delay: the exGaussian's mode lies a little after the true arrival
    assert peak_bin(h) == pytest.approx(phot.time_axis.opl_to_bin(2 * r.mean()), abs=2.5)


def test_the_rig_renders_on_its_time_axis(phot):
    """Between the paper's axis and a 93-ps axis with zero path at bin 16 the
    wall return moves by what geometry says it moves (the pulse's delay, in
    bins, and the wall's spread, in metres, move it within half a bin)."""
    paper, other = (dataclasses.replace(phot, time_axis=a) for a in (geo.PAPER_TIME_AXIS, AXIS_93))
    opl = 2 * H.wall_samples("3x3").r[4].mean()
    move = AXIS_93.opl_to_bin(opl) - geo.PAPER_TIME_AXIS.opl_to_bin(opl)
    assert abs(move) > 5  # a move the test can see
    peaks = [peak_bin(H.expected_counts("3x3", False, [], p)[1, 1]) for p in (paper, other)]
    assert peaks[1] - peaks[0] == pytest.approx(move, abs=0.5)


def test_noise_is_poisson_plus_read(phot):
    mean = H.expected_counts("3x3", True, [], phot)
    draws = np.stack([H.sample_counts(mean, phot, np.random.default_rng(s)) for s in range(200)])
    assert draws.dtype == np.int32 and draws.min() >= 0
    var = draws[..., :30].var(0).mean()
    expected = mean[..., :30].mean() + phot.read_noise_counts**2
    assert var == pytest.approx(expected, rel=0.1)


def test_bump_has_no_pattern_from_sampling(phot, catalogue):
    # the expected bump is converged in the object's sampling: halving the
    # sample spacing moves no bin by more than 1 % of the peak (a sharp edge
    # is physics: the pulse is ~2 bins wide)
    spec, pose = catalogue["A"], geo.object_pose(MID)
    coarse = object_scatterer(spec, "8inch", pose)
    points, area = front_samples(object_mesh(spec, "8inch"), sample_spacing("8inch") / 2)
    fine = dataclasses.replace(coarse, points=pose.apply(points), normals=np.tile(coarse.normals[0], (len(points), 1)), area=area)
    bg = centre(phot, [])
    b_coarse, b_fine = centre(phot, [coarse]) - bg, centre(phot, [fine]) - bg
    assert len(fine.points) > 3 * len(coarse.points)
    assert np.abs(b_coarse - b_fine).max() < 0.01 * b_fine.max()


def test_dead_time_lowers_every_later_bin():
    x = np.full(128, 100.0)
    x[40] = 1e5
    y = H.respond(x, saturation=1e6, dead=1e6)
    assert y[:40] == pytest.approx(100 * np.exp(-np.arange(40) * 1e-4), rel=1e-3)
    assert y[60] < 0.95 * y[30]


REAL_ZONE_MEANS = np.asarray(paper.REAL_ZONE_MEANS)


@pytest.fixture(scope="module")
def zone_means(phot, mid_scene):
    """Mean counts per zone and bin over lightings, objects and gantry locations."""
    return np.mean(
        [
            H.counts_from_transport("3x3", light, tr, phot).mean(-1)
            for tr in (H.transport("3x3", mid_scene(name, "8inch", k), phot) for k in (5, 45, 94) for name in ("A", "square"))
            for light in (True, False)
        ],
        axis=0,
    )


def test_zones_are_centre_weighted_like_the_real_sensor(zone_means):
    m = zone_means
    edge = m[[0, 1, 1, 2], [1, 0, 2, 1]].mean()
    corner = m[[0, 0, 2, 2], [0, 2, 0, 2]].mean()
    # real (REFERENCE Part 5's means): centre 2.46x the edges' mean and
    # 3.39x the corners', where a single Gaussian beam gives centre/edge =
    # edge/corner; the beam's core lights the centre zone alone
    assert m[1, 1] / edge == pytest.approx(2.46, rel=0.15)
    assert m[1, 1] / corner == pytest.approx(3.39, rel=0.15)
    assert np.all(np.abs(m / REAL_ZONE_MEANS - 1) < 0.15)


@pytest.mark.parametrize("contour", [2.0, 12.7])
def test_the_diffuse_term_sees_the_whole_beam(phot, contour):
    # the coarse laser grid plus the core's spot carry the beam's power over
    # the field, as a fine grid of the emission does: the core, narrower
    # than a grid cell, would otherwise fall between the grid's points, and
    # a near-rectangular flood's edges between them (the coarse grid alone
    # over-integrates it by 10 %)
    phot = dataclasses.replace(phot, beam_contour=contour)
    _, _, share = H._lit_spots(phot)
    fine = H._wall_samples(1, 64)
    assert share.sum() == pytest.approx((phot.emission(fine.d_cam) * fine.omega).sum(), rel=0.005)
    axis, power = phot.core_spot()
    assert power == pytest.approx((phot.core(fine.d_cam) * fine.omega).sum(), rel=0.02)
    assert phot.core(axis) == pytest.approx(phot.core_share)  # the spot sits on the core's peak


def test_a_rectangular_flood_lights_the_field_corners_more(phot):
    # a diffuser shaped to the receiver's rectangle (beam_contour > 2) keeps
    # the flood's half widths on its axes but sends more light toward the
    # field's diagonals than an ellipse does, so the corner zones gain on the edges
    flat = dataclasses.replace(phot, beam_yaw_deg=0.0, beam_pitch_deg=0.0, core_share=0.0, beam_order=1.0)
    ellipse, rectangle = (dataclasses.replace(flat, beam_contour=q) for q in (2.0, 6.0))
    hx, hy = np.tan(np.deg2rad(flat.beam_hwhm_deg))
    on_axes = np.array([[hx, 0, 1], [0, hy, 1]]) / np.linalg.norm([[hx, 0, 1], [0, hy, 1]], axis=1, keepdims=True)
    diagonal = np.array([hx, hy, 1]) / np.linalg.norm([hx, hy, 1])
    for p in (ellipse, rectangle):
        assert p.flood(on_axes) == pytest.approx(0.5, rel=1e-9)
    assert rectangle.flood(diagonal) > 1.3 * ellipse.flood(diagonal)

    def corner_over_edge(p):
        m = H.expected_counts("3x3", False, [], p).mean(-1) - p.dark_counts
        return m[[0, 0, 2, 2], [0, 2, 0, 2]].mean() / m[[0, 1, 1, 2], [1, 0, 2, 1]].mean()

    assert corner_over_edge(rectangle) > 1.05 * corner_over_edge(ellipse)


def test_zones_near_end_of_the_wall_is_brighter_like_the_real_sensor(zone_means):
    # real: column 2 (the near end of the wall, the captures' columns being
    # mirrored) ~20 % above column 0, rows top and bottom within 2 %
    ratio = zone_means[:, 2].sum() / zone_means[:, 0].sum()
    assert 1.1 < ratio < 1.35
    assert zone_means[0].sum() / zone_means[2].sum() == pytest.approx(1.0, abs=0.05)


def test_column_0_holds_the_latest_broadest_direct_returns_like_the_release(phot):
    # The release's figures of a real 3x3 capture (capture_setup.png, the
    # teaser's grid): pixels 1, 4, 7 peak latest (~bin 60) and broadest,
    # pixels 3, 6, 9 earliest (~53) and sharpest; the captures' column 0 is
    # the far, oblique end of the wall. Peaks from the pulse-free transport
    # (the wall's own paths), breadth from the expected counts (above 30 % of
    # the peak: real 10-21 bins in column 0, 4-5 in column 2).
    wall = H.transport("3x3", [], phot).hist.reshape(3, 3, -1)
    peak = wall.argmax(-1)
    assert np.all(peak[:, 0] > peak[:, 1]) and np.all(peak[:, 1] > peak[:, 2])
    counts = H.expected_counts("3x3", False, [], phot)
    broad = (counts > 0.3 * counts.max(-1, keepdims=True)).sum(-1)
    assert np.all(broad[:, 0] > broad[:, 2])
    # and the rows are not mirrored: the bottom row's returns come later
    assert peak[2].sum() > peak[0].sum()


def test_every_zone_rises_when_and_lasts_as_long_as_the_release_capture(phot, mid_scene):
    # capture_setup.png's nine panels read bar by bar (paper.REAL_FIGURE_ZONES:
    # its hexagon at about location 84, lights off): where each zone's direct
    # return reaches half its height, against the centre's, and how many bins
    # it stays above half. The sensor's pose and field, the zones' tiling, the
    # pulse and the combiner's saturation set both.
    shapes = [zone_shape(h) for h in H.expected_counts("3x3", False, mid_scene(*paper.REAL_FIGURE_CAPTURE), phot).reshape(9, -1)]
    rise = np.array([s["half_rise"] for s in shapes])
    assert np.abs((rise - rise[4]) - paper.REAL_FIGURE_ZONES["half_rise"]).max() <= 3
    real = np.array(paper.REAL_FIGURE_ZONES["width"])
    read = ~np.isnan(real)
    assert np.abs(np.array([s["width"] for s in shapes])[read] - real[read]).max() <= 2


def test_light_outlasts_the_direct_return_by_the_lasers_slow_tail(phot, mid_scene):
    # Every panel of capture_setup.png read (paper.REAL_FIGURE_ZONES) holds
    # light above its early floor 15-29 bins after its direct return, 0.010
    # of the peak in the centre. The pulse's fast part is long gone by then
    # and the dead time lowers the late bins, so without the VCSEL's slow
    # tail (carrier diffusion, afterglow) the centre falls below its floor.
    # The centre panel's direct peak is 123 px tall: a reading is good to a
    # pixel.
    pixel = 1 / 123

    def tails(p):
        counts = H.expected_counts("3x3", False, mid_scene(*paper.REAL_FIGURE_CAPTURE), p).reshape(9, -1)
        return np.array([zone_shape(h)["tail_15_29"] for h in counts])

    real = np.array(paper.REAL_FIGURE_ZONES["tail_15_29"])
    read = ~np.isnan(real)
    rig = tails(phot)
    assert np.all(rig[read] > 0)
    assert abs(rig[4] - real[4]) <= pixel
    assert tails(dataclasses.replace(phot, slow_tail_fraction=0.0))[4] < 0


def test_far_column_holds_the_bright_zones_return_early_by_glare(phot):
    # capture_setup.png's far column: pixels 1 and 7 (the far corners) show
    # a first peak at the other columns' direct return, 0.56 and 0.67 of
    # their own later one, pixel 4 (beside the bright centre) 0.11. Only
    # light meant for other zones can arrive that early: the receiver's glare.
    def shares(p):
        counts = H.expected_counts("3x3", False, [], p).reshape(9, -1)
        return np.array([early_share(counts, z) for z in (0, 3, 6)])

    corner, edge, _ = with_glare = shares(phot)
    assert 0.4 < with_glare[[0, 2]].min() and with_glare[[0, 2]].max() < 1.0
    assert edge < corner
    assert np.all(shares(dataclasses.replace(phot, glare_share=0.0)) < 0.05)


def test_bump_width_is_the_objects_path_extent_not_the_pulse(phot, mid_scene):
    # At mid gantry the rig's 8 in square is ~0.23 m of path wide: the centre zone
    # sees the plate from ~40 deg off its normal, so 2 |q - o| spans ~0.21 m
    # across the plate; the pulse (~2 bins FWHM) adds little and a narrower
    # plate narrows it.
    def width(name, size, p):
        bg = centre(p, mid_scene(name, size)[:1])
        return measure(centre(p, mid_scene(name, size)), bg).bump_fwhm

    # widths in metres of path: the axis sets how many bins they span
    path = phot.time_axis.bin_width_opl
    sharp = dataclasses.replace(phot, pulse_sigma_bins=0.3, pulse_tail_bins=0.3, slow_tail_fraction=0.0)
    assert width("square", "8inch", phot) * path > 0.21
    assert width("square", "8inch", sharp) * path > 0.19  # a near-delta pulse leaves the width
    assert (width("square", "4inch", phot) - width("square", "8inch", phot)) * path < -0.06


def test_bump_width_matches_the_release_capture_at_its_gantry_location(phot, mid_scene):
    # digital_twin.png's real capture: an 8 in "8" at gantry location 90
    # (its tag 1 located through the tracking camera, docs/rig_zones.md),
    # bump ~5 bins FWHM read off the figure's bars (+-20 %). The plate's
    # path extent alone gives ~4.8 there, so this bounds the pulse. (The
    # hexagon of capture_setup.png, at about location 84, is ~6 bins real
    # and 7.5 in the rig: not yet reproduced, docs/rig_zones.md.)
    scene = mid_scene("8", "8inch", 90)
    m = measure(centre(phot, scene), centre(phot, scene[:1]))
    assert 4.0 <= m.bump_fwhm <= 6.0


def test_8x8_subcaptures_tile_the_grid_on_sparse_lattices():
    sub = geo.zone_subcapture("8x8").reshape(8, 8)
    assert np.all(np.bincount(sub.ravel()) == 8)
    # neighbours in a row or a column come from different subcaptures
    assert np.all(sub[:, 1:] != sub[:, :-1]) and np.all(sub[1:] != sub[:-1])
    # REFERENCE Part 6: subcapture 0 covers rows 1, 3, 5, 7 in columns 0 and 4
    assert set(zip(*np.nonzero(sub == 0))) == {(r, c) for r in (1, 3, 5, 7) for c in (0, 4)}
    assert np.all(geo.zone_subcapture("3x3") == 0)


def test_each_subcapture_has_its_own_power_and_clock(phot):
    scene = [mount_scatterer(geo.object_pose(50).t)]
    sub = geo.zone_subcapture("8x8").reshape(8, 8)
    base = H.expected_counts("8x8", False, scene, phot)
    power = tuple(1.0 + 0.1 * (np.arange(8) == 3))
    brighter = H.expected_counts("8x8", False, scene, phot, H.Conditions(power_gain=power))
    changed = np.abs(brighter - base).max(-1) > 1e-9
    assert np.array_equal(changed, sub == 3)
    shift = tuple(2.0 * (np.arange(8) == 5))
    later = H.expected_counts("8x8", False, scene, phot, H.Conditions(time_shift_bins=shift))
    assert np.array_equal(np.argmax(later, -1) - np.argmax(base, -1) == 2, sub == 5)
