"""A ROS 1 bag (format 2.0) read chunk by chunk, without an index of every message.

``rosbags.rosbag1.Reader.open`` reads the index data records of every chunk into one
``IndexData`` a message (about 160 bytes each: 47 MB for an hour of a Ping360 rig's 292,000
messages) before it gives the first message. :class:`Ros1Bag` keeps what the bag's index section
holds once per connection and per chunk instead: the connection records (topic, type, the
message definition) and, of each chunk info record, the chunk's position, its time span and
which connections it holds. Its :meth:`Ros1Bag.messages` decompresses one chunk at a time and
gives the messages of the connections asked in the order ``rosbags`` gives them
(``Reader.messages``): by receive time; at the same time by the connection's place in the list
asked, then the chunk's place in the index, then the message's place in its chunk. Chunks
whose time spans overlap are merged through a heap that holds the messages of those chunks
only, so the memory held is a chunk's (1 MiB as ``rosbags`` and ``rosbag record`` write them),
whatever the bag's length.

The format (http://wiki.ros.org/Bags/Format/2.0): a line ``#ROSBAG V2.0``, a bag header record
(``index_pos``, ``conn_count``, ``chunk_count``), chunk records (``compression`` none, bz2 or
lz4; data: message data and connection records) each followed by its index data records, then
at ``index_pos`` the connection records and the chunk info records (``chunk_pos``,
``start_time``, ``end_time``, per connection its message count). A record is a header (field
``name=value`` pairs, ``op`` its kind) and its data, each behind a little-endian uint32 length.
The record headers are parsed with ``rosbags``' own ``Header``; the messages are decoded with a
typestore of the bag's own definitions (checked against their MD5 sums), as ``rosbags``'
``AnyReader`` builds it.
"""

from __future__ import annotations

import heapq
import io
from collections.abc import Collection, Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

__all__ = ["Ros1Bag", "Ros1BagError"]

#: Record kinds (the header's ``op``).
OP_MSG_DATA, OP_BAG_HEADER, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 0x02, 0x03, 0x05, 0x06, 0x07
#: A chunk info record's ``start_time`` without messages (``rosbags``' own placeholder).
NO_START = 2**63 - 1


class Ros1BagError(ValueError):
    """A ROS 1 bag that cannot be read: the file is not one, or is damaged."""


class Ros1Bag:
    """An open ROS 1 bag: its connections and topics, and its messages chunk by chunk.

    The attributes ``connections``, ``topics``, ``start_time`` and ``end_time`` and the methods
    ``messages`` and ``deserialize`` are those of ``rosbags.highlevel.AnyReader`` over one
    ``.bag`` file (times in ns; ``end_time`` one past the last message).

    Parameters
    ----------
    path : Path
        The ``.bag`` file.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.bio: BinaryIO | None = None
        self.connections: list[Any] = []
        self.typestore: Any = None
        self._rank: dict[int, int] = {}  # connection id -> its place in ``connections``
        # per chunk (the chunk info records' order): position, start (ns), end (ns, one past
        # the last message), and a bit per connection (by rank) it holds messages of
        self._chunk_pos = np.zeros(0, dtype=np.int64)
        self._chunk_start = np.zeros(0, dtype=np.int64)
        self._chunk_end = np.zeros(0, dtype=np.int64)
        self._chunk_conns: list[int] = []

    # -- opening ---------------------------------------------------------------------------------

    def open(self) -> None:
        """Read the bag header, the connection records and the chunk info records."""
        from rosbags.rosbag1.reader import Header, ReaderError  # lazy: only bags load rosbags

        try:
            self.bio = self.path.open("rb")
        except OSError as exc:
            raise Ros1BagError(f"cannot open: {exc.strerror or exc}") from None
        try:
            self._open(self.bio, Header)
        except ReaderError as exc:
            self.close()
            raise Ros1BagError(" ".join(str(a) for a in exc.args)) from None
        except BaseException:
            self.close()
            raise

    def _open(self, bio: BinaryIO, header_type: Any) -> None:
        from rosbags.interfaces import (  # lazy: only bags load rosbags
            Connection,
            ConnectionExtRosbag1,
            MessageDefinition,
            MessageDefinitionFormat,
        )
        from rosbags.rosbag1.reader import normalize  # lazy: only bags load rosbags
        from rosbags.typesys.msg import normalize_msgtype  # lazy: only bags load rosbags

        magic = bio.readline()
        if not magic:
            raise Ros1BagError("the file is empty")
        if magic != b"#ROSBAG V2.0\n":
            raise Ros1BagError(f"not a ROS 1 bag of format 2.0 (it begins {magic[:20]!r})")
        header = header_type.read(bio, OP_BAG_HEADER)
        index_pos = header.get_uint64("index_pos")
        conn_count = header.get_uint32("conn_count")
        chunk_count = header.get_uint32("chunk_count")
        if header.get("encryptor"):
            raise Ros1BagError(f"bag encryption {header.get_string('encryptor')!r} is not read")
        if index_pos == 0:
            raise Ros1BagError("the bag is not indexed (rosbag reindex it)")
        if chunk_count == 0:
            return
        bio.seek(index_pos)
        raw_conns = []
        for _ in range(conn_count):
            head = header_type.read(bio, OP_CONNECTION)
            data = header_type.read(bio)
            callerid = data.get_string("callerid") if "callerid" in data else None
            latching = data.get_string("latching") if "latching" in data else ""
            raw_conns.append(
                (
                    head.get_uint32("conn"),
                    normalize(head.get_string("topic")),
                    normalize_msgtype(data.get_string("type")),
                    MessageDefinition(
                        MessageDefinitionFormat.MSG, data.get_string("message_definition")
                    ),
                    data.get_string("md5sum"),
                    ConnectionExtRosbag1(callerid, int(latching) if latching else None),
                )
            )
        self._rank = {c[0]: i for i, c in enumerate(raw_conns)}
        counts = dict.fromkeys(self._rank, 0)
        pos, start, end = [], [], []
        for _ in range(chunk_count):
            head = header_type.read(bio, OP_CHUNK_INFO)
            if head.get_uint32("ver") != 1:
                raise Ros1BagError(f"chunk info version {head.get_uint32('ver')} is not read")
            n = head.get_uint32("count")
            pos.append(head.get_uint64("chunk_pos"))
            start.append(head.get_time("start_time") if n else NO_START)
            end.append(head.get_time("end_time") + 1 if n else 0)
            size = _uint32(bio)
            if size != 8 * n:
                raise Ros1BagError(f"a chunk info record of {size} bytes for {n} connections")
            pairs = np.frombuffer(_exactly(bio, size), dtype="<u4").reshape(n, 2)
            bits = 0
            for conn, k in pairs.tolist():
                if conn not in self._rank:
                    raise Ros1BagError(f"a chunk info names connection {conn}, which has no record")
                counts[conn] += k
                bits |= 1 << self._rank[conn]
            self._chunk_conns.append(bits)
        self._chunk_pos = np.array(pos, dtype=np.int64)
        self._chunk_start = np.array(start, dtype=np.int64)
        self._chunk_end = np.array(end, dtype=np.int64)
        self.connections = [
            Connection(cid, topic, ty, msgdef, md5, counts[cid], ext, self)
            for cid, topic, ty, msgdef, md5, ext in raw_conns
        ]
        self.typestore = _bag_typestore(self.connections)

    def close(self) -> None:
        if self.bio is not None:
            self.bio.close()
            self.bio = None

    def __enter__(self) -> Ros1Bag:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- what the bag holds ----------------------------------------------------------------------

    @property
    def topics(self) -> dict[str, Any]:
        """Topic -> ``rosbags.interfaces.TopicInfo`` (type, definition, count, connections)."""
        from rosbags.interfaces import (  # lazy: only bags load rosbags
            MessageDefinition,
            MessageDefinitionFormat,
            TopicInfo,
        )

        out: dict[str, Any] = {}
        for topic in sorted({c.topic for c in self.connections}):
            conns = [c for c in self.connections if c.topic == topic]
            types = {c.msgtype for c in conns}
            defs = {c.msgdef for c in conns}
            out[topic] = TopicInfo(
                types.pop() if len(types) == 1 else None,
                defs.pop()
                if len(defs) == 1
                else MessageDefinition(MessageDefinitionFormat.NONE, ""),
                sum(c.msgcount for c in conns),
                conns,
            )
        return out

    @property
    def start_time(self) -> int:
        return int(self._chunk_start.min()) if self._chunk_start.size else NO_START

    @property
    def end_time(self) -> int:
        return int(self._chunk_end.max()) if self._chunk_end.size else 0

    def deserialize(self, raw: bytes | memoryview, msgtype: str) -> Any:
        """A message of ``msgtype`` from its ROS 1 serialization."""
        return self.typestore.deserialize_ros1(raw, msgtype)

    # -- the messages ----------------------------------------------------------------------------

    def messages(self, connections: Collection[Any] = ()) -> Iterator[tuple[Any, int, memoryview]]:
        """``(connection, receive time ns, serialized message: a view of its chunk)`` of ``connections`` (all when
        empty) in ``rosbags``' order (module docstring), one chunk in memory at a time (more
        only where chunks' time spans overlap)."""
        if self.bio is None:
            raise Ros1BagError("the bag is not open")
        conns = list(connections) or list(self.connections)
        wanted = {c.id: (rank, c) for rank, c in enumerate(conns)}
        bits = 0
        for c in conns:
            bits |= 1 << self._rank[c.id]
        chunks = [
            k
            for k in np.lexsort((np.arange(self._chunk_start.size), self._chunk_start)).tolist()
            if self._chunk_conns[k] & bits
        ]
        heap: list[tuple[int, int, int, int, Any, memoryview]] = []
        for k in chunks:
            start = int(self._chunk_start[k])
            while heap and heap[0][0] < start:
                entry = heapq.heappop(heap)
                yield entry[4], entry[0], entry[5]
            for entry in self._chunk_messages(k, wanted):
                heapq.heappush(heap, entry)
        while heap:
            entry = heapq.heappop(heap)
            yield entry[4], entry[0], entry[5]

    def _chunk_messages(
        self, k: int, wanted: dict[int, tuple[int, Any]]
    ) -> list[tuple[int, int, int, int, Any, memoryview]]:
        """The messages of chunk ``k`` (the index's order) of the connections ``wanted`` (id
        -> (rank, connection)): ``(time, rank, k, offset, connection, data)``."""
        from rosbags.rosbag1.reader import (  # lazy: only bags load rosbags
            Header,
            RecordType,
            decompressors,
        )

        assert self.bio is not None
        pos = int(self._chunk_pos[k])
        self.bio.seek(pos)
        head = Header.read(self.bio, RecordType.CHUNK)
        compression = head.get_string("compression")
        if compression not in decompressors:
            raise Ros1BagError(f"chunk at byte {pos}: compression {compression!r} is not read")
        size = _uint32(self.bio)
        data = decompressors[compression](_exactly(self.bio, size))
        if len(data) != head.get_uint32("size"):
            raise Ros1BagError(
                f"chunk at byte {pos}: {len(data)} bytes, its header says {head.get_uint32('size')}"
            )
        lo, hi = int(self._chunk_start[k]), int(self._chunk_end[k])
        chunk = io.BytesIO(data)
        view = memoryview(data)  # the messages are views of the chunk, not copies
        out: list[tuple[int, int, int, int, Any, memoryview]] = []
        while chunk.tell() < len(data):
            offset = chunk.tell()
            record = Header.read(chunk)
            op = record.get_uint8("op")
            length = _uint32(chunk)
            if op == OP_CONNECTION:
                chunk.seek(length, io.SEEK_CUR)
                continue
            if op != OP_MSG_DATA:
                raise Ros1BagError(f"chunk at byte {pos}: a record of kind {op} among messages")
            conn = record.get_uint32("conn")
            time = record.get_time("time")
            if not lo <= time < hi:
                raise Ros1BagError(
                    f"chunk at byte {pos}: a message at {time} ns outside the chunk's span"
                    f" [{lo}, {hi}) in the index"
                )
            begin = chunk.tell()
            if begin + length > len(data):
                raise Ros1BagError(f"chunk at byte {pos}: a message cut short")
            if conn in wanted:
                rank, c = wanted[conn]
                out.append((time, rank, k, offset, c, view[begin : begin + length]))
            chunk.seek(length, io.SEEK_CUR)
        return out


def _exactly(bio: BinaryIO, size: int) -> bytes:
    data = bio.read(size)
    if len(data) != size:
        raise Ros1BagError(f"cut short: {len(data)} of {size} bytes")
    return data


def _uint32(bio: BinaryIO) -> int:
    return int.from_bytes(_exactly(bio, 4), "little")


def _bag_typestore(connections: list[Any]) -> Any:
    """The types of the bag's own message definitions, each checked against its MD5 sum (as
    ``rosbags.highlevel.AnyReader`` builds them for ROS 1 bags)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # lazy: rosbags

    types: dict[str, Any] = {}
    digests: dict[str, str] = {}
    for c in connections:
        types.update(get_types_from_msg(c.msgdef.data, c.msgtype))
        if c.digest:
            digests[c.msgtype] = c.digest
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    for msgtype, digest in digests.items():
        have = store.generate_msgdef(msgtype)[1]
        if have != digest:
            raise Ros1BagError(f"message type {msgtype!r}: MD5 {have} != the bag's {digest}")
    return store
