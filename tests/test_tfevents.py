"""TensorBoard event files written by hand: decoded back field by field, CRCs checked."""

import struct

import pytest

from hopper_mjx.envs import tfevents


def test_crc32c_matches_the_standard_check_value():
    assert tfevents.crc32c(b"123456789") == 0xE3069283  # CRC-32C (Castagnoli) of the standard check string


def _varint(data: bytes, i: int) -> tuple[int, int]:
    shift = value = 0
    while True:
        b = data[i]
        value |= (b & 0x7F) << shift
        i, shift = i + 1, shift + 7
        if not b & 0x80:
            return value, i


def _fields(data: bytes) -> list[tuple[int, object]]:
    """A protobuf message's (field number, value) pairs: varints, doubles, floats and bytes."""
    out, i = [], 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value, i = struct.unpack("<d", data[i:i + 8])[0], i + 8
        elif wire == 5:
            value, i = struct.unpack("<f", data[i:i + 4])[0], i + 4
        else:
            size, i = _varint(data, i)
            value, i = data[i:i + size], i + size
        out.append((number, value))
    return out


def _records(raw: bytes) -> list[bytes]:
    out, i = [], 0
    while i < len(raw):
        header = raw[i:i + 8]
        (size,) = struct.unpack("<Q", header)
        assert struct.unpack("<I", raw[i + 8:i + 12])[0] == tfevents.masked_crc(header)
        data = raw[i + 12:i + 12 + size]
        assert struct.unpack("<I", raw[i + 12 + size:i + 16 + size])[0] == tfevents.masked_crc(data)
        out.append(data)
        i += 16 + size
    assert i == len(raw)
    return out


def test_a_written_curve_reads_back_exactly(tmp_path):
    writer = tfevents.EventWriter(tmp_path / "tb")
    writer.scalars(1_000_000, {"eval/episode_reward": 623.5, "training/sps": 31000.0}, wall_time=12.5)
    writer.scalars(2_000_000, {"eval/episode_reward": -100.25}, wall_time=25.0)
    first, *scalars = _records(writer.path.read_bytes())
    assert dict(_fields(first))[3] == b"brain.Event:2"
    decoded = []
    for data in scalars:
        f = dict(_fields(data))
        values = [dict(_fields(v)) for n, v in _fields(f[5]) if n == 1]
        decoded.append((f[1], f[2], {v[1].decode(): v[2] for v in values}))
    assert decoded == [(12.5, 1_000_000, {"eval/episode_reward": 623.5, "training/sps": 31000.0}),
                       (25.0, 2_000_000, {"eval/episode_reward": -100.25})]


def test_a_negative_step_is_encoded_as_protobuf_int64():
    f = dict(_fields(tfevents.event(0.0, -1)))
    assert f[2] == 2**64 - 1  # ten-byte two's complement varint
    with pytest.raises(KeyError):
        f[5]
