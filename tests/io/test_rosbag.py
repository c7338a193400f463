"""A synthetic sequence written as a ROS 2 bag and read back with rosbags' own reader."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nidar_mi.errors import NidarError
from nidar_mi.io.rosbag import BagCamera, BagFrame, write_ros2_bag


def _frames(clouds, poses, times):
    K = np.array([[50.0, 0, 16], [0, 50.0, 12], [0, 0, 1]])
    frames = []
    for k, (pts, T, t) in enumerate(zip(clouds, poses, times)):
        rgb = np.full((24, 32, 3), 10 * k, np.uint8)
        rgb[0, 0] = [255, 0, 7]
        T_cam = T @ np.array([[0, 0, 1, 0.2], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1.0]])
        cam = BagCamera(rgb=rgb, K=K, T_world_cam=T_cam, stamp_s=t + 0.05)
        frames.append(BagFrame(stamp_s=t, T_world_lidar=T, points=pts, cameras={"cam": cam}))
    return frames


def test_bag_reads_back_with_rosbags(tmp_path, synthetic_sequence):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    clouds, poses, times = synthetic_sequence
    bag = tmp_path / "seq_bag"
    write_ros2_bag(bag, _frames(clouds, poses, times), lidar="roof")
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    got: dict[str, list] = {}
    with Reader(bag) as reader:
        assert reader.message_count == 3 * 5
        for conn, stamp, raw in reader.messages():
            msg = typestore.deserialize_cdr(raw, conn.msgtype)
            got.setdefault(conn.topic, []).append((stamp, conn.msgtype, msg))
    assert sorted(got) == ["/cam/camera_info", "/cam/image_raw", "/roof/points", "/tf"]

    clouds_msgs = got["/roof/points"]
    assert [s for s, _, _ in clouds_msgs] == [0, 100_000_000, 200_000_000]
    for (_, msgtype, msg), pts in zip(clouds_msgs, clouds):
        assert msgtype == "sensor_msgs/msg/PointCloud2" and msg.header.frame_id == "roof"
        names = [f.name for f in msg.fields]
        assert names == ["x", "y", "z", "intensity", "ring", "time", "label", "instance"]
        dtype = {7: "<f4", 4: "<u2", 6: "<u4"}
        record = np.dtype(
            {
                "names": names,
                "formats": [dtype[f.datatype] for f in msg.fields],
                "offsets": [f.offset for f in msg.fields],
                "itemsize": msg.point_step,
            }
        )
        data = np.frombuffer(msg.data.tobytes(), dtype=record)
        assert msg.width == len(pts["xyz"]) == len(data) and msg.height == 1
        np.testing.assert_array_equal(np.stack([data["x"], data["y"], data["z"]], 1), pts["xyz"])
        for field, key in (("intensity", "intensity"), ("ring", "ring"), ("time", "t")):
            np.testing.assert_array_equal(data[field], pts[key])
        np.testing.assert_array_equal(data["label"], pts["label"])
        np.testing.assert_array_equal(data["instance"], pts["instance"])
        assert set(np.unique(data["label"])) == {10, 40}

    # tf: world -> roof at each sweep start equals the pose; world -> cam at the image time
    lidar_tf = [
        (s, m.transforms[0]) for s, _, m in got["/tf"] if m.transforms[0].child_frame_id == "roof"
    ]
    assert [s for s, _ in lidar_tf] == [0, 100_000_000, 200_000_000]
    for (_, tf), T in zip(lidar_tf, poses):
        assert tf.header.frame_id == "world"
        q = tf.transform.rotation
        R = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        np.testing.assert_allclose(R, T[:3, :3], atol=1e-12)
        v = tf.transform.translation
        np.testing.assert_allclose([v.x, v.y, v.z], T[:3, 3])
    images = got["/cam/image_raw"]
    assert [s for s, _, _ in images] == [50_000_000, 150_000_000, 250_000_000]
    img = images[1][2]
    assert (img.encoding, img.height, img.width, img.step) == ("rgb8", 24, 32, 96)
    pixels = img.data.reshape(24, 32, 3)
    assert list(pixels[0, 0]) == [255, 0, 7] and list(pixels[5, 5]) == [10, 10, 10]
    info = got["/cam/camera_info"][0][2]
    np.testing.assert_allclose(info.k.reshape(3, 3), [[50, 0, 16], [0, 50, 12], [0, 0, 1]])


def test_bag_refuses_bad_input(tmp_path, synthetic_sequence):
    clouds, poses, times = synthetic_sequence
    frames = _frames(clouds, poses, times)
    (tmp_path / "exists").mkdir()
    with pytest.raises(NidarError, match="exists"):
        write_ros2_bag(tmp_path / "exists", frames)
    with pytest.raises(NidarError, match="time order"):
        write_ros2_bag(tmp_path / "b", frames[::-1])
    bad = _frames(clouds, poses, times)
    bad[1].points = dict(bad[1].points) | {"intensity": np.full(len(clouds[1]["xyz"]), np.nan)}
    with pytest.raises(NidarError, match="non-finite"):
        write_ros2_bag(tmp_path / "c", bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exists"]
