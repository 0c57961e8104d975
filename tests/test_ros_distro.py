"""The ROS 2 distribution of the MCAP outputs (the config's ``output.ros_distro``,
streams/distro.py): ``simulate``'s log, ``run``'s estimates.mcap (with ``--map`` too) and
``map``'s fgm.mcap, each made for Humble and for Jazzy from a tenth of a lap (micro.yaml),
are read message by message by rosbags' typestore of that distribution with *its*
definitions (not the file's), the bytes written again by it equal to the file's (no
byte missing or left over); every schema is that typestore's text and the rosbag2 record
names the distribution. A Jazzy Range carries the sonar model's variance; ``run`` gives
the same trajectory on either log; Humble, the default, leaves the files as before."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import shared_dir
from mcap.reader import make_reader
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore
from test_robust_logs import cli

from fuzzyslam.config import load_config
from fuzzyslam.errors import ConfigError

MICRO = Path(__file__).parent / "micro.yaml"  # 1/10 lap
DISTROS = ("humble", "jazzy")
STORES = {"humble": Stores.ROS2_HUMBLE, "jazzy": Stores.ROS2_JAZZY}
RANGE = "sensor_msgs/msg/Range"
FILES = ("log.mcap", "run/estimates.mcap", "fgm/fgm.mcap", "runmap/estimates.mcap")
# the types of the outputs: the simulated log's, the estimates' (with the map) and the map's
TYPES = {
    "log.mcap": {
        "nav_msgs/msg/Odometry",
        "sensor_msgs/msg/CameraInfo",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/JointState",
        RANGE,
        "std_msgs/msg/String",
        "tf2_msgs/msg/TFMessage",
        "visualization_msgs/msg/MarkerArray",
    },
    "run/estimates.mcap": {
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "tf2_msgs/msg/TFMessage",
        "visualization_msgs/msg/MarkerArray",
    },
    "fgm/fgm.mcap": {"nav_msgs/msg/OccupancyGrid", "visualization_msgs/msg/MarkerArray"},
    "runmap/estimates.mcap": {
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "nav_msgs/msg/OccupancyGrid",
        "tf2_msgs/msg/TFMessage",
        "visualization_msgs/msg/MarkerArray",
    },
}


def _config(folder: Path, distro: str | None) -> Path:
    """micro.yaml beside ``folder``'s outputs, with ``output.ros_distro: distro`` (None:
    no output section)."""
    path = folder / "micro.yaml"
    text = MICRO.read_text(encoding="utf-8")
    if distro is not None:
        text += f"output:\n  ros_distro: {distro}\n"
    path.write_text(text, encoding="utf-8")
    return path


def _make(folder: Path, distro: str | None) -> None:
    """simulate, run, map and run --map of micro.yaml for ``distro`` into ``folder``."""
    cfg = _config(folder, distro)
    steps = (
        ("simulate", cfg, "-o", folder / "log.mcap"),
        ("run", folder / "log.mcap", "--config", cfg, "-o", folder / "run"),
        ("map", folder / "log.mcap", "--trajectory", folder / "run" / "trajectory.tum",
         "--config", cfg, "-o", folder / "fgm", "--no-figures"),
        ("run", folder / "log.mcap", "--config", cfg, "--map", folder / "fgm",
         "-o", folder / "runmap"),
    )  # fmt: skip
    for args in steps:
        code, _, err = cli(*args)
        assert code == 0, (args[0], err)


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The outputs of each distribution (built once per test run)."""
    return {
        d: shared_dir(tmp_path_factory, f"ros-distro-{d}", lambda p, d=d: _make(p, d))
        for d in DISTROS
    }


def read_as(path: Path, distro: str) -> dict[str, list]:
    """Every message of an MCAP file read by rosbags' typestore of ``distro`` with its
    own definitions, checking the file against it: the rosbag2 record names ``distro``,
    each schema is the typestore's text, and each message's bytes are what the typestore
    writes for what it read (a field missing or left over fails).

    Parameters
    ----------
    path : Path
        The file.
    distro : str
        'humble' or 'jazzy'.

    Returns
    -------
    dict
        Type name -> its messages (rosbags objects), in log order.
    """
    store = get_typestore(STORES[distro])
    out: dict[str, list] = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        assert meta["rosbag2"] == {"ROS_DISTRO": distro}, path
        for schema, _, message in reader.iter_messages():
            name = schema.name
            want, _ = store.generate_msgdef(name, ros_version=2)
            assert schema.data.decode() == want, f"{path}: {name}'s schema is not {distro}'s"
            msg = store.deserialize_cdr(message.data, name)
            again = bytes(store.serialize_cdr(msg, name))
            assert again == message.data, f"{path}: a {name} is not {distro}'s layout"
            out.setdefault(name, []).append(msg)
    return out


@pytest.mark.parametrize("distro", DISTROS)
def test_every_output_is_the_distros(made: dict[str, Path], distro: str) -> None:
    """Each file of ``distro`` is read by that typestore's definitions and holds its
    schemas; every type the outputs use is among them."""
    for name in FILES:
        types = read_as(made[distro] / name, distro)
        assert set(types) == TYPES[name], name


def test_the_other_distros_typestore_refuses_the_range(made: dict[str, Path]) -> None:
    """The two layouts differ where the distributions do: Humble's typestore refuses a
    Jazzy Range (4 bytes left over), Jazzy's a Humble one (4 bytes short), and the files'
    MarkerArray schemas differ by Jazzy's ARROW_STRIP alone."""
    for distro, other in (("humble", "jazzy"), ("jazzy", "humble")):
        store = get_typestore(STORES[other])
        with open(made[distro] / "log.mcap", "rb") as f:
            for schema, _, message in make_reader(f).iter_messages(topics=["/sonar/s00"]):
                assert schema.name == RANGE
                # Humble's bytes are 4 short of Jazzy's Range, Jazzy's 4 too many for Humble's
                why = "buffer of at least" if other == "jazzy" else "size mismatch"
                with pytest.raises(SerdeError, match=why):
                    store.deserialize_cdr(message.data, RANGE)
                break
    texts = {}
    for distro in DISTROS:
        with open(made[distro] / "run" / "estimates.mcap", "rb") as f:
            summary = make_reader(f).get_summary()
            assert summary is not None
            (text,) = [s.data.decode() for s in summary.schemas.values()
                       if s.name == "visualization_msgs/msg/MarkerArray"]  # fmt: skip
            texts[distro] = text
    assert texts["jazzy"] == texts["humble"].replace(
        "int32 TRIANGLE_LIST=11\n", "int32 TRIANGLE_LIST=11\nint32 ARROW_STRIP=12\n"
    )


def test_jazzy_range_carries_the_sonar_variance(made: dict[str, Path]) -> None:
    """A Jazzy Range's variance is the sonar model's at its reading (noise_frac and
    quantisation of the config's sonar), 0 (unknown) for a no-echo reading."""
    from fuzzyslam.sim.sonar import reading_variance

    sonar = load_config(made["jazzy"] / "micro.yaml").sonar
    ranges = read_as(made["jazzy"] / "log.mcap", "jazzy")[RANGE]
    r = np.array([m.range for m in ranges])
    var = np.array([m.variance for m in ranges])
    want = (sonar.noise_frac * r) ** 2 + sonar.quantization**2 / 12.0
    echo = r < sonar.max_range
    assert echo.sum() > 100 and (~echo).sum() > 10  # both kinds are there
    np.testing.assert_allclose(var[echo], want[echo], rtol=1e-6)
    assert np.all(var[~echo] == 0.0)
    np.testing.assert_allclose(var, reading_variance(r, sonar), rtol=1e-6)


def test_run_reads_either_log_alike(made: dict[str, Path]) -> None:
    """``run`` on the Jazzy log (its Range messages 4 bytes longer) gives the trajectory,
    landmarks and covariances of the Humble one, and ``map`` the same map."""
    for name in ("run/trajectory.tum", "run/landmarks.yaml", "run/covariance.csv",
                 "runmap/trajectory.tum", "fgm/fgm.npz", "fgm/fgm.pgm"):  # fmt: skip
        assert (made["jazzy"] / name).read_bytes() == (made["humble"] / name).read_bytes(), name


def test_humble_is_the_default_and_leaves_the_files_as_before(
    made: dict[str, Path], tmp_path: Path
) -> None:
    """Humble is the default: a config without the output section simulates the bytes of
    ``ros_distro: humble``, whose scenario record (the simulation's config) has no output
    section, so a Humble log is what it was before the choice."""
    from fuzzyslam.streams.logmeta import read_scenario
    from fuzzyslam.streams.reader import LogReader

    assert load_config(MICRO).output.ros_distro == "humble"
    code, _, err = cli("simulate", _config(tmp_path, None), "-o", tmp_path / "log.mcap")
    assert code == 0, err
    assert (tmp_path / "log.mcap").read_bytes() == (made["humble"] / "log.mcap").read_bytes()
    for distro in DISTROS:
        scenario = read_scenario(LogReader(made[distro] / "log.mcap"))
        assert "output" not in scenario.config


def test_an_unknown_distribution_is_refused(tmp_path: Path) -> None:
    """``ros_distro`` other than humble or jazzy: a ConfigError naming the key and both;
    a LogWriter of one, a ValueError."""
    from fuzzyslam.streams.writer import LogWriter

    with pytest.raises(ConfigError, match=r"output\.ros_distro.*humble, jazzy"):
        load_config(_config(tmp_path, "iron"))
    with pytest.raises(ValueError, match="humble, jazzy"):
        LogWriter(tmp_path / "x.mcap", ros_distro="rolling")


@pytest.mark.parametrize("distro", DISTROS)
def test_the_encoders_write_the_distros_bytes(distro: str) -> None:
    """streams/cdr_encode.py's Range bytes are those rosbags' typestore of the
    distribution writes for a Range of its own class, and streams/msgdefs.py's texts
    that typestore's."""
    from fuzzyslam.streams import cdr_encode
    from fuzzyslam.streams.msgdefs import MSGDEFS_OF

    store = get_typestore(STORES[distro])
    ty = store.types
    frames, r, var = ["s0", "sonar_01"], [1.25, 6.5], [2.5e-4, 0.0]
    got = cdr_encode.encode_ranges(12.5, frames, r, 0.4, 0.15, 6.5, var, distro)
    for frame, rj, vj, data in zip(frames, r, var, got, strict=True):
        header = ty["std_msgs/msg/Header"](
            stamp=ty["builtin_interfaces/msg/Time"](sec=12, nanosec=500_000_000),
            frame_id=frame,
        )
        extra = {"variance": vj} if distro == "jazzy" else {}
        msg = ty[RANGE](header=header, radiation_type=0, field_of_view=0.4, min_range=0.15,
                        max_range=6.5, range=rj, **extra)  # fmt: skip
        assert data == bytes(store.serialize_cdr(msg, RANGE))
    for name, text in MSGDEFS_OF[distro].items():
        assert store.generate_msgdef(name, ros_version=2)[0] == text, name
