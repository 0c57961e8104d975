"""Messages written a batch of one time at a time (LogWriter.write_cdr_at, the simulator's
sonar rings and robot steps) make the same file as written one by one."""

from __future__ import annotations

import numpy as np
import pytest

from fuzzyslam.streams.writer import LogWriter


def _write(path, batches, batched: bool, lean: bool) -> bytes:
    with LogWriter(path, chunk_size=4096) as w:
        w._writer.lean = lean
        for topics, types, datas, t in batches:
            if batched:
                w.write_cdr_at(topics, types, datas, t)
            else:
                for args in zip(topics, types, datas, strict=True):
                    w.write_cdr(*args, t)
        counts = dict(w.counts)
    return path.read_bytes(), counts


@pytest.mark.parametrize("lean", [True, False])
def test_batches_of_one_time_write_the_same_file(tmp_path, lean):
    rng = np.random.default_rng(9)
    ring = [f"/sonar/s{k:02d}" for k in range(16)]
    batches, t = [], 0.0
    for step in range(400):
        t += float(rng.uniform(0.0, 0.05))
        if step % 3 == 0:  # a ring; a topic first seen in the middle of the log at step 150
            topics = ring if step < 150 else [*ring, "/sonar/late"]
            types = ["sensor_msgs/msg/Range"] * len(topics)
        else:  # one time, two types, a topic repeated
            topics, types = ["/odom", "/truth", "/odom"], ["nav_msgs/msg/Odometry"] * 3
        datas = [rng.bytes(int(rng.integers(0, 300))) for _ in topics]
        batches.append((topics, types, datas, t))
    one, counts_one = _write(tmp_path / "one.mcap", batches, False, lean)
    many, counts_many = _write(tmp_path / "many.mcap", batches, True, lean)
    assert one == many
    assert counts_one == counts_many
    assert counts_one["/odom"] == 2 * sum(1 for b in batches if b[0][0] == "/odom")
    assert len(one) > 10 * 4096  # several chunks
