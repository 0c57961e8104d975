"""Corrupt MCAP structure (issue 14, class 3): every structural field is bounds-checked.

Real faults are injected into a copy of a short simulated log (test_robust_logs'
``tiny``, 38 s written in 256 KiB chunks: 19 chunks, each with its Message Indexes,
and the summary; the sample log of data/ has 9 chunks and costs twice as much to run
and map): a bit flip in a chunk header's length fields, a Chunk Index offset off by
64 KiB, a Message Index whose length is not a multiple of 16, random byte flips in the
summary and index region. ``run`` and ``run --map`` (sonar rings read through the same
reader) must exit 0 with ``log_damage`` counting the damage, or 3 with one line, never 1.
Where the damage loses no message (a wrong index over intact data), the outputs must be
the undamaged run's.
"""

from __future__ import annotations

import json
import shutil
import struct
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import test_robust_logs
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_robust_logs import Tiny, cli  # the in-process CLI runner the robustness tests share

from fuzzyslam.errors import InputError
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.typestore import deserialize

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
tiny = test_robust_logs.tiny  # the session fixture: a short simulated log, its run and map
FOOTER_TAIL = 8 + 29  # footer record (opcode, length, 2 x u64, crc) + magic
OP_CHUNK_INDEX = 0x08


# -- the file's structure, parsed independently of fuzzyslam (MCAP spec) ---------------------


@dataclass
class ChunkAt:
    offset: int  # of the Chunk record
    length: int
    index_record: int  # offset of its Chunk Index record in the summary
    message_indexes: dict[int, int]  # channel id -> offset of its Message Index record


def summary_start(data: bytes) -> int:
    return struct.unpack_from("<Q", data, len(data) - FOOTER_TAIL + 9)[0]


def fix_summary_crc(data: bytearray) -> None:
    """Recompute the footer's summary CRC (a writer that wrote a wrong index)."""
    s, foot = summary_start(data), len(data) - FOOTER_TAIL
    crc = zlib.crc32(bytes(data[foot : foot + 25]), zlib.crc32(bytes(data[s:foot])))
    struct.pack_into("<I", data, foot + 25, crc)


def chunks_of(data: bytes) -> list[ChunkAt]:
    """Chunks in file order, from the Chunk Index records of the summary."""
    pos, end = summary_start(data), len(data) - FOOTER_TAIL
    out = []
    while pos < end:
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == OP_CHUNK_INDEX:
            _t0, _t1, off, clen, map_len = struct.unpack_from("<QQQQI", data, pos + 9)
            idx = {}
            for k in range(map_len // 10):
                cid, moff = struct.unpack_from("<HQ", data, pos + 9 + 36 + 10 * k)
                idx[cid] = moff
            out.append(ChunkAt(off, clen, pos, idx))
        pos += 9 + length
    return sorted(out, key=lambda c: c.offset)


def channel_id(path: Path, topic: str) -> int:
    from mcap.reader import SeekingReader

    with open(path, "rb") as f:
        summary = SeekingReader(f).get_summary()
    return next(cid for cid, ch in summary.channels.items() if ch.topic == topic)


# -- fixtures ------------------------------------------------------------------------------


@dataclass
class Base:
    dir: Path
    log: Path
    config: Path
    data: bytes
    chunks: list[ChunkAt]
    est: Path
    fgm: Path
    run: dict
    run_map: dict


@pytest.fixture(scope="module")
def base(tmp_path_factory, tiny: Tiny) -> Base:
    d = tmp_path_factory.mktemp("damage")
    log, cfg = d / "tiny.mcap", tiny.config
    shutil.copyfile(tiny.small_chunks, log)
    code, out, err = cli("run", log, "-o", d / "est", "--config", cfg)
    assert code == 0, err
    run = json.loads(out)
    code, _, err = cli(
        "map", log, "--trajectory", d / "est" / "trajectory.tum", "-o", d / "fgm",
        "--config", cfg, "--no-figures",
    )  # fmt: skip
    assert code == 0, err
    code, out, err = cli("run", log, "-o", d / "est_map", "--map", d / "fgm", "--config", cfg)
    assert code == 0, err
    data = log.read_bytes()
    chunks = chunks_of(data)
    assert len(chunks) >= 8
    return Base(d, log, cfg, data, chunks, d / "est", d / "fgm", run, json.loads(out))


def run_all(base: Base, data: bytes, td: Path) -> tuple[dict | None, ...]:
    """``run``, ``run --map`` and ``map`` (on the intact run's trajectory) on ``data``:
    their summaries (None: exit 3 with one line), outputs in ``td``."""
    log = td / "bad.mcap"
    log.write_bytes(data)
    out = []
    commands = {
        "est0": ["run", log, "-o", td / "est0"],
        "est2": ["run", log, "-o", td / "est2", "--map", base.fgm],
        "fgm": ["map", log, "--trajectory", base.est / "trajectory.tum", "-o", td / "fgm"],
    }
    for name, args in commands.items():
        extra = ["--config", base.config, *(["--no-figures"] if name == "fgm" else [])]
        code, stdout, stderr = cli(*args, *extra)
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        assert code in (0, 3), stderr  # never 1 (an internal error)
        if code == 3:
            assert len(lines) == 1 and str(log) in lines[0], stderr
            assert not (td / name).exists()
            out.append(None)
        else:
            out.append(json.loads(stdout))
    return out[0], out[1], out[2]


def same_map(a: Path, b: Path) -> None:
    with np.load(a / "fgm.npz") as x, np.load(b / "fgm.npz") as y:
        assert sorted(x.files) == sorted(y.files)
        for k in x.files:
            assert np.array_equal(x[k], y[k]), k


def same_outputs(a: Path, b: Path) -> None:
    for name in ("trajectory.tum", "landmarks.yaml", "updates.csv"):
        same = (a / name).read_bytes() == (b / name).read_bytes()  # no diff of megabytes
        assert same, name


# -- the faults of issue 14 ----------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("field", ["record", "compression", "records"])
@pytest.mark.parametrize("bit", [0, 5, 17, 43])
def test_bit_flip_in_a_chunk_header_length(base: Base, field: str, bit: int) -> None:
    """A flipped bit in a chunk's record length, compression-string length or records
    length: counted; the chunk is lost (or read whole by the record walk when only its
    records length is wrong, or whole through its Chunk Index when its record length is
    wrong: then only the Message Index records after it are lost, never a message),
    every other chunk is read; never exit 1."""
    c = base.chunks[len(base.chunks) // 2]
    indexes = [  # its Message Index records, right after the chunk record
        (off, off + 9 + struct.unpack_from("<Q", base.data, off + 1)[0])
        for off in c.message_indexes.values()
    ]
    assert min(a for a, _ in indexes) == c.offset + c.length
    index_bytes = max(b for _, b in indexes) - (c.offset + c.length)
    assert index_bytes < c.length // 2  # the two outcomes below cannot be confused
    clen = struct.unpack_from("<I", base.data, c.offset + 9 + 28)[0]
    at = {
        "record": c.offset + 1,
        "compression": c.offset + 9 + 28,
        "records": c.offset + 9 + 32 + clen,
    }[field]
    width = 4 if field == "compression" else 8
    data = bytearray(base.data)
    if bit >= 8 * width:
        bit %= 8 * width
    data[at + bit // 8] ^= 1 << (bit % 8)
    with tempfile.TemporaryDirectory() as td:
        run, run_map, fgm = run_all(base, bytes(data), Path(td))
        for s in (run, run_map, fgm):
            assert s is not None  # most of the log is intact
            dmg = s["log_damage"]
            assert dmg["damaged_records"] >= 1
            assert not dmg["truncated"]  # the summary is intact: read through it
        if run["log_damage"]["lost_bytes"] <= index_bytes:  # no message lost, if any index
            same_outputs(base.est, Path(td) / "est0")
        else:
            assert run["log_damage"]["lost_bytes"] >= c.length // 2
            assert 0 < run["counts"]["frames"] < base.run["counts"]["frames"]


@pytest.mark.slow
@pytest.mark.parametrize("crc", [True, False], ids=["crc-fixed", "crc-stale"])
def test_chunk_index_offset_off_by_64k(base: Base, crc: bool) -> None:
    """A Chunk Index whose chunk offset is 64 KiB off. With the summary CRC recomputed
    (a writer that wrote a wrong index), the index does not match the file: counted,
    and the record walk from the last good chunk reads every message, so the outputs
    are the undamaged run's. With a stale CRC the summary is not used at all."""
    c = base.chunks[len(base.chunks) // 2]
    data = bytearray(base.data)
    at = c.index_record + 9 + 16
    struct.pack_into("<Q", data, at, struct.unpack_from("<Q", data, at)[0] + 65536)
    if crc:
        fix_summary_crc(data)
    with tempfile.TemporaryDirectory() as td:
        run, run_map, fgm = run_all(base, bytes(data), Path(td))
        for s in (run, run_map, fgm):
            assert s is not None
            assert s["log_damage"]["truncated"] == (not crc)
            if crc:
                assert s["log_damage"]["damaged_records"] == 1
        same_outputs(base.est, Path(td) / "est0")
        same_outputs(base.dir / "est_map", Path(td) / "est2")
        same_map(base.fgm, Path(td) / "fgm")


@pytest.mark.slow
@pytest.mark.parametrize("extra", [8, 3, -7])
def test_message_index_length_not_a_multiple_of_16(base: Base, extra: int) -> None:
    """The /joint_states Message Index of one chunk with an entries length that is not a
    multiple of 16 (record length to match): counted, the chunk's records are scanned
    instead, nothing is lost (the outputs are the undamaged run's)."""
    cid = channel_id(base.log, "/joint_states")
    c = base.chunks[len(base.chunks) // 2]
    at = c.message_indexes[cid]
    data = bytearray(base.data)
    length, _ch, n = struct.unpack_from("<QHI", data, at + 1)
    struct.pack_into("<QHI", data, at + 1, length + extra, cid, n + extra)
    with tempfile.TemporaryDirectory() as td:
        run, run_map, fgm = run_all(base, bytes(data), Path(td))
        for s in (run, run_map):
            assert s is not None and s["log_damage"]["damaged_records"] == 1
            assert not s["log_damage"]["truncated"]
        assert fgm["log_damage"]["damaged_records"] == 0  # map reads no joint states
        same_outputs(base.est, Path(td) / "est0")
        same_outputs(base.dir / "est_map", Path(td) / "est2")
        same_map(base.fgm, Path(td) / "fgm")


def index_region(base: Base) -> list[tuple[int, int]]:
    """(start, end) byte ranges of the Message Index records and the summary section."""
    spans = []
    for c in base.chunks:
        for off in c.message_indexes.values():
            spans.append((off, off + 9 + struct.unpack_from("<Q", base.data, off + 1)[0]))
    spans.append((summary_start(base.data), len(base.data)))
    return spans


def chunk_heads(base: Base) -> list[tuple[int, int]]:
    """The first 64 bytes of each chunk: its record header, times, sizes, compression."""
    return [(c.offset, c.offset + 64) for c in base.chunks]


@st.composite
def flips(draw, base: Base, where: str = "index"):
    spans = {
        "index": index_region,
        "chunk-heads": chunk_heads,
        "anywhere": lambda b: [(8, len(b.data))],
    }[where](base)
    out = []
    for _ in range(draw(st.integers(1, 4))):
        a, b = draw(st.sampled_from(spans))
        out.append((draw(st.integers(a, b - 1)), draw(st.integers(1, 255))))
    return out, draw(st.booleans())


def damaged(base: Base, flip: list[tuple[int, int]], crc: bool) -> bytes:
    data = bytearray(base.data)
    for at, x in flip:
        data[at] ^= x
    if crc:
        fix_summary_crc(data)
    return bytes(data)


START = 15.0  # seconds into the 38 s log: the reader's start seeks past its first 7 chunks


@pytest.mark.slow
@pytest.mark.parametrize(
    "where",
    [
        "index",
        pytest.param("chunk-heads", marks=pytest.mark.slow),
        pytest.param("anywhere", marks=pytest.mark.slow),
    ],
)
def test_random_flips_never_break_the_reader(base: Base, where: str) -> None:
    """The reader on random byte flips in the indexes and summary, in chunk headers or
    anywhere (with the summary CRC stale or recomputed): only InputError, and the
    messages are a subset of the intact log's, none twice, each topic in log-time order."""
    topics = ["/joint_states", "/ceiling_camera/image_raw", "/sonar/s00", "/sonar/s09"]
    reader = LogReader(base.log)
    intact = [(m.topic, m.t_ns) for m in reader.messages(topics)]
    full = set(intact)
    assert len(full) == len(intact)
    later = [(m.topic, m.t_ns) for m in reader.messages(topics[2:], start=reader.start + START)]
    assert 0 < len(later) < len(intact) / 2  # the intact log read from START: past chunks

    @settings(max_examples=30, deadline=None)
    @given(flips(base, where))
    def check(case) -> None:
        with tempfile.TemporaryDirectory() as td:
            log = Path(td) / "bad.mcap"
            log.write_bytes(damaged(base, *case))
            try:
                r = LogReader(log)
            except InputError:
                return
            a = [(m.topic, m.t_ns) for m in r.messages(topics)]
            b = [(m.topic, m.t_ns) for m in r.messages(topics[2:], start=r.start + START)]
        for got in (a, b):
            assert set(got) <= full and len(set(got)) == len(got)
            for tp in topics:
                ts = [t for topic, t in got if topic == tp]
                assert ts == sorted(ts)
        assert all(t >= round((r.start + START) * 1e9) for _, t in b)
        assert all(v >= 0 for v in r.damage().values())

    check()


@pytest.mark.slow
@pytest.mark.parametrize("where", ["index", "chunk-heads"])
def test_random_flips_never_exit_1(base: Base, where: str) -> None:
    """``run``, ``run --map`` and ``map`` on random byte flips in the indexes and summary
    or in chunk headers: exit 0 or 3 with one line; never a silent loss (outputs that
    differ from the intact log's come with the damage counted)."""

    def counted(s: dict) -> bool:
        d = s["log_damage"]
        return d["truncated"] or d["damaged_records"] > 0 or d["undecodable"] > 0

    @settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    @given(flips(base, where))
    def check(case) -> None:
        with tempfile.TemporaryDirectory() as td:
            run, _run_map, fgm = run_all(base, damaged(base, *case), Path(td))
            traj = "trajectory.tum"
            if (
                run is not None
                and (Path(td) / "est0" / traj).read_bytes() != (base.est / traj).read_bytes()
            ):
                assert counted(run)
            if fgm is not None:
                with np.load(Path(td) / "fgm" / "fgm.npz") as a, np.load(base.fgm / "fgm.npz") as b:
                    if any(not np.array_equal(a[k], b[k]) for k in b.files):
                        assert counted(fgm)

    check()


@pytest.mark.parametrize(
    "variant", ["no-chunking", "no-message-index", "no-chunk-index", "lz4", "no-compression"]
)
def test_files_written_without_some_indexes_are_read_whole(tmp_path: Path, variant: str) -> None:
    """Valid MCAP written by the mcap library without chunks, Message Indexes or Chunk
    Indexes, or with other compressions: every message read, in log-time order, no
    damage (the index is an optimisation, never a requirement)."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, IndexType, Writer

    src: list = []
    with open(SAMPLE, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=True):
            src.append((schema, channel, m))
            if len(src) == 3000:
                break
    kw: dict = {"chunk_size": 64 * 1024}
    if variant == "no-chunking":
        kw["use_chunking"] = False
    elif variant == "no-message-index":
        kw["index_types"] = IndexType.ALL & ~IndexType.MESSAGE
    elif variant == "no-chunk-index":
        kw["index_types"] = IndexType.ALL & ~IndexType.CHUNK
    else:
        kw["compression"] = CompressionType.LZ4 if variant == "lz4" else CompressionType.NONE
    log = tmp_path / "variant.mcap"
    with open(log, "wb") as f:
        w = Writer(f, **kw)
        w.start(profile="ros2", library="test")
        schemas: dict = {}
        channels: dict = {}
        for schema, channel, m in src:
            if schema.name not in schemas:
                schemas[schema.name] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.topic not in channels:
                channels[channel.topic] = w.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.name]
                )
            w.add_message(channels[channel.topic], m.log_time, m.data, m.publish_time, m.sequence)
        w.finish()
    r = LogReader(log)
    got = [(m.topic, m.t_ns) for m in r.messages()]
    assert got == [(c.topic, m.log_time) for _s, c, m in src]
    t0 = src[1500][2].log_time
    sonar = [m.msg.range for m in r.messages(["/sonar/s03"], start=t0 / 1e9)]
    ref = [
        deserialize(m.data, s.name).range
        for s, c, m in src
        if c.topic == "/sonar/s03" and m.log_time >= t0
    ]
    assert len(ref) > 10 and np.array_equal(sonar, ref, equal_nan=True)
    d = r.damage()
    assert d["damaged_records"] == d["lost_bytes"] == d["undecodable"] == 0


def test_chunks_overlapping_in_time_are_merged_in_log_time_order(tmp_path: Path) -> None:
    """A file whose chunks overlap in time (messages written out of time order, as a
    recorder flushing two buffers may): the messages still come in log-time order, as
    the mcap library's log-time-ordered reader gives them."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from fuzzyslam.streams import messages as M
    from fuzzyslam.streams.typestore import msgdef, serialize

    log = tmp_path / "overlap.mcap"
    with open(log, "wb") as f:
        w = Writer(f, chunk_size=2048)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(M.RANGE, "ros2msg", msgdef(M.RANGE).encode())
        ca = w.register_channel("/sonar/s00", "cdr", sid)
        cb = w.register_channel("/sonar/s01", "cdr", sid)
        for cid, times in ((ca, range(0, 400, 2)), (cb, range(101, 501, 2))):
            for seq, k in enumerate(times):
                data = serialize(M.range_msg(k / 100, "s", k / 100, 0.4, 0.1, 5.0), M.RANGE)
                w.add_message(cid, k * 10_000_000, data, k * 10_000_000, seq)
        w.finish()
    with open(log, "rb") as f:
        ref = [
            (c.topic, m.log_time) for _s, c, m in make_reader(f).iter_messages(log_time_order=True)
        ]
    assert [m.t_ns for m in ref and []] == [] and ref != sorted(ref, key=lambda x: x[0])
    r = LogReader(log)
    got = [(m.topic, m.t_ns) for m in r.messages()]
    assert got == ref and [t for _, t in got] == sorted(t for _, t in got)
    assert next(m.msg.range for m in r.messages(["/sonar/s01"], start=2.0)) == np.float32(2.01)
    d = r.damage()
    assert d["damaged_records"] == d["lost_bytes"] == 0
