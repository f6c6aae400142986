"""A ROS 1 bag read chunk by chunk (:class:`sonarslam.datasets.ros1bag.Ros1Bag`, issue 30's
memory target) gives what ``rosbags``' own reader gives, message for message and in its order,
in the cases its merge must get right: chunks whose time spans overlap, messages written out of
time order, ties of receive time within a connection and across connections, two connections
of one topic, each compression; and a damaged index is an error, never another order."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from sonarslam.datasets.ros1bag import Ros1Bag, Ros1BagError
from sonarslam.datasets.rosbag import _typestore


def _write(path: Path, compression: str, seed: int) -> Path:
    """A bag of 600 small messages on three topics (four connections), written in an order
    that is not time order (so that chunks of 1 kB overlap in time), with repeated times."""
    from rosbags.rosbag1 import Writer

    store = _typestore()
    T = store.types
    rng = random.Random(seed)
    w = Writer(path)
    if compression != "none":
        w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = 1024
    with w:
        conns = [
            w.add_connection("/a", "std_msgs/msg/Float64", typestore=store),
            w.add_connection("/b", "std_msgs/msg/Float64", typestore=store),
            w.add_connection("/a", "std_msgs/msg/Float64", typestore=store, callerid="/other"),
            w.add_connection("/c", "std_msgs/msg/String", typestore=store),
        ]
        t = 1_700_000_000_000_000_000
        for i in range(600):
            t += rng.choice((0, 0, 1, 1_000_000, 50_000_000))  # ties at every second step
            stamp = t - rng.choice((0, 0, 0, 400_000_000))  # some written late
            k = rng.randrange(4)
            msg = (
                T["std_msgs/msg/String"](data="x" * rng.randrange(40))
                if k == 3
                else T["std_msgs/msg/Float64"](data=float(i))
            )
            w.write(conns[k], stamp, store.serialize_ros1(msg, conns[k].msgtype))
    return path


def _same(path: Path, selections: list[list[int]]) -> int:
    """Ros1Bag against rosbags' AnyReader: connections, topics, span and every message."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([path], default_typestore=_typestore()) as a, Ros1Bag(path) as b:
        key = lambda c: (c.id, c.topic, c.msgtype, c.digest, c.msgcount, c.ext)  # noqa: E731
        assert [key(c) for c in b.connections] == [key(c) for c in a.connections]
        assert {t: (i.msgtype, i.msgcount) for t, i in b.topics.items()} == {
            t: (i.msgtype, i.msgcount) for t, i in a.topics.items()
        }
        assert (b.start_time, b.end_time) == (a.start_time, a.end_time)
        for sel in selections:
            got: list[Any] = [
                (c.id, t, raw) for c, t, raw in b.messages([b.connections[i] for i in sel])
            ]
            want = [(c.id, t, raw) for c, t, raw in a.messages([a.connections[i] for i in sel])]
            assert got == want, sel
            n += len(got)
            for c, _, raw in list(b.messages([b.connections[sel[0]]]))[:3]:
                assert repr(b.deserialize(raw, c.msgtype)) == repr(a.deserialize(raw, c.msgtype))
    return n


@pytest.mark.parametrize("compression", ["none", "bz2", "lz4"])
def test_chunk_by_chunk_gives_rosbags_messages_in_rosbags_order(
    tmp_path: Path, compression: str
) -> None:
    path = _write(tmp_path / "mixed.bag", compression, seed=3)
    with Ros1Bag(path) as b:
        starts, ends = b._chunk_start.tolist(), b._chunk_end.tolist()
    assert len(starts) > 20  # many chunks, and some overlap in time: the merge is exercised
    assert any(s < max(ends[:k]) for k, s in enumerate(starts) if k)
    n = _same(path, [[0, 1, 2, 3], [3, 2, 1, 0], [2, 0], [1]])
    assert n >= 2 * 600 + 2  # both full selections, and the others not empty


def test_a_message_outside_its_chunks_indexed_span_is_an_error(tmp_path: Path) -> None:
    """A chunk info whose start time is later than a message of its chunk: the merge could
    not keep time order, so the bag is refused rather than read in another order."""
    path = _write(tmp_path / "ok.bag", "none", seed=5)
    data = bytearray(path.read_bytes())
    with Ros1Bag(path) as b:
        k = int(b._chunk_start.argmin())
        start = int(b._chunk_start[k])
    old = (start // 10**9).to_bytes(4, "little") + (start % 10**9).to_bytes(4, "little")
    later = start + 1
    new = (later // 10**9).to_bytes(4, "little") + (later % 10**9).to_bytes(4, "little")
    at = data.rfind(b"start_time=" + old)  # the chunk info record's, in the index at the end
    assert at > 0
    data[at + 11 : at + 19] = new
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    with Ros1Bag(bad) as b, pytest.raises(Ros1BagError, match="outside the chunk's span"):
        list(b.messages())
