"""A minimal OpenEXR writer: one part, scan lines, 32-bit float channels, ZIP compression.

Blender's Python API can only write images through its render pipeline or as RGBA
images, but the exporter must write files with chosen channel names (the reflection
G-buffer, the height map, the environment map). This writes them with numpy and zlib
alone, so it runs in Blender and in pip's bpy module alike.

The layout follows the OpenEXR file format document ("OpenEXR File Layout"): magic and
version, a header of attributes, an offset table with one entry per chunk, then chunks of
16 scan lines each, ZIP-compressed (bytes split into even and odd halves, delta-encoded,
deflated). Channel names are written sorted, as the format requires, and row 0 of each
array is the first (top) scan line of the file.
"""
import struct
import zlib

import numpy as np

_MAGIC = 20000630
_VERSION = 2
_LONG_NAMES = 0x400
_FLOAT = 2
_ZIP_COMPRESSION = 3
_LINES_PER_CHUNK = 16


def _attribute(name, kind, payload):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def _zip_chunk(raw):
    """ZIP_COMPRESSION's predictor: interleave bytes, then delta-encode, then deflate."""
    data = np.frombuffer(raw, dtype=np.uint8)
    interleaved = np.concatenate([data[0::2], data[1::2]])
    delta = interleaved.astype(np.int16)
    delta[1:] = (interleaved[1:].astype(np.int16) - interleaved[:-1].astype(np.int16) + 128 + 256) & 0xFF
    return zlib.compress(delta.astype(np.uint8).tobytes(), 6)


def write_exr(path, channels):
    """Writes `channels`, a dict of full channel name -> 2-D array (rows x columns, row 0
    the top scan line), as one single-part float EXR. All arrays must have one shape."""
    names = sorted(channels)
    if not names:
        raise ValueError(f"{path}: no channels to write")
    arrays = [np.ascontiguousarray(channels[n], dtype="<f4") for n in names]
    height, width = arrays[0].shape
    if any(a.shape != (height, width) for a in arrays):
        raise ValueError(f"{path}: channels differ in size")

    chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", _FLOAT, 0, 1, 1) for n in names) + b"\0"
    window = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = b"".join([
        _attribute("channels", "chlist", chlist),
        _attribute("compression", "compression", bytes([_ZIP_COMPRESSION])),
        _attribute("dataWindow", "box2i", window),
        _attribute("displayWindow", "box2i", window),
        _attribute("lineOrder", "lineOrder", bytes([0])),
        _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]) + b"\0"
    flags = _LONG_NAMES if any(len(n) > 31 for n in names) else 0

    chunks = []
    for y0 in range(0, height, _LINES_PER_CHUNK):
        y1 = min(y0 + _LINES_PER_CHUNK, height)
        # Within a chunk: for each scan line, each channel's whole line in turn.
        raw = np.stack([a[y0:y1] for a in arrays], axis=1).tobytes()
        packed = _zip_chunk(raw)
        if len(packed) >= len(raw):
            packed = raw  # the format stores a chunk uncompressed when that is smaller
        chunks.append(struct.pack("<ii", y0, len(packed)) + packed)

    start = 8 + len(header) + 8 * len(chunks)
    offsets, position = [], start
    for c in chunks:
        offsets.append(position)
        position += len(c)
    with open(path, "wb") as f:
        f.write(struct.pack("<ii", _MAGIC, _VERSION | flags))
        f.write(header)
        f.write(struct.pack(f"<{len(offsets)}Q", *offsets))
        for c in chunks:
            f.write(c)


_NO_COMPRESSION, _ZIPS_COMPRESSION = 0, 2
_SAMPLE_TYPES = {0: np.dtype("<u4"), 1: np.dtype("<f2"), 2: np.dtype("<f4")}


def _read_header(data, at):
    """One header's attributes (name -> (type, payload)) from `at`; returns them and the
    offset after the header's terminating null byte."""
    attributes = {}
    while data[at] != 0:
        name_end = data.index(b"\0", at)
        kind_end = data.index(b"\0", name_end + 1)
        size, = struct.unpack_from("<i", data, kind_end + 1)
        start = kind_end + 5
        attributes[data[at:name_end].decode()] = (data[name_end + 1:kind_end].decode(), data[start:start + size])
        at = start + size
    return attributes, at + 1


def _channel_list(payload):
    channels, at = [], 0
    while payload[at] != 0:
        end = payload.index(b"\0", at)
        pixel_type, = struct.unpack_from("<i", payload, end + 1)
        channels.append((payload[at:end].decode(), pixel_type))
        at = end + 17
    return channels


def _unzip_chunk(packed, size):
    """The inverse of `_zip_chunk`: inflate, undo the delta, de-interleave."""
    delta = np.frombuffer(zlib.decompress(packed), dtype=np.uint8)[:size].copy()
    # The first byte is as stored; each next one is the previous plus its delta - 128,
    # modulo 256 (uint8 arithmetic wraps).
    delta[1:] -= np.uint8(128)
    interleaved = np.cumsum(delta, dtype=np.uint8)
    half = (size + 1) // 2
    out = np.empty(size, dtype=np.uint8)
    out[0::2], out[1::2] = interleaved[:half], interleaved[half:]
    return out.tobytes()


def _headers(path):
    """The file's bytes, whether it is multi-part, each part's header attributes, and the
    offset after the headers."""
    with open(path, "rb") as f:
        data = f.read()
    magic, flags = struct.unpack_from("<ii", data, 0)
    if magic != _MAGIC:
        raise ValueError(f"{path}: not an OpenEXR file")
    multipart, at, headers = bool(flags & 0x1000), 8, []
    while True:
        attributes, at = _read_header(data, at)
        headers.append(attributes)
        if not multipart or data[at] == 0:
            break
    return data, multipart, headers, at + (1 if multipart else 0)


def _full_names(attributes, multipart):
    """A part's channels as (full name, pixel type): prefixed with the part's name in a
    multi-part file unless they already are."""
    prefix = attributes["name"][1].rstrip(b"\0").decode() + "." if multipart else ""
    return [(n if n.startswith(prefix) else prefix + n, t) for n, t in _channel_list(attributes["channels"][1])]


def channel_names(path):
    """The full channel names of a scan-line EXR, as `read_exr_channels` names them."""
    _, multipart, headers, _ = _headers(path)
    return [name for attributes in headers for name, _ in _full_names(attributes, multipart)]


def read_exr_channels(path, wanted):
    """The channels `wanted` (full dotted names, as the G-buffer reader names them: a
    multi-part file's channels prefixed with their part's name unless they already are)
    of a scan-line EXR with no, ZIPS or ZIP compression, as 2-D float32 arrays (row 0 the
    top scan line); a channel not in the file is an error naming it."""
    data, multipart, headers, at = _headers(path)
    parts = []
    for attributes in headers:
        x0, y0, x1, y1 = struct.unpack("<iiii", attributes["dataWindow"][1])
        compression = attributes["compression"][1][0]
        if compression not in (_NO_COMPRESSION, _ZIPS_COMPRESSION, _ZIP_COMPRESSION) or \
                attributes.get("type", ("", b"scanlineimage\0"))[1].rstrip(b"\0") != b"scanlineimage":
            raise ValueError(f"{path}: only scan-line files with no, ZIPS or ZIP compression are read")
        width, height = x1 - x0 + 1, y1 - y0 + 1
        lines = _LINES_PER_CHUNK if compression == _ZIP_COMPRESSION else 1
        chunks = (height + lines - 1) // lines
        offsets = struct.unpack_from(f"<{chunks}Q", data, at)
        at += 8 * chunks
        channels = _full_names(attributes, multipart)
        parts.append((width, height, y0, lines, compression, offsets, channels))
    out = {}
    for k, (width, height, y0, lines, compression, offsets, channels) in enumerate(parts):
        taken = [name for name, _ in channels if name in wanted]
        if not taken:
            continue
        values = {name: np.empty((height, width), dtype=np.float32) for name in taken}
        for offset in offsets:
            head = 4 if multipart else 0
            y, size = struct.unpack_from("<ii", data, offset + head)
            packed = data[offset + head + 8:offset + head + 8 + size]
            rows = min(lines, y0 + height - y)
            raw_size = rows * width * sum(_SAMPLE_TYPES[t].itemsize for _, t in channels)
            raw = packed if compression == _NO_COMPRESSION or size == raw_size else _unzip_chunk(packed, raw_size)
            if len({t for _, t in channels}) == 1:
                # One sample type: the chunk is rows x channels x width of it.
                block = np.frombuffer(raw, dtype=_SAMPLE_TYPES[channels[0][1]], count=rows * len(channels) * width)
                block = block.reshape(rows, len(channels), width)
                for c, (name, _) in enumerate(channels):
                    if name in values:
                        values[name][y - y0:y - y0 + rows] = block[:, c]
                continue
            at = 0
            for row in range(rows):
                for name, pixel_type in channels:
                    dtype = _SAMPLE_TYPES[pixel_type]
                    line = np.frombuffer(raw, dtype=dtype, count=width, offset=at)
                    at += width * dtype.itemsize
                    if name in values:
                        values[name][y - y0 + row] = line.astype(np.float32)
        out.update(values)
    missing = [name for name in wanted if name not in out]
    if missing:
        raise ValueError(f"{path}: no channel {missing[0]}")
    return out
