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
