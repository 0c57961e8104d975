"""The output edge of the SLAM stage: the files of docs/contracts.md sec. 2 (trajectory.tum,
odometry.tum, covariance.csv, updates.csv, landmarks.yaml, estimates.mcap, summary.json),
streamed as the filter's rows come (:class:`StreamingOutputs`, a ``RowSink``)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from fuzzyslam.config import Config
from fuzzyslam.exactsum import ExactSum
from fuzzyslam.robot import integrate_from
from fuzzyslam.rundir import (
    COVARIANCE,
    ESTIMATES,
    LANDMARKS,
    ODOMETRY,
    SUMMARY,
    TRAJECTORY,
    UPDATES,
    write_landmarks,
)
from fuzzyslam.se2 import compose, interpolate_poses, inverse, wrap_angle
from fuzzyslam.slam.events import SlamResult, TfFrames, UpdateRow
from fuzzyslam.slam.markers import lamp_markers_cdr
from fuzzyslam.stamps import TIME_FORMAT, format_time
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr import encode_pose_with_covariance_block, encode_tf_block
from fuzzyslam.streams.tum import format_tum
from fuzzyslam.streams.writer import LogWriter


def _num(v: float) -> str:
    return f"{v:.9g}" if math.isfinite(v) else ""


def _fmt_rows(a: np.ndarray) -> str:
    """CSV rows of a finite float array (N, k): the time column (first) in
    ``stamps.TIME_FORMAT``, the others to 9 significant digits."""
    if len(a) == 0:
        return ""
    fmt = ",".join([TIME_FORMAT] + ["%.9g"] * (a.shape[1] - 1))
    return "\n".join(fmt % tuple(r) for r in a.tolist()) + "\n"


def dead_reckoning_at(t: np.ndarray, odo_t: np.ndarray, odo_poses: np.ndarray) -> np.ndarray:
    """The dead-reckoning poses (N, 3) at times ``t``: the pose after the last odometry
    increment at or before each time (the one the filter's estimate has integrated; the
    first pose, the start pose, before the first increment).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Query times (s).
    odo_t : ndarray, shape (K,)
        Times of the dead-reckoning poses (sorted).
    odo_poses : ndarray, shape (K, 3) or (K, m)
        The dead-reckoning poses (or any other rows at those times).

    Returns
    -------
    ndarray, shape (N, 3) or (N, m)
    """
    idx = np.searchsorted(np.asarray(odo_t, dtype=float), np.asarray(t, dtype=float), "right")
    a = np.asarray(odo_poses, dtype=float)
    return (a if a.ndim == 2 else a.reshape(-1, 3))[np.maximum(idx - 1, 0)]


def log_odom_at(t: np.ndarray, log_odom: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The log's odom -> base at times ``t``: ``se2.interpolate_poses`` of its series
    (x, y linear in time, the heading the shorter way round); before the series' first
    stamp and after its last, its first / last pose held (``outside="hold"``).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Query times (s).
    log_odom : (ndarray, ndarray)
        The series: increasing times (K,) and poses (K, 3), the heading continuous
        (``TfFrames.log_odom``: unwrapped over the whole series, so that a slice of it
        interpolates to the same floats as the whole, whatever the blocks).

    Returns
    -------
    ndarray, shape (N, 3)
    """
    lt, lp = log_odom
    t = np.asarray(t, dtype=float).reshape(-1)
    if not len(t):
        return np.zeros((0, 3))
    # the samples around the block's span (one more each side): the same interpolation,
    # without unwrapping the whole series per block
    i0 = max(int(np.searchsorted(lt, t.min(), "right")) - 1, 0)
    i1 = int(np.searchsorted(lt, t.max(), "left")) + 1
    return interpolate_poses(lt[i0:i1], lp[i0:i1], t, outside="hold")


def tf_payloads(
    t: np.ndarray, poses: np.ndarray, odo: np.ndarray, frames: TfFrames | None = None
) -> list[bytes]:
    """CDR of the /tf messages of trajectory rows: map -> odom (the filter's correction,
    estimate (+) (-)dead reckoning) and odom -> base_link (the dead reckoning ``odo`` at
    the same times), so that map -> odom -> base_link composes to the estimate; the
    frame names and whether odom -> base is written from ``frames`` (slam/events.py).

    When the log carries odom -> base (``frames.odom_to_base`` False), only map -> odom
    is written, against the log's odom -> base L(t) (``frames.log_odom``, interpolated by
    :func:`log_odom_at`; its end poses held outside its time span): estimate (+) (-)L(t),
    so that it composes with the log's /tf to the estimate (REP 105, as AMCL does); the
    filter's own dead reckoning may differ from the robot driver's (start pose, odometry
    delay, wheel radius). Without that series, against ``odo``.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Row times (s).
    poses : ndarray, shape (N, 3)
        The estimate.
    odo : ndarray, shape (N, 3)
        The dead reckoning at ``t``.
    frames : TfFrames, optional
        Frame names (default map, odom, base_link).

    Returns
    -------
    list of bytes
        One CDR tf2_msgs/TFMessage per row.
    """
    f = frames or TfFrames()
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    odo = np.asarray(odo, dtype=float).reshape(-1, 3)
    if not f.odom_to_base:
        odom = odo if f.log_odom is None else log_odom_at(t, f.log_odom)
        return encode_tf_block(t, [(f.map, f.odom)], [compose(poses, inverse(odom))])
    correction = compose(poses, inverse(odo))
    return encode_tf_block(t, [(f.map, f.odom), (f.odom, f.base)], [correction, odo])


def _update_line(u: UpdateRow) -> str:
    """The updates.csv line of one update attempt (unused innovation components empty):
    what ``csv.writer`` writes of these fields (none holds a comma, quote or newline), at
    half its cost."""
    v0, v1, v2 = (*np.asarray(u.v, dtype=float).tolist(), math.nan, math.nan, math.nan)[:3]
    return (
        f"{format_time(u.t)},{u.kind},{u.id},{u.dof},{_num(u.nis)},{int(u.accepted)},"
        f"{_num(v0)},{_num(v1)},{_num(v2)}\n"
    )


UPDATES_HEADER = "t,kind,id,dof,nis,accepted,v0,v1,v2\n"
COVARIANCE_HEADER = "t,pxx,pxy,pxt,pyy,pyt,ptt\n"


def _tum_lines(t, poses) -> str:
    """TUM lines of ``format_tum`` without its header line (a block of a longer file)."""
    return format_tum(t, poses).split("\n", 1)[1]


class StreamingOutputs:
    """A ``RowSink`` (slam/events.py) writing the files of docs/contracts.md sec. 2 into the
    staging directory ``tmp`` as the rows come, in blocks, so memory stays flat over long
    logs; the bytes do not depend on the block sizes. In estimates.mcap the /slam/pose
    (each followed by its /tf) and /slam/landmarks messages are interleaved in log-time
    order. /tf needs
    the dead reckoning at each row's time: the odometry block is integrated before each
    block of rows, and the poses from the last one at or before the last row are kept.
    Rows and messages are buffered and written ``rows_block`` rows at a time.

    The dead reckoning is ``robot.integrate_from`` (``robot.integrate`` block by block with
    the running sums carried over: the floats of one whole call).
    Use as a context manager inside ``OutputDir``; :meth:`finish` writes landmarks.yaml
    and the extra messages; on an exception every file is closed (and the staging
    directory is removed by ``OutputDir``)."""

    rows_block = 1024  # trajectory rows formatted per block
    odometry_block = 4096  # odometry increments integrated per block

    def __init__(
        self, tmp: Path, cfg: Config, start_pose: np.ndarray, frames: TfFrames | None = None
    ) -> None:
        self.tmp = Path(tmp)
        self.frames = frames or TfFrames()
        self.topics = cfg.topics
        self.ros_distro = cfg.output.ros_distro
        self.start_pose = np.asarray(start_pose, dtype=float)
        self.rows = 0
        self.lamp_nis = ExactSum()  # accepted lamp updates (summary's mean_nis_lamp)
        self._rows: list[tuple[float, np.ndarray, np.ndarray]] = []
        # estimates.mcap messages of the buffered block: (is /slam/landmarks, t, a, b)
        self._messages: list[tuple[bool, float, np.ndarray, np.ndarray]] = []
        self._odo_t: list[float] = []
        self._odo_u: list[tuple[float, float]] = []
        self._carry = (0.0, 0.0, 0.0)  # running sums of d_rot, dx, dy
        self._odo_first = True
        # dead-reckoning poses integrated but maybe still needed by /tf (from the last one
        # at or before the last row written)
        self._dr_t = np.zeros(0)
        self._dr_p = np.zeros((0, 3))
        # the dead reckoning's continuous heading and distance travelled at _dr_t (K, 2),
        # and their running sums (for slam/turn_check.py; the poses' headings are wrapped)
        self._dr_c = np.zeros((0, 2))
        self._dist = 0.0
        # per block of rows (k, 8): t, the estimate's heading less the dead reckoning's
        # (wrapped), the dead reckoning's continuous heading and distance, the estimate's
        # and the dead reckoning's positions; 64 bytes a row
        self._headings: list[np.ndarray] = []

    def __enter__(self) -> StreamingOutputs:
        def text(name: str):
            return open(self.tmp / name, "w", encoding="utf-8", newline="")

        self._files = []
        try:
            self._traj = text(TRAJECTORY)
            self._files.append(self._traj)
            self._odo = text(ODOMETRY)
            self._files.append(self._odo)
            self._cov = text(COVARIANCE)
            self._files.append(self._cov)
            self._upd = text(UPDATES)
            self._files.append(self._upd)
            self._mcap = LogWriter(
                self.tmp / ESTIMATES, latched=self.topics.latched(), ros_distro=self.ros_distro
            ).__enter__()
        except BaseException:
            self._close()
            raise
        self._mcap_open = True
        header = format_tum(np.zeros(0), np.zeros((0, 3)))  # the header line alone
        self._traj.write(header)
        self._odo.write(header)
        self._cov.write(COVARIANCE_HEADER)
        self._upd.write(UPDATES_HEADER)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if self._mcap_open:  # not finished: an error or Ctrl-C; no estimates.mcap
            self._mcap_open = False
            self._mcap.__exit__(exc_type or RuntimeError, exc, tb)
        self._close()

    def _close(self) -> None:
        for f in self._files:
            f.close()

    # -- RowSink ---------------------------------------------------------------------

    def row(self, t: float, pose: np.ndarray, cov: np.ndarray) -> None:
        self.rows += 1
        self._rows.append((t, pose, cov))
        self._messages.append((False, t, pose, cov))
        if len(self._rows) >= self.rows_block:
            self._flush_rows()

    def odometry_start(self, t: float) -> None:
        self._odo_t.append(t)

    def odometry(self, t: float, d_trans: float, d_rot: float) -> None:
        self._odo_t.append(t)
        self._odo_u.append((d_trans, d_rot))
        if len(self._odo_u) >= self.odometry_block:
            self._flush_odometry()

    def update(self, row: UpdateRow) -> None:
        if row.kind == "lamp" and row.accepted:
            self.lamp_nis.add(row.nis)
        self._upd.write(_update_line(row))

    def snapshot(self, t: float, lamps: np.ndarray, covs: np.ndarray) -> None:
        self._messages.append((True, t, lamps, covs))

    # -- blocks ----------------------------------------------------------------------

    def _flush_rows(self) -> None:
        """Write the buffered rows and messages (in blocks: building the messages in a
        batch costs half as much as one at a time between filter steps)."""
        tp = self.topics
        t = np.array([r[0] for r in self._rows], dtype=float)
        poses = np.array([r[1] for r in self._rows], dtype=float).reshape(-1, 3)
        cov = np.array([r[2] for r in self._rows], dtype=float).reshape(-1, 6)
        cdr = iter(encode_pose_with_covariance_block(t, poses, cov, self.frames.map))
        self._flush_odometry()  # every increment up to the rows' times (runner: rows lag)
        odo = dead_reckoning_at(t, self._dr_t, self._dr_p)
        cont = dead_reckoning_at(t, self._dr_t, self._dr_c)
        rel = wrap_angle(poses[:, 2] - odo[:, 2])
        self._headings.append(np.column_stack([t, rel, cont, poses[:, :2], odo[:, :2]]))
        tf = iter(tf_payloads(t, poses, odo, self.frames))
        if len(t):
            keep = max(int(np.searchsorted(self._dr_t, t[-1], "right")) - 1, 0)
            self._dr_t, self._dr_p = self._dr_t[keep:], self._dr_p[keep:]
            self._dr_c = self._dr_c[keep:]
        pose_tf = [tp.slam_pose, tp.tf], [M.POSE_COV_STAMPED, M.TF_MESSAGE]
        mcap = self._mcap
        for lamps, tm, a, b in self._messages:  # in the order they came
            if lamps:
                cdr_lamps = lamp_markers_cdr(tm, a, b)
                mcap.write_cdr(tp.slam_landmarks, M.MARKER_ARRAY, cdr_lamps, tm)
            else:  # the pose, then its /tf: write_cdr of each, the time's bookkeeping once
                mcap.write_cdr_at(*pose_tf, [next(cdr), next(tf)], tm)
        self._messages.clear()
        if not self._rows:
            return
        self._traj.write(_tum_lines(t, poses))
        self._cov.write(_fmt_rows(np.column_stack([t, cov])))
        self._rows.clear()

    def _flush_odometry(self) -> None:
        """``robot.integrate_from`` over the buffered increments, continuing the running
        sums."""
        if not self._odo_t:
            return
        u = np.asarray(self._odo_u, dtype=float).reshape(-1, 2)
        rot0 = self._carry[0]
        poses, self._carry = integrate_from(self.start_pose, u[:, 0], u[:, 1], self._carry)
        heading = self.start_pose[2] + np.cumsum(np.concatenate([[rot0], u[:, 1]]))
        dist = np.cumsum(np.concatenate([[self._dist], u[:, 0]]))
        self._dist = float(dist[-1])
        cont = np.column_stack([heading, dist])
        if not self._odo_first:
            poses = poses[1:]  # the previous block's last pose, already written
            cont = cont[1:]
        odo_t = np.asarray(self._odo_t, dtype=float)
        self._odo.write(_tum_lines(odo_t, poses))
        self._dr_t = np.concatenate([self._dr_t, odo_t])
        self._dr_p = np.concatenate([self._dr_p, poses])
        self._dr_c = np.concatenate([self._dr_c, cont])
        self._odo_first = False
        self._odo_t.clear()
        self._odo_u.clear()

    def headings(self) -> np.ndarray:
        """The rows written so far: their times, the estimate's heading and the dead
        reckoning's, both continuous, and the dead reckoning's distance travelled at those
        times (the odometry's turns against the filter's, slam/turn_check.py). The dead
        reckoning's heading is its start plus the sum of its turns; the estimate's is that
        plus their difference, unwrapped from row to row (the filter's correction between
        two rows is far below pi, however far the robot turned between them).

        Returns
        -------
        ndarray (n, 4)
            t (s), the estimate's heading and the dead reckoning's (rad), the dead
            reckoning's distance (m, signed).
        """
        if not self._headings:
            return np.zeros((0, 4))
        t, rel, heading, dist = np.concatenate(self._headings)[:, :4].T
        return np.column_stack([t, heading + np.unwrap(rel), heading, dist])

    def positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows written so far: their times, the estimate's positions and the dead
        reckoning's at those times (the odometry's distances against the filter's,
        slam/turn_check.py ``distance_ratio``).

        Returns
        -------
        t : ndarray (n,)
            Times (s).
        xy_est, xy_odo : ndarray (n, 2)
            The estimate's positions (map frame) and the dead reckoning's (odom frame), m.
        """
        if not self._headings:
            return np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2))
        rows = np.concatenate(self._headings)
        return rows[:, 0], rows[:, 4:6], rows[:, 6:8]

    def write_messages(self, messages) -> None:
        """Write ``messages`` (topic, type name, message or its CDR bytes, t) into
        estimates.mcap now: the map the fixes use, before the run's first pose (a reader
        of the file in its order, ``mcap cat``, sees it first), or the aids' messages at
        the end.

        Parameters
        ----------
        messages : iterable of (str, str, message or bytes, float)
            The messages.
        """
        for topic, typename, msg, t in messages:
            self._mcap.write(topic, typename, msg, t)

    def finish(self, res: SlamResult, extra=()) -> None:
        """Write what is left: the last blocks, landmarks.yaml and ``extra`` (topic, type
        name, message or its CDR bytes, t) messages of estimates.mcap (e.g. the aids'
        /slam/changes), and close estimates.mcap (renamed into place inside ``tmp``).

        Parameters
        ----------
        res : SlamResult
            The filter's result (landmarks).
        extra : iterable of (str, str, message or bytes, float)
            The aids' messages.
        """
        self._flush_rows()
        self._flush_odometry()
        write_landmarks(self.tmp / LANDMARKS, res.lamps)
        self.write_messages(extra)
        self._mcap_open = False
        self._mcap.__exit__(None, None, None)
        self._close()


def write_outputs(tmp: Path, out: StreamingOutputs, res: SlamResult, extra=()) -> None:
    """Complete the streamed files of docs/contracts.md sec. 2 (but summary.json and the fix
    files) in the staging directory ``tmp`` (:meth:`StreamingOutputs.finish`).

    Parameters
    ----------
    tmp : Path
        The staging directory.
    out : StreamingOutputs
        The sink the rows went to.
    res : SlamResult
        The filter's result.
    extra : iterable of (str, str, message or bytes, float)
        The aids' messages for estimates.mcap (rosbags messages or CDR bytes).
    """
    assert out.tmp == Path(tmp)
    out.finish(res, extra)


def write_summary(tmp: Path, summary: dict) -> None:
    """summary.json (indented, keys sorted, numpy numbers as floats).

    Parameters
    ----------
    tmp : Path
        The staging directory.
    summary : dict
        The JSON summary.
    """
    (tmp / SUMMARY).write_text(
        json.dumps(summary, indent=2, sort_keys=True, default=float) + "\n", encoding="utf-8"
    )
