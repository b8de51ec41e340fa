"""A fast reader of ROS 1 bags (format 2.0) for the two message types identification needs.

No ROS and no per-message Python: the file is memory-mapped, the chunk
records are found by walking the top-level records (a few per megabyte), and
the index records that follow every chunk give the record time and offset of
each message of each connection; the fields wanted (a TransformStamped's
stamp, translation and rotation; a Twist's linear.x and angular.z) are then
gathered from the chunks with numpy. Only chunks that hold a wanted
connection are decompressed (``none``, ``bz2``; ``lz4`` through ROS's roslz4
if it is importable). A bag without index records (not closed properly) is
read record by record instead (slower, same result).

``read(path, topics)`` -> ``{topic: (datatype, arrays)}``; every problem with the
file raises :class:`BagError` with a message that names it.
"""

import bz2
import mmap
import struct

import numpy as np

MAGIC = b"#ROSBAG V2.0\n"
OP_MSG, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
_U32 = struct.Struct("<I")
INDEX_ENTRY = np.dtype([("secs", "<u4"), ("nsecs", "<u4"), ("offset", "<u4")])


class BagError(ValueError):
    """The file is not a readable ROS 1 bag; the message says why."""


def _fields(buf, start, length):
    """Header fields (name -> bytes) of a record header at buf[start:start + length]."""
    out, pos, end = {}, start, start + length
    while pos < end:
        if pos + 4 > end:
            raise BagError("truncated record header")
        (n,) = _U32.unpack_from(buf, pos)
        pos += 4
        field = bytes(buf[pos:pos + n])
        if len(field) != n or b"=" not in field:
            raise BagError("malformed record header")
        name, _, value = field.partition(b"=")
        out[name.decode("ascii", "replace")] = value
        pos += n
    return out


def _records(buf, pos, end):
    """(header fields, record start, data start, data length) of the records in buf[pos:end]."""
    while pos < end:
        if pos + 4 > end:
            raise BagError("truncated record at byte %d" % pos)
        (hlen,) = _U32.unpack_from(buf, pos)
        hdr = _fields(buf, pos + 4, hlen)
        dpos = pos + 4 + hlen
        if dpos + 4 > end:
            raise BagError("truncated record at byte %d" % pos)
        (dlen,) = _U32.unpack_from(buf, dpos)
        if dpos + 4 + dlen > end:
            raise BagError("truncated record data at byte %d" % pos)
        yield hdr, pos, dpos + 4, dlen
        pos = dpos + 4 + dlen


def _op(hdr):
    op = hdr.get("op")
    if op is None or len(op) != 1:
        raise BagError("record without an op code")
    return op[0]


def _u32(value):
    return _U32.unpack(value[:4])[0]


def _decompress(buf, start, length, compression, size):
    raw = buf[start:start + length]
    if compression == b"none":
        return raw
    if compression == b"bz2":
        data = bz2.decompress(raw)
    elif compression == b"lz4":
        try:
            import roslz4
        except ImportError:
            raise BagError("lz4-compressed chunks need ROS's roslz4 module") from None
        data = roslz4.decompress(bytes(raw))
    else:
        raise BagError("unknown chunk compression %r" % compression.decode("ascii", "replace"))
    if len(data) != size:
        raise BagError("chunk decompressed to %d bytes, its header says %d" % (len(data), size))
    return data


class _Connection:
    def __init__(self, cid, topic, datatype):
        self.id, self.topic, self.datatype = cid, topic, datatype
        self.count = 0


def _connection(hdr, buf, dstart, dlen):
    cid = _u32(hdr["conn"])
    inner = _fields(buf, dstart, dlen)
    topic = (inner.get("topic") or hdr.get("topic", b"")).decode("utf-8", "replace")
    return _Connection(cid, topic, inner.get("type", b"").decode("ascii", "replace"))


def scan(buf):
    """Connections and chunks of a bag in ``buf``: ({id: _Connection}, [chunk]), each chunk a dict
    with its data position, compression, size and index: {connection id: (times [s], offsets)}."""
    if bytes(buf[:len(MAGIC)]) != MAGIC:
        raise BagError("not a ROS 1 bag (format 2.0): the file does not start with %r" % MAGIC.decode())
    conns, chunks = {}, []
    for hdr, _, dstart, dlen in _records(buf, len(MAGIC), len(buf)):
        op = _op(hdr)
        if op == OP_CHUNK:
            chunks.append({"start": dstart, "length": dlen, "compression": hdr.get("compression", b"none"),
                           "size": _u32(hdr["size"]), "index": {}})
        elif op == OP_INDEX:
            if not chunks:
                raise BagError("index record before any chunk")
            cid, count = _u32(hdr["conn"]), _u32(hdr["count"])
            if dlen != 12 * count:
                raise BagError("index record of %d entries holds %d bytes" % (count, dlen))
            entries = np.frombuffer(bytes(buf[dstart:dstart + dlen]), dtype=INDEX_ENTRY)
            chunks[-1]["index"][cid] = (entries["secs"] + 1e-9 * entries["nsecs"], entries["offset"].astype(np.int64))
        elif op == OP_CONNECTION:
            c = _connection(hdr, buf, dstart, dlen)
            conns.setdefault(c.id, c)
    indexed = all(ch["index"] for ch in chunks)
    if not indexed:
        _index_by_walking(buf, conns, chunks)
    for ch in chunks:
        for cid, (times, _) in ch["index"].items():
            if cid in conns:
                conns[cid].count += times.size
    return conns, chunks


def _index_by_walking(buf, conns, chunks):
    """Build the chunk indexes of a bag without index records by walking every chunk's records."""
    for ch in chunks:
        data = _decompress(buf, ch["start"], ch["length"], ch["compression"], ch["size"])
        index = {}
        for hdr, start, dstart, dlen in _records(data, 0, len(data)):
            op = _op(hdr)
            if op == OP_CONNECTION:
                c = _connection(hdr, data, dstart, dlen)
                conns.setdefault(c.id, c)
            elif op == OP_MSG:
                secs, nsecs = struct.unpack("<II", hdr["time"][:8])
                index.setdefault(_u32(hdr["conn"]), []).append((secs + 1e-9 * nsecs, start))
        ch["index"] = {cid: (np.array([e[0] for e in v]), np.array([e[1] for e in v], dtype=np.int64))
                       for cid, v in index.items()}
        ch["data"] = data


def _gather(data, starts, width):
    """(n, width) uint8 array of data[starts[i]:starts[i] + width] (vectorised)."""
    arr = np.frombuffer(data, dtype=np.uint8)
    idx = starts[:, None] + np.arange(width)[None, :]
    if idx.size and idx.max() >= arr.size:
        raise BagError("message data past the end of its chunk")
    return arr[idx]


def _u32_at(data, starts):
    return _gather(data, starts, 4).view("<u4").reshape(-1).astype(np.int64)


def _f64_at(data, starts, count):
    return _gather(data, starts, 8 * count).view("<f8").reshape(-1, count)


def _message_starts(data, offsets):
    """Data start of the message records at ``offsets`` of a chunk (after their headers)."""
    hlen = _u32_at(data, offsets)
    return offsets + 4 + hlen + 4


def _decode_transform(data, d):
    """TransformStamped at data starts d: columns stamp [s], x, y, z, qx, qy, qz, qw."""
    secs = _u32_at(data, d + 4)
    nsecs = _u32_at(data, d + 8)
    frame_len = _u32_at(data, d + 12)
    child_at = d + 16 + frame_len
    child_len = _u32_at(data, child_at)
    values = _f64_at(data, child_at + 4 + child_len, 7)
    return np.column_stack([secs + 1e-9 * nsecs, values])


def _decode_twist(data, d):
    """Twist at data starts d: columns linear x, y, z, angular x, y, z."""
    return _f64_at(data, d, 6)


DECODERS = {"geometry_msgs/TransformStamped": _decode_transform, "geometry_msgs/Twist": _decode_twist}


def read(path, topics):
    """Read the messages of ``topics`` (names) from the bag at ``path``.

    Returns ``(info, messages)``: ``info`` = {topic: (datatype, message count)} of every
    connection in the bag; ``messages`` = {topic: (record times [s], decoded rows)} for the wanted
    topics whose type has a decoder (DECODERS), in record-time order.
    """
    with open(path, "rb") as f:
        try:
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError:
            raise BagError("empty file") from None
    view = memoryview(buf)
    chunks = data = None
    try:
        conns, chunks = scan(view)
        info = {}
        for c in conns.values():
            dtype, count = info.get(c.topic, (c.datatype, 0))
            info[c.topic] = (dtype, count + c.count)
        wanted = {cid: c for cid, c in conns.items() if c.topic in topics and c.datatype in DECODERS}
        parts = {c.topic: [] for c in wanted.values()}
        for ch in chunks:
            ids = [cid for cid in ch["index"] if cid in wanted]
            if not ids:
                continue
            data = ch.get("data")
            if data is None:
                data = _decompress(view, ch["start"], ch["length"], ch["compression"], ch["size"])
            for cid in ids:
                times, offsets = ch["index"][cid]
                rows = DECODERS[wanted[cid].datatype](data, _message_starts(data, offsets))
                parts[wanted[cid].topic].append((times, rows))
            del data
        messages = {}
        for topic, items in parts.items():
            if not items:
                continue
            t = np.concatenate([a for a, _ in items])
            rows = np.concatenate([b for _, b in items])
            order = np.argsort(t, kind="stable")
            messages[topic] = (t[order], rows[order])
        return info, messages
    except (KeyError, struct.error) as e:
        raise BagError("malformed record (%s)" % e) from None
    finally:
        chunks = data = None
        try:                # views of the map may still be referenced (freed with them otherwise)
            view.release()
            buf.close()
        except BufferError:
            pass
