"""ROS bag export and import: round trips, an independent read with rosbags, foreign bags."""

from __future__ import annotations

import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coloradar import (
    CalibrationWarning,
    DataWarning,
    FormatError,
    MissingDataError,
    OutputExistsError,
    open_sequence,
)
from coloradar.cli.main import main
from coloradar.interop import decode_cloud, export_bag, import_bag, ns_to_times, times_to_ns
from coloradar.interop.pointcloud2 import CloudLayout
from coloradar.sim.run import simulate_run

rosbags = pytest.importorskip("rosbags", reason="the optional 'ros' extra (rosbags) is not installed")
from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("rosrun")
    res = simulate_run(root, duration=1.0, seed=2, heatmaps=False, vicon=True)
    return open_sequence(res.run_path)


# -- time ------------------------------------------------------------------------------------
def test_times_to_ns_is_exact_against_rational_arithmetic():
    rng = np.random.default_rng(0)
    t = 1.6e9 + rng.uniform(0, 1e6, 2000)
    t = np.array([float(f"{v:.9f}") for v in t])          # as the text files hold them
    t[:3] = [1_600_000_000.0, 1_600_000_000.999999999, 12.5]
    sec, nsec = times_to_ns(t)
    for v, s, n in zip(t[:200], sec[:200], nsec[:200], strict=True):
        exact = round(Fraction(v) * 10**9)                  # nearest ns of the float64, exactly
        assert s * 10**9 + n == exact
    assert np.all((nsec >= 0) & (nsec < 10**9))
    assert np.array_equal(ns_to_times(sec, nsec), t)        # back to the very same float64


# -- PointCloud2 layouts -----------------------------------------------------------------------
def test_decode_cloud_reads_a_foreign_padded_big_endian_organised_layout():
    rng = np.random.default_rng(1)
    h, w = 2, 7
    dt = np.dtype([("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("pad", "V3"),
                   ("range_rate", ">f4"), ("power", ">u2"), ("pad2", "V5")])
    rec = np.zeros((h, w), dt)
    for f in ("x", "y", "z", "range_rate"):
        rec[f] = rng.standard_normal((h, w))
    rec["power"] = rng.integers(0, 60000, (h, w))
    row_pad = 11
    buf = np.zeros(h * (w * dt.itemsize + row_pad), np.uint8)
    for r in range(h):
        start = r * (w * dt.itemsize + row_pad)
        buf[start:start + w * dt.itemsize] = rec[r].view(np.uint8)
    layout = CloudLayout(("x", "y", "z", "range_rate", "power"),
                         tuple(dt.fields[f][1] for f in ("x", "y", "z", "range_rate", "power")),
                         (8, 8, 8, 7, 4), (1,) * 5, dt.itemsize, w * dt.itemsize + row_pad, h, w,
                         True)
    got = decode_cloud(layout, buf, ("x", "y", "z", "intensity", "doppler"),
                       aliases={"doppler": ("range_rate",), "intensity": ("power",)})
    flat = rec.reshape(-1)
    want = np.stack([flat["x"], flat["y"], flat["z"], flat["power"], flat["range_rate"]], axis=1)
    assert np.array_equal(got, want.astype(np.float32))
    with pytest.raises(FormatError, match="no field doppler"):
        decode_cloud(layout, buf, ("x", "doppler"))
    with pytest.raises(FormatError, match="data bytes"):
        decode_cloud(layout, buf[:50], ("x",))


# -- export, read back by rosbags alone ----------------------------------------------------------
def _cloud(msg) -> np.ndarray:
    names = [f.name for f in msg.fields]
    assert all(f.datatype == 7 and f.count == 1 for f in msg.fields)
    assert [f.offset for f in msg.fields] == [4 * i for i in range(len(names))]
    assert msg.point_step == 4 * len(names) and msg.height == 1 and not msg.is_bigendian
    return np.frombuffer(bytes(msg.data), "<f4").reshape(msg.width, len(names))


def _stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_exported_bag_read_by_rosbags_alone(run, tmp_path, fmt):
    out = tmp_path / ("run.bag" if fmt == "ros1" else "run_ros2")
    res = export_bag(run, out, fmt, radar_points="shipped",
                     streams=["lidar/pointclouds", "single_chip/pointclouds", "imu", "groundtruth",
                              "vicon", "tf_static"])
    if fmt == "ros2":
        assert (out / "metadata.yaml").is_file()
    got: dict[str, list] = {}
    with AnyReader([out], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        (tf_conn,) = [c for c in reader.connections if c.topic == "/tf_static"]
        if fmt == "ros1":
            assert tf_conn.ext.latching == 1
        else:  # latched in ROS 2 terms: transient local
            from rosbags.interfaces import QosDurability

            assert tf_conn.ext.offered_qos_profiles[0].durability == QosDurability.TRANSIENT_LOCAL
        last = -1
        for conn, t_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic != "/tf_static":
                st = msg.header.stamp
                assert t_ns == st.sec * 10**9 + st.nanosec      # bag time = header stamp
            assert t_ns >= last                                  # written in time order
            last = t_ns
            got.setdefault(conn.topic, []).append(msg)
    assert types == {"/lidar/points": "sensor_msgs/msg/PointCloud2",
                     "/single_chip/points": "sensor_msgs/msg/PointCloud2",
                     "/imu/data": "sensor_msgs/msg/Imu", "/groundtruth/odom": "nav_msgs/msg/Odometry",
                     "/vicon/pose": "geometry_msgs/msg/PoseStamped",
                     "/tf_static": "tf2_msgs/msg/TFMessage"}
    assert res.counts == {k: len(v) for k, v in got.items()}

    lid = run.lidar.pointclouds
    assert np.array_equal([_stamp(m) for m in got["/lidar/points"]], lid.timestamps)
    for k in (0, len(lid) - 1):
        assert np.array_equal(_cloud(got["/lidar/points"][k]), lid[k])
        assert [f.name for f in got["/lidar/points"][k].fields] == ["x", "y", "z", "intensity"]
    sc = run.single_chip.pointclouds
    assert np.array_equal([_stamp(m) for m in got["/single_chip/points"]], sc.timestamps)
    for k, m in enumerate(got["/single_chip/points"]):
        assert [f.name for f in m.fields] == ["x", "y", "z", "intensity", "doppler"]
        assert m.header.frame_id == "single_chip"
        assert np.array_equal(_cloud(m), sc[k])
    imu = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z,
                     m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                    for m in got["/imu/data"]])
    assert np.array_equal(imu, run.imu.data)
    assert all(m.orientation_covariance[0] == -1 for m in got["/imu/data"])
    gt = np.array([[m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z,
                    m.pose.pose.orientation.x, m.pose.pose.orientation.y, m.pose.pose.orientation.z,
                    m.pose.pose.orientation.w] for m in got["/groundtruth/odom"]])
    assert np.array_equal(gt, run.groundtruth.poses)
    assert {(m.header.frame_id, m.child_frame_id) for m in got["/groundtruth/odom"]} == {("world", "base")}
    assert np.array_equal([_stamp(m) for m in got["/vicon/pose"]], run.vicon.timestamps)
    (tf,) = got["/tf_static"]
    tfs = {t.child_frame_id: t for t in tf.transforms}
    assert set(tfs) == set(run.calib.transforms)
    for name, ext in run.calib.transforms.items():
        tr = tfs[name].transform
        assert tfs[name].header.frame_id == "base"
        assert np.array_equal([tr.translation.x, tr.translation.y, tr.translation.z], ext.translation)
        assert np.array_equal([tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w],
                              ext.quaternion)


# -- round trip ---------------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_export_import_round_trip_is_identical(run, tmp_path, fmt):
    out = tmp_path / ("run.bag" if fmt == "ros1" else "run_ros2")
    res = export_bag(run, out, fmt)
    assert res.sources == {"cascade": "adc", "single_chip": "shipped"}
    imp = import_bag(out, tmp_path / "ds", name="back")
    assert imp.calib_written and imp.extrinsics == sorted(run.calib.transforms)
    back = open_sequence(imp.run_path)                    # finds ds/calib beside the run
    for a, b in ((run.lidar.pointclouds, back.lidar.pointclouds),
                 (run.single_chip.pointclouds, back.single_chip.pointclouds)):
        assert np.array_equal(a.timestamps, b.timestamps)
        assert len(a) == len(b) and all(np.array_equal(a[k], b[k]) for k in range(len(a)))
    # cascade points were computed from ADC by coloradar.dsp: same frames, same times
    from coloradar.dsp import RadarProcessor

    proc = RadarProcessor(run.calib.cascade)
    assert np.array_equal(back.cascade.pointclouds.timestamps, run.cascade.adc.timestamps)
    assert np.array_equal(back.cascade.pointclouds[1], proc.pointcloud(run.cascade.adc[1]))
    for name in ("imu", "groundtruth", "vicon"):
        a, b = getattr(run, name), getattr(back, name)
        assert np.array_equal(a.timestamps, b.timestamps)
        assert np.array_equal(a.data if name == "imu" else a.poses, b.data if name == "imu" else b.poses)
    for name, ext in run.calib.transforms.items():
        assert np.allclose(back.calib.transforms[name].translation, ext.translation, atol=1e-12)
        assert np.allclose(back.calib.transforms[name].matrix(), ext.matrix(), atol=1e-12)


# -- foreign bag: own topic names, a tf chain -----------------------------------------------------
def test_import_foreign_bag_with_topic_map_and_tf_chain(tmp_path):
    from rosbags.rosbag2 import Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    path = tmp_path / "rig"
    rng = np.random.default_rng(3)
    pts = [rng.standard_normal((n, 3)).astype(np.float32) for n in (5, 9)]
    t0 = 1_700_000_000

    def header(k, frame):
        stamp = T["builtin_interfaces/msg/Time"](sec=t0 + k, nanosec=250_000_000)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def tfm(parent, child, t, q):
        return T["geometry_msgs/msg/TransformStamped"](
            header=header(0, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](
                translation=T["geometry_msgs/msg/Vector3"](x=t[0], y=t[1], z=t[2]),
                rotation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])))

    q1 = Rotation.from_euler("z", 90, degrees=True).as_quat()
    q2 = Rotation.from_euler("x", 30, degrees=True).as_quat()
    with Writer(path, version=8) as w:
        c_pts = w.add_connection("/radar/detections", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c_tf = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
        msg = T["tf2_msgs/msg/TFMessage"](transforms=[tfm("base_link", "mount", (1.0, 0.0, 0.5), q1),
                                                      tfm("mount", "radar_link", (0.0, 0.2, 0.0), q2)])
        w.write(c_tf, t0 * 10**9, ts.serialize_cdr(msg, "tf2_msgs/msg/TFMessage"))
        F = T["sensor_msgs/msg/PointField"]
        for k, p in enumerate(pts):  # x y z and a velocity field under another name
            data = np.concatenate([p, p[:, :1] * 0.5], axis=1).astype("<f4")
            cloud = T["sensor_msgs/msg/PointCloud2"](
                header=header(k, "radar_link"), height=1, width=len(p),
                fields=[F(name=n, offset=4 * i, datatype=7, count=1)
                        for i, n in enumerate(("x", "y", "z", "velocity"))],
                is_bigendian=False, point_step=16, row_step=16 * len(p),
                data=data.reshape(-1).view(np.uint8), is_dense=True)
            w.write(c_pts, (t0 + k) * 10**9, ts.serialize_cdr(cloud, "sensor_msgs/msg/PointCloud2"))

    with pytest.warns(DataWarning, match=r"/radar/detections has no field for intensity \(its fields: "
                                         r"x, y, z, velocity\)"), \
            pytest.warns(CalibrationWarning, match=r"preset extrinsics .* for cascade, imu, lidar, "
                                                   r"vicon: the bag's /tf_static gave none"):
        imp = import_bag(path, tmp_path / "ds", topics={"/radar/detections": "single_chip/pointclouds",
                                                        "/tf_static": "tf_static"},
                         base_frame="base_link")
    seq = open_sequence(imp.run_path)
    got = seq.single_chip.pointclouds
    assert np.array_equal(got.timestamps, t0 + np.arange(2) + 0.25)
    for k, p in enumerate(pts):
        assert np.array_equal(got[k][:, :3], p)
        assert np.all(got[k][:, 3] == 0)                    # no intensity field: zeros
        assert np.array_equal(got[k][:, 4], (p[:, 0] * 0.5).astype(np.float32))
    # base_T_radar = base_T_mount @ mount_T_radar, composed here with plain matrices
    m1, m2 = np.eye(4), np.eye(4)
    m1[:3, :3], m1[:3, 3] = Rotation.from_quat(q1).as_matrix(), (1.0, 0.0, 0.5)
    m2[:3, :3], m2[:3, 3] = Rotation.from_quat(q2).as_matrix(), (0.0, 0.2, 0.0)
    assert np.allclose(seq.calib.transforms["single_chip"].matrix(), m1 @ m2, atol=1e-12)
    assert imp.extrinsics == ["single_chip"]
    # The other sensors' extrinsics in the calib just written are the presets: said, kept apart.
    assert imp.preset_extrinsics == ["cascade", "imu", "lidar", "vicon"]

    with pytest.raises(FormatError, match="carries sensor_msgs/msg/PointCloud2"):
        import_bag(path, tmp_path / "ds2", topics={"/radar/detections": "imu"})
    with pytest.raises(MissingDataError, match="no topic /nope"):
        import_bag(path, tmp_path / "ds2", topics={"/nope": "imu"})
    with pytest.raises(OutputExistsError):
        import_bag(path, tmp_path / "ds", topics={"/radar/detections": "single_chip/pointclouds"})
    with_tf = {"/radar/detections": "single_chip/pointclouds", "/tf_static": "tf_static"}
    imp2 = import_bag(path, tmp_path / "ds", topics=with_tf, base_frame="base_link", overwrite=True)
    assert not imp2.calib_written                              # the existing calib is kept
    assert imp2.extrinsics_not_applied == []                   # and agrees with the bag
    # A bag whose extrinsics differ from the kept calib: said, never silently dropped.
    tf_file = tmp_path / "ds" / "calib" / "transforms" / "base_to_single_chip.txt"
    xyz, quat = tf_file.read_text().splitlines()[:2]
    z = float(xyz.split()[2]) + 0.25
    tf_file.write_text(" ".join([*xyz.split()[:2], repr(z)]) + "\n" + quat + "\n")
    with pytest.warns(CalibrationWarning, match="single_chip"):
        imp3 = import_bag(path, tmp_path / "ds", topics=with_tf, base_frame="base_link", overwrite=True)
    assert imp3.extrinsics_not_applied == ["single_chip"]


def test_outputs_are_never_overwritten_unless_asked(run, tmp_path):
    bag = tmp_path / "a.bag"
    export_bag(run, bag, "ros1", streams=["imu"])
    size = bag.stat().st_size
    with pytest.raises(OutputExistsError):
        export_bag(run, bag, "ros1", streams=["imu"])
    export_bag(run, bag, "ros1", streams=["imu", "groundtruth"], overwrite=True)
    assert bag.stat().st_size > size
    other = tmp_path / "notes.txt"
    other.write_text("mine")
    with pytest.raises(OutputExistsError, match="not a ros1 bag"):
        export_bag(run, other, "ros1", overwrite=True)
    assert other.read_text() == "mine"
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "x.txt").write_text("mine")
    with pytest.raises(OutputExistsError):
        import_bag(bag, tmp_path, name="mine", overwrite=True)   # not written by an import
    with pytest.raises(FormatError, match=r"expected a ROS 1 \.bag"):
        import_bag(other, tmp_path / "ds")
    assert not list(tmp_path.glob(".*partial*"))


def test_cli_export_and_import(run, tmp_path, capsys):
    bag = tmp_path / "cli.bag"
    assert main(["export", str(run.location), str(bag), "--format", "ros1", "--quiet",
                 "--streams", "imu,groundtruth", "--topic", "imu=/rig/imu"]) == 0
    out = capsys.readouterr().out
    assert "/rig/imu" in out and "ros1 bag" in out
    assert main(["export", str(run.location), str(bag), "--format", "ros1", "--quiet"]) == 1
    assert main(["import", str(bag), str(tmp_path / "ds"), "--quiet",
                 "--topic", "/rig/imu=imu", "--topic", "/groundtruth/odom=groundtruth"]) == 0
    back = open_sequence(Path(tmp_path / "ds" / "cli"))
    assert np.array_equal(back.imu.data, run.imu.data)
    assert main(["import", str(bag), "--list"]) == 0
    assert "/rig/imu" in capsys.readouterr().out


# -- what a new user meets: empty bags, foreign fields, clocks, bad frames ------------------------
def _foreign_bag(path, fields=("x", "y", "z", "snr_db", "v_doppler_mps"), cloud_t0=1_700_000_000,
                 imu_t0=1_700_000_000, n=3, seed=4):
    """A ROS 2 bag as another recorder writes it: radar points with its own field names and an
    IMU topic; returns the points written (float32, columns in ``fields`` order)."""
    from rosbags.rosbag2 import Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    rng = np.random.default_rng(seed)
    clouds = [rng.standard_normal((5 + k, len(fields))).astype(np.float32) for k in range(n)]

    def header(t, frame):
        sec = int(t)
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9)),
            frame_id=frame)

    F = T["sensor_msgs/msg/PointField"]
    V = T["geometry_msgs/msg/Vector3"]
    with Writer(path, version=8) as w:
        c_pts = w.add_connection("/radar/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c_imu = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        for k, p in enumerate(clouds):
            t = cloud_t0 + 0.1 * k
            cloud = T["sensor_msgs/msg/PointCloud2"](
                header=header(t, "radar"), height=1, width=len(p),
                fields=[F(name=nm, offset=4 * i, datatype=7, count=1) for i, nm in enumerate(fields)],
                is_bigendian=False, point_step=4 * len(fields), row_step=4 * len(fields) * len(p),
                data=p.astype("<f4").reshape(-1).view(np.uint8), is_dense=True)
            w.write(c_pts, round(t * 1e9), ts.serialize_cdr(cloud, "sensor_msgs/msg/PointCloud2"))
        for k in range(4):
            t = imu_t0 + 0.05 * k
            imu = T["sensor_msgs/msg/Imu"](
                header=header(t, "imu"),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9), angular_velocity=V(x=0.0, y=0.0, z=0.1 * k),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=V(x=0.0, y=0.0, z=9.8),
                linear_acceleration_covariance=np.zeros(9))
            w.write(c_imu, round(t * 1e9), ts.serialize_cdr(imu, "sensor_msgs/msg/Imu"))
    return clouds


FOREIGN = {"/radar/points": "single_chip/pointclouds", "/imu": "imu"}


def test_import_of_an_empty_bag_is_one_named_error(tmp_path, capsys):
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    # Bags with topics but no message (what a recorder stopped at once leaves), both formats.
    w1 = Writer1(tmp_path / "empty.bag")
    w1.open()
    w1.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=get_typestore(Stores.ROS1_NOETIC))
    w1.close()
    with Writer2(tmp_path / "empty2", version=8) as w2:
        w2.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=get_typestore(Stores.ROS2_HUMBLE))
    with Writer2(tmp_path / "bare", version=8):
        pass                                                     # not even a topic
    for bag in (tmp_path / "empty.bag", tmp_path / "empty2", tmp_path / "bare"):
        topics = "" if bag.name == "bare" else r" \(topics: /imu/data\)"
        with pytest.raises(MissingDataError, match=rf"{bag}: an empty bag: no messages{topics}$"):
            import_bag(bag, tmp_path / "ds")
        assert main(["import", str(bag), str(tmp_path / "ds"), "--quiet"]) == 1
        err = capsys.readouterr().err
        assert err.startswith(f"coloradar: error: {bag}: an empty bag") and err.count("\n") == 1
    assert not (tmp_path / "ds").exists() or not any((tmp_path / "ds").iterdir())
    # A zero-byte .bag file: one line too, also for --list (a rosbags traceback before).
    (tmp_path / "zero.bag").write_bytes(b"")
    for argv in (["import", str(tmp_path / "zero.bag"), str(tmp_path / "ds")],
                 ["import", str(tmp_path / "zero.bag"), "--list"]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.startswith(f"coloradar: error: {tmp_path / 'zero.bag'}: ")


def test_unrecognised_point_fields_are_said_and_can_be_mapped(tmp_path, capsys):
    bag = tmp_path / "fieldbag"
    clouds = _foreign_bag(bag)
    with pytest.warns(DataWarning, match=r"/radar/points has no field for intensity or range_rate "
                                         r"\(its fields: x, y, z, snr_db, v_doppler_mps\)"):
        res = import_bag(bag, tmp_path / "ds", name="plain", topics=FOREIGN)
    got = open_sequence(res.run_path).single_chip.pointclouds
    assert all(np.all(got[k][:, 3:] == 0) for k in range(len(got)))   # zeros, but said
    # Mapped: the recorder's values, in coloradar's columns (x y z intensity range_rate).
    res = import_bag(bag, tmp_path / "ds", name="mapped", topics=FOREIGN,
                     fields={"intensity": "snr_db", "range_rate": "v_doppler_mps"})
    got = open_sequence(res.run_path).single_chip.pointclouds
    for k, p in enumerate(clouds):
        assert np.array_equal(got[k], p)
    # Recorders with > 0 approaching: one switch gives coloradar's sign (> 0 receding).
    res = import_bag(bag, tmp_path / "ds", name="flipped", topics=FOREIGN,
                     fields={"intensity": "snr_db", "range_rate": "v_doppler_mps"}, flip_range_rate=True)
    got = open_sequence(res.run_path).single_chip.pointclouds
    assert np.array_equal(got[1][:, 4], -clouds[1][:, 4]) and np.array_equal(got[1][:, :4], clouds[1][:, :4])
    # A mapped name the bag does not have is an error naming the fields found; nothing written.
    with pytest.raises(FormatError, match=r"no point-cloud topic has the field 'snr' given for "
                                          r"intensity \(fields found: /radar/points: x, y, z, snr_db"):
        import_bag(bag, tmp_path / "ds", name="typo", topics=FOREIGN, fields={"intensity": "snr"})
    assert not (tmp_path / "ds" / "typo").exists()
    # The same from the command line.
    argv = ["import", str(bag), str(tmp_path / "ds"), "--name", "cli", "--quiet",
            "--topic", "/radar/points=single_chip/pointclouds", "--topic", "/imu=imu",
            "--field", "intensity=snr_db", "--field", "range_rate=v_doppler_mps"]
    assert main(argv) == 0
    assert np.array_equal(open_sequence(tmp_path / "ds" / "cli").single_chip.pointclouds[2], clouds[2])
    with pytest.warns(DataWarning, match="imported as zeros; name the fields with "
                                         "--field intensity=NAME --field range_rate=NAME"):
        assert main([*argv[:10], "--overwrite"]) == 0
    assert main([*argv[:10], "--field", "speed=v"]) == 1
    assert "expected intensity=FIELD or range_rate=FIELD" in capsys.readouterr().err


def test_streams_that_do_not_overlap_in_time_are_said(tmp_path):
    bag = tmp_path / "clocks"
    _foreign_bag(bag, fields=("x", "y", "z", "intensity", "doppler"), imu_t0=1_700_000_100)
    with pytest.warns(DataWarning, match=r"streams that do not overlap in time: "
                                         r"single_chip/pointclouds and imu"):
        res = import_bag(bag, tmp_path / "ds", topics=FOREIGN)
    assert res.disjoint == [("single_chip/pointclouds", "imu")]
    # Overlapping streams: no warning.
    bag2 = tmp_path / "same_clock"
    _foreign_bag(bag2, fields=("x", "y", "z", "intensity", "doppler"), imu_t0=1_700_000_000.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert import_bag(bag2, tmp_path / "ds", topics=FOREIGN).disjoint == []


def test_ros2_export_holds_normal_file_names(run, tmp_path):
    out = tmp_path / "mybag"
    export_bag(run, out, "ros2", streams=["imu", "groundtruth"])
    assert sorted(p.name for p in out.iterdir()) == ["metadata.yaml", "mybag.db3"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mybag"]      # no partial left
    meta = (out / "metadata.yaml").read_text()
    assert "partial" not in meta and "mybag.db3" in meta
    # `cp mybag/* elsewhere/` gets a whole bag: rosbags reads the copy.
    copy = tmp_path / "copied"
    copy.mkdir()
    for f in out.glob("*"):                                  # what a shell's * expands to
        (copy / f.name).write_bytes(f.read_bytes())
    with AnyReader([copy]) as reader:
        n = sum(1 for _ in reader.messages())
    assert n == len(run.imu.timestamps) + len(run.groundtruth.timestamps)
    export_bag(run, out, "ros2", streams=["imu"], overwrite=True)      # replaced the same way
    assert sorted(p.name for p in out.iterdir()) == ["metadata.yaml", "mybag.db3"]


@pytest.mark.parametrize("fmt", ["ros1", "ros2"])
def test_export_skips_and_reports_a_bad_frame(run, tmp_path, fmt, capsys):
    import shutil

    root, src = tmp_path / "data", Path(run.location)
    shutil.copytree(src.parent / "calib", root / "calib")
    shutil.copytree(src, root / src.name)
    lid = open_sequence(root / src.name).lidar.pointclouds
    bad = Path(lid.path(2))
    bad.write_bytes(bad.read_bytes()[:1001])                  # truncated mid-row
    seq = open_sequence(root / src.name)
    out = tmp_path / ("run.bag" if fmt == "ros1" else "run_ros2")
    with pytest.warns(DataWarning, match=rf"{bad.name}.*lidar/pointclouds frame 2 skipped"):
        res = export_bag(seq, out, fmt, streams=["lidar/pointclouds", "imu"])
    assert len(res.failures) == 1 and str(bad) in res.failures[0]
    assert res.counts["/lidar/points"] == len(lid) - 1
    with AnyReader([out]) as reader:                          # a valid bag with all the rest
        stamps = [t for c, t, _ in reader.messages() if c.topic == "/lidar/points"]
        n_imu = sum(1 for c, _, _ in reader.messages() if c.topic == "/imu/data")
    sec, nsec = times_to_ns(np.delete(lid.timestamps, 2))
    assert stamps == list(sec * 10**9 + nsec) and n_imu == len(seq.imu.timestamps)
    # The command goes on to the end, says it, and exits 1.
    with pytest.warns(DataWarning, match=rf"{bad.name}"):   # on stderr: "warning: ...", one line
        code = main(["export", str(root / src.name), str(tmp_path / "cli_out"),
                     "--format", fmt, "--quiet", "--streams", "lidar/pointclouds,imu"])
    cap = capsys.readouterr()
    assert code == 1
    assert "bad frames skipped: 1" in cap.out and f"/lidar/points {len(lid) - 1:>18}" in cap.out
    assert "Traceback" not in cap.err
    assert cap.err.rstrip().splitlines()[-1].startswith("coloradar: error: 1 frame(s) of ")


def test_import_usage_shows_out_as_required(capsys):
    with pytest.raises(SystemExit):
        main(["import", "--help"])
    usage = capsys.readouterr().out.split("\n\n")[0]
    assert "BAG OUT" in usage and "[out]" not in usage and "[OUT]" not in usage
    with pytest.raises(SystemExit) as exc:
        main(["import", "some.bag"])                           # a usage error: exit 2
    assert exc.value.code == 2
    assert "required: OUT" in capsys.readouterr().err


def test_a_damaged_message_is_one_named_error(run, tmp_path):
    import sqlite3

    out = tmp_path / "dmg"
    export_bag(run, out, "ros2", streams=["imu"])
    with sqlite3.connect(out / "dmg.db3") as db:              # one message cut to 3 bytes
        db.execute("UPDATE messages SET data = x'000100' WHERE id = 5")
    with pytest.raises(FormatError, match=r"dmg: a sensor_msgs/msg/Imu message on /imu/data "
                                          r"\(bag time \d+ ns\) cannot be decoded"):
        import_bag(out, tmp_path / "ds")
    assert not list((tmp_path / "ds").glob(".*partial*"))      # nothing half-written is left
