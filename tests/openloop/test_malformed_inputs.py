"""Inputs to ``foveatrack track`` a user can get wrong: each gives one clear line naming what was
wrong (the file, topic, message type or field), exit status 2, no traceback."""

import shutil
from pathlib import Path

import numpy as np
import pytest

import bag_writers as bw
from foveatrack.cli import main

FIXTURE = Path(__file__).parent / "mmaud_seq1" / "livox_avia"
TOPIC = "/livox/lidar"


@pytest.fixture(scope="module")
def frames():
    return bw.npy_frames(FIXTURE)[:4]


def _fails(argv, capsys, *needles):
    code = main(["track", *map(str, argv)])
    out = capsys.readouterr()
    err = out.err.strip()
    assert code == 2, (code, out.out, err)
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith("foveatrack: error: ")
    for n in needles:
        assert str(n) in err, (n, err)
    return err


def test_wrong_topic_names_it_and_lists_the_bags_topics(tmp_path, frames, capsys):
    bag = bw.write_bag(tmp_path / "b", frames, "custom", ros1=False, extra_topics=("/status",))
    _fails([bag, "--topic", "/velodyne_points"], capsys, "'/velodyne_points'", "/livox/lidar",
           "livox_ros_driver2/msg/CustomMsg", "/status")


def test_no_topic_with_two_clouds_lists_the_topics(tmp_path, frames, capsys):
    bag = bw.write_bag(tmp_path / "b.bag", frames, "pointcloud2", ros1=True, extra_clouds=("/velodyne_points",),
                       extra_topics=("/status",))
    _fails([bag], capsys, "--topic", "/livox/lidar (sensor_msgs/msg/PointCloud2, 4 messages)", "/velodyne_points")


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1-bag", "ros2-mcap"])
def test_no_topic_with_one_cloud_reads_it_and_says_so(tmp_path, frames, capsys, ros1):
    # before: refused, naming --topic and the one topic there was to give (an audit's finding)
    bag = bw.write_bag(tmp_path / ("b.bag" if ros1 else "b"), frames, "pointcloud2", ros1=ros1,
                       extra_topics=("/status",))
    assert main(["track", str(bag)]) == 0
    out = capsys.readouterr()
    assert "reading /livox/lidar, the bag's only point-cloud topic" in out.err, out.err
    assert "frames 4, tracked" in out.out, out.out


def test_topic_that_is_not_a_cloud_names_its_type(tmp_path, frames, capsys):
    bag = bw.write_bag(tmp_path / "b.bag", frames, "pointcloud2", ros1=True, extra_topics=("/status",))
    _fails([bag, "--topic", "/status"], capsys, "/status", "std_msgs/msg/String", "not a point cloud")


def test_pointcloud2_without_z_names_the_field(tmp_path, frames, capsys):
    bag = bw.write_bag(tmp_path / "b", frames, "pointcloud2", ros1=False, drop=("z",))
    _fails([bag, "--topic", TOPIC], capsys, "no field z", "fields: x, y, intensity", TOPIC, "message 0")


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1-bag", "ros2-mcap"])
def test_truncated_bag(tmp_path, frames, capsys, ros1):
    bag = bw.write_bag(tmp_path / ("b.bag" if ros1 else "b"), frames, "custom", ros1=ros1)
    f = bag if ros1 else next(bag.glob("*.mcap"))
    data = f.read_bytes()
    cut = tmp_path / ("cut.bag" if ros1 else "cut.mcap")
    cut.write_bytes(data[: len(data) // 2])
    _fails([cut, "--topic", TOPIC], capsys, str(cut))


def test_pcd_with_a_bad_header(tmp_path, capsys):
    d = tmp_path / "pcd"
    d.mkdir()
    (d / "1706255621.614239.pcd").write_bytes(b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4\nDATA binary\n\x00\x00")
    _fails([d], capsys, "1706255621.614239.pcd", "not a readable PCD", "bad header")


def test_pcd_without_xyz_names_the_field(tmp_path, capsys):
    from pypcd4 import PointCloud

    d = tmp_path / "pcd"
    d.mkdir()
    PointCloud.from_points(np.ones((3, 2)), ("x", "y"), (np.float32, np.float32)).save(d / "1706255621.5.pcd")
    _fails([d], capsys, "1706255621.5.pcd", "no field z")


def test_empty_folder(tmp_path, capsys):
    d = tmp_path / "frames"
    d.mkdir()
    _fails([d], capsys, str(d), "empty folder")


def test_npy_of_the_wrong_shape_names_the_file(tmp_path, capsys):
    d = tmp_path / "frames"
    d.mkdir()
    np.save(d / "1706255621.614239.npy", np.ones((10, 2)))
    _fails([d], capsys, "1706255621.614239.npy", "shape (10, 2)")


def test_npy_not_named_by_a_time(tmp_path, capsys):
    d = tmp_path / "frames"
    d.mkdir()
    shutil.copy(next(FIXTURE.glob("*.npy")), d / "frame_0001.npy")
    _fails([d], capsys, "frame_0001.npy", "not a time")


def test_npy_that_is_not_an_array(tmp_path, capsys):
    d = tmp_path / "frames"
    d.mkdir()
    (d / "1706255621.614239.npy").write_bytes(b"not numpy at all")
    _fails([d], capsys, "1706255621.614239.npy", "not a readable .npy")


def test_reference_csv_with_a_bad_row(tmp_path, capsys):
    ref = tmp_path / "ref.csv"
    ref.write_text("time,x,y,z\n1706255621.6,1,2,3\n1706255621.7,1,two,3\n")
    _fails([FIXTURE, "--reference", ref], capsys, "ref.csv:3", "time, x, y, z")


def test_missing_source_and_a_single_pcd_file(tmp_path, capsys):
    _fails([tmp_path / "nothing.bag"], capsys, "nothing.bag", "no such file")
    one = tmp_path / "scan.pcd"
    one.write_text("x")
    _fails([one], capsys, "scan.pcd", "folder of PCD files")


def test_a_bad_box_and_a_bad_config(tmp_path, capsys):
    _fails([FIXTURE, "--box", "0", "0", "0", "1", "-1", "1"], capsys, "--box", "min_xyz")
    cfg = tmp_path / "c.toml"
    cfg.write_text("[openloop]\nmin_points = 0\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "min_points")
    cfg.write_text("[openloop]\nconfirm_hitz = 3\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "confirm_hitz")


def test_a_config_with_tables_track_does_not_read(tmp_path, capsys):
    # before: [tracker.sky] beside [openloop] was ignored without a word, and alone it was refused as
    # "[openloop]: unknown key(s) 'tracker'" in a file with no [openloop] table
    cfg = tmp_path / "c.toml"
    cfg.write_text("[openloop]\nmin_points = 3\n[tracker.sky]\nmin_points = 2\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "[tracker]: the multi-object tracker")
    cfg.write_text("[tracker.sky]\nmin_points = 2\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "reads an [openloop] table")
    cfg.write_text("[scene]\nname = 'x'\n[[target]]\nid = 'a'\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "[scene], [target]")
    # the open-loop keys bare, with their own [space] table, are still read (this one's box is bad)
    cfg.write_text("min_points = 3\n[space]\nkind = 'box'\n")
    _fails([FIXTURE, "--config", cfg], capsys, "c.toml", "space: box needs min_xyz")


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_a_pcd_cut_short_gives_its_whole_points_and_says_so(tmp_path, encoding):
    # A scan whose writer was killed: read silently (ascii, its last number cut in half) or refused
    # whole with numpy's "buffer size must be a multiple of element size" (binary).  Now its whole
    # points are read, to the bit, and one line says how many of the header's are missing.
    from pypcd4 import Encoding, PointCloud

    from foveatrack.sources.pcd_folder import PcdFolderSource

    xyz = np.random.default_rng(3).uniform(1, 50, (820, 3))
    f = tmp_path / "1706255621.000000.pcd"
    PointCloud.from_points(xyz, ("x", "y", "z"), (np.float64,) * 3).save(f, encoding=Encoding(encoding))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2 + 5])
    said = []
    frames = list(PcdFolderSource(tmp_path, warn=said.append))
    got = frames[0].frame.xyz
    assert 300 < len(got) < 820 and len(said) == 1
    assert f"holds {len(got)} of the 820 points" in said[0] and "cut short" in said[0]
    want = xyz[:len(got)] if encoding == "binary" else np.array([[float(f"{v:.10g}") for v in p] for p in xyz[:len(got)]])
    # the source may order points by time: compared as sorted rows
    assert np.allclose(np.sort(got.view([("", float)] * 3), axis=0).view(float).reshape(-1, 3),
                       np.sort(want.view([("", float)] * 3), axis=0).view(float).reshape(-1, 3), rtol=0, atol=1e-6)
    f.write_bytes(data)
    said.clear()
    assert len(list(PcdFolderSource(tmp_path, warn=said.append))[0].frame.xyz) == 820 and not said


def test_a_bag_cut_short_says_how_to_mend_it(tmp_path, frames, capsys):
    # the usual state of a bag whose recorder was killed: no index (ROS 1) or no end (ROS 2 MCAP)
    bag = bw.write_bag(tmp_path / "b.bag", frames, "pointcloud2", ros1=True)
    data = bag.read_bytes()
    bag.write_bytes(data[: int(len(data) * 0.9)])
    assert main(["track", str(bag), "--topic", "/livox/lidar"]) == 2
    err = capsys.readouterr().err
    assert "not a readable bag" in err and "rosbag reindex" in err and "Traceback" not in err, err


def test_an_npy_cut_short_gives_its_whole_points_and_says_so(tmp_path, capsys):
    # One frame of a folder cut short aborted the whole run ("Failed to read all data for array"),
    # where a PCD cut short is read to its last whole point: now the same, one line naming the file.
    from foveatrack.sources.npy_folder import NpyFolderSource

    xyz = np.random.default_rng(4).uniform(1, 50, (500, 3))
    for k in range(3):
        np.save(tmp_path / f"1706255621.{k}00000.npy", xyz + k)
    cut = tmp_path / "1706255621.100000.npy"
    data = cut.read_bytes()
    cut.write_bytes(data[: len(data) - 4001])             # 7999 bytes of points left: 333 and a third
    said = []
    frames = [fr for _, fr in NpyFolderSource(tmp_path, warn=said.append)]
    assert [fr.n_points for fr in frames] == [500, 333, 500]
    np.testing.assert_array_equal(frames[1].xyz, xyz[:333] + 1)
    assert len(said) == 1 and "1706255621.100000.npy: holds 333 of the 500 points" in said[0], said
    assert main(["track", str(tmp_path), "--csv", str(tmp_path / "t.csv")]) == 0
    err = capsys.readouterr().err
    assert "WARNING:" in err and "1706255621.100000.npy" in err and "Traceback" not in err, err
    assert len((tmp_path / "t.csv").read_text().splitlines()) == 4
    cut.write_bytes(data[:60])                              # the header cut: not an array at all
    _fails([tmp_path], capsys, "1706255621.100000.npy", "not a readable .npy")


@pytest.mark.parametrize("n, stamp", [(12, 0), (3, 1706255621_614239000)], ids=["12-unset", "3-all-one"])
def test_a_bag_whose_clouds_all_share_one_stamp_is_refused(tmp_path, n, stamp, capsys):
    # every header.stamp 0 (a converter that never set it): "tracked 118/120", every frame at t=0
    xyz = bw.npy_frames(FIXTURE)[0][1]
    bag = bw.write_bag(tmp_path / "b.bag", [(stamp, xyz)] * n, "pointcloud2", ros1=True)
    err = _fails([bag, "--topic", TOPIC, "--csv", tmp_path / "t.csv"], capsys, "b.bag", TOPIC,
                 f"the first {min(n, 10)} messages all have header.stamp {stamp * 1e-9:.6f} s")
    assert ("never set" in err) == (stamp == 0)
    assert not (tmp_path / "t.csv").exists()


def test_header_stamps_that_go_back_or_repeat_are_counted_and_said(tmp_path, frames):
    # a swapped pair and a repeated stamp were read in the bag's order without a word
    from foveatrack.sources.rosbag import BagSource

    from rosbags.rosbag1 import Writer

    ns = [s for s, _ in frames]
    stamps = [ns[0], ns[2], ns[1], ns[3], ns[3]]
    store, bag = bw._stores(True), tmp_path / "b.bag"
    with Writer(bag) as w:                    # logged in order, the stamps as they are
        c = w.add_connection(TOPIC, "sensor_msgs/msg/PointCloud2", typestore=store)
        for i, s in enumerate(stamps):
            msg = bw.pointcloud2(store, s, frames[0][1], True)
            w.write(c, ns[0] + (i + 1) * bw.PERIOD_NS, store.serialize_ros1(msg, "sensor_msgs/msg/PointCloud2"))
    said = []
    got = [fr.t_start_s for _, fr in BagSource(bag, TOPIC, warn=said.append)]
    assert got == [s / 10**9 for s in stamps]
    assert len(said) == 1 and "2 of its 5 messages have a header.stamp not after the message before's" in said[0]
    assert f"message 2 at {ns[1] * 1e-9:.6f} s, after {ns[2] * 1e-9:.6f} s" in said[0] and TOPIC in said[0], said
    said.clear()
    list(BagSource(bw.write_bag(tmp_path / "ok.bag", frames, "pointcloud2", ros1=True), TOPIC, warn=said.append))
    assert said == []


def test_a_livox_viewer_file_points_to_replay(tmp_path, capsys):
    # before: "not a recording this reads", though `replay` reads it
    lvx = tmp_path / "run.lvx"
    lvx.write_bytes(b"livox_tech\x00\x00\x00\x00\x00\x00")
    _fails([lvx], capsys, "run.lvx", "Livox Viewer", f"foveatrack replay {lvx} --tracker-config FILE")


def test_a_folder_of_split_bags_says_to_give_one(tmp_path, frames, capsys):
    # before: "an empty folder for frames" for a folder holding rec_0.bag, rec_1.bag
    d = tmp_path / "split"
    d.mkdir()
    bw.write_bag(d / "rec_0.bag", frames[:2], "pointcloud2", ros1=True)
    bw.write_bag(d / "rec_1.bag", frames[2:], "pointcloud2", ros1=True)
    err = _fails([d], capsys, str(d), "holds 2 .bag files", "give one bag", "metadata.yaml", d / "rec_0.bag")
    assert "empty folder" not in err
    # a ROS 2 bag's .mcap without its metadata.yaml: give the file
    bag = bw.write_bag(tmp_path / "r2", frames, "pointcloud2", ros1=False)
    (bag / "metadata.yaml").unlink()
    _fails([bag], capsys, "holds 1 .mcap file", "give the .mcap file itself")


@pytest.mark.parametrize("head", [b"", b"#ROSBAG V2.0\n", b"\x1f\x8b\x08\x00"], ids=["bytes", "ros1-magic", "gzip"])
def test_a_file_named_bag_that_is_no_bag_is_not_told_to_reindex(tmp_path, frames, capsys, head):
    # before: any file named .bag rosbags could not open got "'rosbag reindex BAG' ... then read it
    # again", which cannot mend a file that never was a bag
    bag = tmp_path / "garbage.bag"
    bag.write_bytes(head + bytes(range(256)) * 10)
    err = _fails([bag, "--topic", TOPIC], capsys, "garbage.bag", "not a ROS bag")
    assert "rosbag reindex BAG" not in err and "read it again" not in err, err
    if head.startswith(b"#ROSBAG"):
        assert "no bag header record follows it" in err and "50462976 bytes" in err, err
    else:
        assert "does not start with the ROS 1 bag header '#ROSBAG V2.0'" in err
        assert repr(head + bytes(range(16 - len(head)))) in err, err
        assert ("gzip" in err) == head.startswith(b"\x1f\x8b"), err
    # a bag cut short keeps its magic and header record: told to reindex (test_a_bag_cut_short_says_how_to_mend_it)
    good = bw.write_bag(tmp_path / "b.bag", frames, "pointcloud2", ros1=True)
    data = good.read_bytes()
    good.write_bytes(data[: int(len(data) * 0.9)])
    _fails([good, "--topic", TOPIC], capsys, "rosbag reindex BAG")


def test_a_bag_of_one_kind_named_as_the_other(tmp_path, frames, capsys):
    ros2 = next(bw.write_bag(tmp_path / "r2", frames, "pointcloud2", ros1=False).glob("*.mcap"))
    ros1 = bw.write_bag(tmp_path / "r1.bag", frames, "pointcloud2", ros1=True)
    _fails([ros2.rename(tmp_path / "x.bag"), "--topic", TOPIC], capsys, "x.bag", "an MCAP file", "name it .mcap")
    _fails([ros1.rename(tmp_path / "x.mcap"), "--topic", TOPIC], capsys, "x.mcap", "a ROS 1 bag", "name it .bag")


def test_a_foveatrack_recording_points_to_replay_and_export(tmp_path, capsys):
    # before: "not a readable bag (Profile is not ros2.)" for foveatrack's own recording
    rec = tmp_path / "run.mcap"
    assert main(["track", str(FIXTURE), "--record", str(rec), "--json"]) == 0
    capsys.readouterr()
    for argv in ([rec], [rec, "--topic", TOPIC]):
        err = _fails(argv, capsys, "run.mcap", "a foveatrack recording", f"foveatrack replay {rec}",
                     f"foveatrack export {rec}")
        assert "Profile" not in err


@pytest.mark.parametrize("ros1", [True, False], ids=["ros1-bag", "ros2-mcap"])
def test_a_topic_without_messages_is_refused_before_any_output(tmp_path, frames, ros1, capsys):
    # before: exit 0, "frames 0", a CSV of its header only and empty plots, and no word of why
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2

    store, bag = bw._stores(ros1), tmp_path / ("b.bag" if ros1 else "b")
    pc2 = "sensor_msgs/msg/PointCloud2"
    w = Writer1(bag) if ros1 else Writer2(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    ser = store.serialize_ros1 if ros1 else store.serialize_cdr
    with w:
        w.add_connection(TOPIC, pc2, typestore=store)
        other = w.add_connection("/points", pc2, typestore=store)
        for ns, xyz in frames:
            w.write(other, ns, ser(bw.pointcloud2(store, ns, xyz, ros1), pc2))
    out = [tmp_path / "t.csv", tmp_path / "plots", tmp_path / "t.mcap"]
    _fails([bag, "--topic", TOPIC, "--csv", out[0], "--plot", out[1], "--record", out[2]], capsys,
           f"topic {TOPIC} has no messages", f"{TOPIC} (sensor_msgs/msg/PointCloud2, 0 messages)",
           "/points (sensor_msgs/msg/PointCloud2, 4 messages)")
    assert not any(p.exists() for p in out)
