"""coloradar.viz: each picture is written headless, at its size, with targets where they are."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from matplotlib.image import imread
from scipy.spatial.transform import Rotation

from coloradar import MissingDataError, OutputExistsError
from coloradar import formats as fm
from coloradar.calib import HeatmapConfig, preset_calibration, write_calibration
from coloradar.dataset import open_sequence
from coloradar.geometry import SE3, sensor_a_T_sensor_b, sensor_to_base
from coloradar.viz import (
    animate_run,
    ffmpeg_path,
    gather_scene,
    plot_heatmap_slice,
    plot_range_azimuth,
    plot_range_doppler,
    plot_scene,
    save_figure,
)

T0 = 1_608_580_000.5


def _png_size(path: Path) -> tuple[int, int]:
    img = imread(path)
    return img.shape[1], img.shape[0]


def _mesh_peak_cell(mesh) -> np.ndarray:
    """Corners ``(4, 2)`` of the brightest cell of a pcolormesh, in data coordinates."""
    arr = np.ma.getdata(mesh.get_array())
    coords = mesh.get_coordinates()                         # (ny+1, nx+1, 2)
    ny, nx = coords.shape[0] - 1, coords.shape[1] - 1
    iy, ix = np.unravel_index(np.nanargmax(arr.reshape(ny, nx)), (ny, nx))
    return coords[iy:iy + 2, ix:ix + 2].reshape(4, 2)


def _mesh_peak_centre(mesh) -> tuple[float, float]:
    return tuple(_mesh_peak_cell(mesh).mean(axis=0))


def _inside(value: float, lo: float, hi: float) -> bool:
    return min(lo, hi) <= value <= max(lo, hi)


# -- radar images from arrays ------------------------------------------------------------------
def test_range_doppler_puts_the_target_at_its_range_and_velocity(tmp_path):
    r = np.arange(128) * 0.0593
    v = (np.arange(32) - 16) * 0.11
    power = np.random.default_rng(0).uniform(1, 2, (128, 32))
    power[50, 23] = 1e6                                     # 2.965 m, +0.77 m/s
    fig = plot_range_doppler(power, r, v)
    im = fig.axes[0].images[0]
    data = im.get_array()
    x0, x1, y0, y1 = im.get_extent()
    iy, ix = np.unravel_index(np.argmax(data), data.shape)
    vx = x0 + (ix + 0.5) * (x1 - x0) / data.shape[1]
    ry = y0 + (iy + 0.5) * (y1 - y0) / data.shape[0]
    assert abs(vx - v[23]) < 1e-9 and abs(ry - r[50]) < 1e-9
    assert fig.axes[0].get_xlabel().startswith("range rate [m/s]")
    assert fig.axes[0].get_ylabel() == "range [m]"
    out = save_figure(fig, tmp_path / "rd.png")
    assert _png_size(out) == (700, 600)
    with pytest.raises(OutputExistsError):
        save_figure(fig, out)


@pytest.mark.parametrize("mode", ["bev", "polar"])
def test_range_azimuth_puts_the_target_at_its_place(tmp_path, mode):
    r = np.arange(64) * 0.125
    az = np.arcsin((np.arange(64) - 32) / 32)[1:]           # sin-spaced, ascending
    power = np.ones((az.size, r.size))
    ia, ir = 40, 30                                          # az ≈ +14.5°, 3.75 m
    power[ia, ir] = 1e5
    fig = plot_range_azimuth(power, r, az, mode=mode)
    ax = fig.axes[0]
    cx, cy = _mesh_peak_centre(ax.collections[0])
    if mode == "polar":
        # Cell centre in degrees/metres, within a quarter bin of the true bin centre.
        assert abs(cx - np.degrees(az[ia])) < 0.5 * np.degrees(az[ia + 1] - az[ia])
        assert abs(cy - r[ir]) < 1e-9
        assert ax.get_xlim()[0] > ax.get_xlim()[1]           # +azimuth (left) drawn on the left
    else:
        # Bird's-eye: across = y (left +), up = x (boresight).
        y, x = r[ir] * np.sin(az[ia]), r[ir] * np.cos(az[ia])
        assert np.hypot(cx - y, cy - x) < 0.1
        assert ax.get_xlim()[0] > ax.get_xlim()[1]
        assert "boresight" in ax.get_ylabel()
    w, h = _png_size(save_figure(fig, tmp_path / f"ra_{mode}.png"))
    # the bird's-eye figure takes the fan's shape (issue 41, item 8): at most the default height
    assert w == 800 and (h == 600 if mode == "polar" else 300 <= h <= 600), (w, h)


def _heatmap_with_target(cfg: HeatmapConfig, e: int, a: int, r: int, rate: float) -> np.ndarray:
    hm = np.zeros((*cfg.shape, 2), dtype=np.float32)
    hm[..., 0] = 1.0
    hm[e, a, r, 0] = 1e4
    hm[e, a, r, 1] = rate
    return hm


@pytest.mark.parametrize("view", ["azimuth-range", "elevation-azimuth"])
def test_heatmap_slices_find_the_target(tmp_path, view):
    cfg = preset_calibration().single_chip.heatmap
    e, a, r = 11, 20, 33
    hm = _heatmap_with_target(cfg, e, a, r, -1.25)
    fig = plot_heatmap_slice(hm, cfg, view=view)
    cell = _mesh_peak_cell(fig.axes[0].collections[0])
    (x0, y0), (x1, y1) = cell.min(axis=0), cell.max(axis=0)
    # The brightest cell spans the target's bin angle; the neighbours' angles lie outside it.
    az = np.degrees(cfg.azimuth_bins)
    assert _inside(az[a], x0, x1) and not _inside(az[a - 1], x0, x1)
    assert not _inside(az[a + 1], x0, x1)
    if view == "azimuth-range":
        assert abs((y0 + y1) / 2 - cfg.range_bins[r]) < 1e-6
        assert f"bin {e}" in fig.axes[0].get_title()        # sliced at the target's elevation
    else:
        el = np.degrees(cfg.elevation_bins)
        assert _inside(el[e], y0, y1) and not _inside(el[e + 1], y0, y1)
    rate = np.ma.getdata(fig.axes[1].collections[0].get_array())
    assert np.nanmin(rate) == pytest.approx(-1.25)            # the range-rate panel shows it
    assert _png_size(save_figure(fig, tmp_path / "hm.png")) == (1300, 550)


def test_heatmap_cells_are_placed_by_direction_sines():
    """Viewers, odometry and heatmap_pointcloud share one placement: an FFT grid measures
    direction sines, azimuth bins are asin(u_y) and elevation bins asin(u_z) (docs/dsp.md), so
    a cell is at R·(√(1 − u_y² − u_z²), u_y, u_z), R = r·range_bin_width."""
    from types import SimpleNamespace

    from coloradar.dsp import FramePoints
    from coloradar.viz.scene import radar_points

    calib = preset_calibration()
    cfg = calib.cascade.heatmap
    e, a, r = 20, 90, 60
    hm = _heatmap_with_target(cfg, e, a, r, 0.5)
    uy, uz = np.sin(cfg.azimuth_bins[a]), np.sin(cfg.elevation_bins[e])
    rng = r * cfg.range_bin_width
    expect = rng * np.array([np.sqrt(1.0 - uy**2 - uz**2), uy, uz])
    seq = SimpleNamespace(calib=calib)
    pts = radar_points(seq, "cascade", "cascade/heatmaps", hm, max_points=5)      # the scene's
    assert pts.shape == (1, 5)
    np.testing.assert_allclose(pts[0, :3], expect, atol=1e-5)
    assert pts[0, 3] == 1e4 and pts[0, 4] == 0.5
    same = FramePoints(calib.cascade, "heatmaps")(hm)                            # odometry's
    np.testing.assert_array_equal(same, pts)
    # Reading the bin angles as spherical azimuth/elevation would put it centimetres away.
    el, az = cfg.elevation_bins[e], cfg.azimuth_bins[a]
    spherical = rng * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    assert np.linalg.norm(spherical - expect) > 0.03


# -- a run on disk: scene and animation --------------------------------------------------------
TARGET_WORLD = np.array([1.5, 6.0, 0.4])   # a static scatterer, world frame


def _pose(t: np.ndarray) -> tuple[np.ndarray, Rotation]:
    rel = t - T0
    return np.outer(rel, [0.0, 0.6, 0.0]), Rotation.from_euler("z", 0.05 * rel[:, None])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("vizrun")
    calib = preset_calibration()
    write_calibration(calib, root / "calib")
    folder = root / "12_21_2020_viz_run0"
    gt_t = T0 + np.arange(41) / 10.0
    p, q = _pose(gt_t)
    fm.write_timestamps(folder / "groundtruth/timestamps.txt", gt_t)
    fm.write_poses(folder / "groundtruth/groundtruth_poses.txt", np.hstack([p, q.as_quat()]))
    rng = np.random.default_rng(3)
    # Single-chip point clouds: the target, seen at its true place, plus a little clutter.
    sc_t = T0 + 0.02 + np.arange(30) / 10.0
    fm.write_timestamps(folder / "single_chip/pointclouds/timestamps.txt", sc_t)
    pp, qq = _pose(sc_t)
    b_T_sc = sensor_to_base(calib, "single_chip")
    for i in range(sc_t.size):
        tgt = (SE3(qq[i], pp[i]) @ b_T_sc).inverse().apply(TARGET_WORLD)
        cloud = np.zeros((4, 5), np.float32)
        cloud[0] = [*tgt, 30.0, -0.6]
        cloud[1:, :3] = rng.uniform([3, -4, -1], [15, 4, 1], (3, 3))
        fm.write_radar_pointcloud(folder / f"single_chip/pointclouds/data/radar_pointcloud_{i}.bin",
                                  cloud)
    # Lidar: a ring of points around the rig.
    li_t = T0 + 0.05 + np.arange(30) / 10.0
    fm.write_timestamps(folder / "lidar/timestamps.txt", li_t)
    ang = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    ring = np.column_stack([8 * np.cos(ang), 8 * np.sin(ang), np.zeros(360), np.ones(360)])
    for i in range(li_t.size):
        fm.write_lidar_pointcloud(folder / f"lidar/pointclouds/lidar_pointcloud_{i}.bin",
                                  ring.astype(np.float32))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = open_sequence(folder)
    return seq


def _collection(ax, label: str):
    return next(c for c in ax.collections if c.get_label() == label)


def test_scene_places_the_radar_target_in_base_and_sensor_frames(run, tmp_path):
    seq = run
    k = 12
    t = seq.single_chip.pointclouds.timestamps[k]
    p, q = _pose(np.array([t]))
    base_T_world = SE3(q[0], p[0]).inverse()
    expect_base = base_T_world.apply(TARGET_WORLD)
    fig = plot_scene(seq, index=k, stream="single_chip/pointclouds")
    ax = fig.axes[0]
    off = _collection(ax, "single_chip radar").get_offsets()[0]
    np.testing.assert_allclose(off, expect_base[:2], atol=1e-4)   # base: x across, y up
    assert "x [m]" in ax.get_xlabel() and "y [m]" in ax.get_ylabel()
    assert _png_size(save_figure(fig, tmp_path / "scene.png")) == (800, 750)
    # Cascade-centric: across = −y (rig right), up = x (boresight, rig forward).
    fig = plot_scene(seq, index=k, stream="single_chip/pointclouds", frame="cascade")
    ax = fig.axes[0]
    c_T_b = sensor_to_base(seq.calib, "cascade").inverse()
    in_c = c_T_b.apply(expect_base)
    off = _collection(ax, "single_chip radar").get_offsets()[0]
    np.testing.assert_allclose(off, [-in_c[1], in_c[0]], atol=1e-4)
    assert ax.get_xlabel().startswith("−y") and ax.get_ylabel().startswith("x")
    # World: the target is where it is, whatever the rig did.
    scene = gather_scene(seq, t, frame="world")
    np.testing.assert_allclose(scene.radars["single_chip"][0, :3], TARGET_WORLD, atol=1e-4)
    assert scene.radars["single_chip"][0, 3] == pytest.approx(-0.6)
    np.testing.assert_allclose(sensor_a_T_sensor_b(seq.calib, "cascade", "base").matrix(),
                               c_T_b.matrix())


def test_scene_compensates_motion_between_sensor_timestamps(run):
    """The lidar scan 30 ms after the radar frame is moved with the ground truth."""
    seq = run
    t = seq.single_chip.pointclouds.timestamps[5]
    scene = gather_scene(seq, t, frame="world")
    # The ring is centred on the lidar's origin at the scan's own time.
    i = scene.sources["lidar/pointclouds"][0]
    t_l = seq.lidar.pointclouds.timestamps[i]
    p, q = _pose(np.array([t_l]))
    lidar_origin = (SE3(q[0], p[0]) @ sensor_to_base(seq.calib, "lidar")).translation
    np.testing.assert_allclose(scene.lidar.mean(axis=0)[:2], lidar_origin[:2], atol=1e-3)


def test_scene_3d_view(run, tmp_path):
    fig = plot_scene(run, index=3, view="3d")
    assert _png_size(save_figure(fig, tmp_path / "scene3d.png")) == (800, 750)


def test_animation_gif(run, tmp_path):
    calls = []
    out = animate_run(run, tmp_path / "run.gif", start=0.5, duration=0.5, fps=4, dpi=40,
                      progress=lambda d, n: calls.append((d, n)))
    from PIL import Image

    with Image.open(out) as im:
        assert im.n_frames == 3 and im.size == (320, 288)
    assert calls[-1] == (3, 3)
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]   # no temp file left
    with pytest.raises(OutputExistsError):
        animate_run(run, out)


@pytest.mark.skipif(ffmpeg_path() is None, reason="no ffmpeg (pip install imageio-ffmpeg)")
def test_animation_mp4(run, tmp_path):
    out = animate_run(run, tmp_path / "run.mp4", duration=0.4, fps=5, dpi=40, frame="cascade")
    data = out.read_bytes()
    assert data[4:8] == b"ftyp" and len(data) > 1000


def test_scene_shows_the_radar_asked_for(run, tmp_path):
    """``plot --view scene --radar R``: R's points alone, ``--frame`` counting R's frames."""
    import shutil

    from coloradar.cli.main import main
    from coloradar.viz import frame_figure

    folder = tmp_path / Path(run.location).name
    shutil.copytree(run.location, folder)
    shutil.copytree(Path(run.location).parent / "calib", tmp_path / "calib")
    # A cascade point stream too: one point 5 m ahead of the cascade, at other times.
    ts = T0 + 0.07 + np.arange(10) / 5.0
    fm.write_timestamps(folder / "cascade/pointclouds/timestamps.txt", ts)
    for i in range(ts.size):
        fm.write_radar_pointcloud(folder / f"cascade/pointclouds/data/radar_pointcloud_{i}.bin",
                                  np.array([[5.0, 0.0, 0.0, 10.0, 0.1]], np.float32))
    seq = open_sequence(folder)
    both = frame_figure(seq, "scene", 3)
    labels = {c.get_label() for c in both.axes[0].collections}
    assert {"cascade radar", "single_chip radar"} <= labels
    for radar, other, stream in (("single_chip", "cascade", "single_chip/pointclouds"),
                                 ("cascade", "single_chip", "cascade/pointclouds")):
        fig = frame_figure(seq, "scene", 3, radar=radar)
        labels = {c.get_label() for c in fig.axes[0].collections}
        assert f"{radar} radar" in labels and f"{other} radar" not in labels
        assert f"{stream} frame 3" in fig.axes[0].get_title()
    out = tmp_path / "sc.png"
    assert main(["plot", str(folder), "--view", "scene", "--radar", "single_chip", "--frame",
                 "2", "--out", str(out)]) == 0
    assert _png_size(out) == (800, 750)


def test_plot_and_animate_commands(run, tmp_path, capsys):
    from coloradar.cli.main import main

    calib = str(Path(run.location).parent / "calib")
    out = tmp_path / "scene.png"
    assert main(["plot", str(run.location), "--view", "scene", "--frame", "2", "--out", str(out),
                 "--calib", calib]) == 0
    assert _png_size(out) == (800, 750)
    assert main(["plot", str(run.location), "--view", "heatmap", "--out", str(tmp_path / "h.png"),
                 "--calib", calib]) == 1
    assert "cascade/adc" in capsys.readouterr().err             # names what is missing
    gif = tmp_path / "a.gif"
    assert main(["animate", str(run.location), "--out", str(gif), "--duration", "0.2",
                 "--fps", "5", "--dpi", "30", "--calib", calib]) == 0
    assert gif.stat().st_size > 0
    err = capsys.readouterr().err
    assert "pictures [" in err and "2/2 frames" in err


def test_rerun_recording(run, tmp_path):
    pytest.importorskip("rerun")
    from rerun.chunk import RrdReader

    from coloradar.cli.main import main

    out = tmp_path / "run.rrd"
    assert main(["animate", str(run.location), "--out", str(out), "--duration", "1.0",
                 "--calib", str(Path(run.location).parent / "calib")]) == 0
    chunks = list(RrdReader(out).stream().collect().stream())
    paths = {c.entity_path for c in chunks}
    assert {"/world/base", "/world/base/lidar/points", "/world/base/single_chip/points",
            "/world/base/single_chip", "/world/groundtruth"} <= paths
    # 1 s of 10 Hz lidar and radar frames -> 10 scans and 10 radar frames.
    rows = sum(c.num_rows for c in chunks if c.entity_path == "/world/base/single_chip/points")
    assert rows == 10


# -- pictures of a raw ADC frame (through coloradar.dsp) ---------------------------------------
TARGET_R, TARGET_AZ, TARGET_RR = 4.0, np.radians(20.0), -0.5


@pytest.fixture(scope="module")
def adc_run(tmp_path_factory):
    """A run with one cascade ADC frame of a single simulated scatterer (physics model)."""
    from coloradar.sim import synthesize_adc

    root = tmp_path_factory.mktemp("adcrun")
    calib = preset_calibration()
    write_calibration(calib, root / "calib")
    folder = root / "12_21_2020_adc_run0"
    u = np.array([np.cos(TARGET_AZ), np.sin(TARGET_AZ), 0.0])
    adc = synthesize_adc(calib.cascade, (TARGET_R * u)[None], (TARGET_RR * u)[None], 1e4,
                         noise_std=1.0, rng=0)
    fm.write_timestamps(folder / "cascade/adc_samples/timestamps.txt", np.array([T0]))
    fm.write_adc(folder / "cascade/adc_samples/data/frame_0.bin", adc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return open_sequence(folder)


def test_range_doppler_of_an_adc_frame_shows_the_scatterer(adc_run, tmp_path):
    from coloradar.viz import frame_figure

    fig = frame_figure(adc_run, "range-doppler", 0)
    im = fig.axes[0].images[0]
    data = im.get_array()
    x0, x1, y0, y1 = im.get_extent()
    iy, ix = np.unravel_index(np.argmax(data), data.shape)
    v = x0 + (ix + 0.5) * (x1 - x0) / data.shape[1]
    r = y0 + (iy + 0.5) * (y1 - y0) / data.shape[0]
    w = adc_run.calib.cascade.waveform
    assert abs(r - TARGET_R) <= w.range_bin_width
    assert abs(v - TARGET_RR) <= w.velocity_bin_width / 2 + 1e-9
    assert _png_size(save_figure(fig, tmp_path / "rd.png")) == (700, 600)


@pytest.mark.parametrize("polar", [False, True])
def test_range_azimuth_of_an_adc_frame_shows_the_scatterer(adc_run, polar):
    from coloradar.viz import frame_figure

    fig = frame_figure(adc_run, "range-azimuth", 0, polar=polar)
    cx, cy = _mesh_peak_centre(fig.axes[0].collections[0])
    if polar:
        assert abs(cx - 20.0) < 2.0 and abs(cy - TARGET_R) < 0.1
    else:
        # Bird's-eye: y (left +) across, x (boresight) up.
        assert np.hypot(cx - TARGET_R * np.sin(TARGET_AZ), cy - TARGET_R * np.cos(TARGET_AZ)) < 0.15
    heat = frame_figure(adc_run, "heatmap", 0)            # no heatmaps in the run: from ADC
    assert "computed from ADC" in heat._suptitle.get_text()


def test_scene_takes_radar_points_from_adc_detections(adc_run):
    scene = gather_scene(adc_run, T0, frame="cascade")     # no ground truth: static extrinsics
    pts = scene.radars["cascade"]
    target = TARGET_R * np.array([np.cos(TARGET_AZ), np.sin(TARGET_AZ), 0.0])
    best = np.argmin(np.linalg.norm(pts[:, :3] - target, axis=1))
    assert np.linalg.norm(pts[best, :3] - target) < 0.1
    assert pts[best, 3] == pytest.approx(TARGET_RR, abs=0.12)
    with pytest.raises(MissingDataError, match="ground truth"):
        gather_scene(adc_run, T0, frame="world")


@pytest.mark.parametrize(("span_deg", "max_range"), [(76.0, 8.0), (60.0, 16.0)])
def test_range_azimuth_fan_fills_its_figure_and_its_colour_bar_matches(span_deg, max_range):
    """Issue 41, item 8: the bird's-eye fan is drawn at equal aspect; its colour bar is as tall
    as the plot (it stood twice the plot's height) and the plot fills the figure's height
    (it floated in white space)."""
    r = np.linspace(0.0, max_range, 64)
    az = np.radians(np.linspace(-span_deg, span_deg, 64))
    fig = plot_range_azimuth(np.ones((64, 64)) + np.random.default_rng(0).random((64, 64)),
                             r, az, mode="bev")
    fig.canvas.draw()
    ax = fig.axes[0]
    bar = ax.collections[0].colorbar.ax
    box = ax.get_position(original=False)
    bar_box = bar.get_position(original=False)
    assert abs(bar_box.height - box.height) <= 0.02 * box.height, (bar_box, box)
    assert box.height >= 0.6, box                     # fraction of the figure's height
