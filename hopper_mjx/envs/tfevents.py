"""TensorBoard event files, written without TensorFlow: training curves the ecosystem reads.

An event file is a sequence of records: the data's length (uint64, little-endian), the masked
CRC-32C of those 8 bytes, the data, and the masked CRC-32C of the data. Each record's data is
an `Event` protocol buffer; a scalar is `Event{wall_time: 1 double, step: 2 int64, summary: 5
Summary{value: 1 Value{tag: 1 string, simple_value: 2 float}}}`, and the first event holds
`file_version: 3 string = "brain.Event:2"`. Those few fields are encoded here by hand.
"""

from __future__ import annotations

import socket
import struct
import time
from pathlib import Path

FILE_VERSION = "brain.Event:2"
_CRC32C_TABLE = []
for _byte in range(256):  # the Castagnoli polynomial, reflected
    _crc = _byte
    for _ in range(8):
        _crc = (_crc >> 1) ^ (0x82F63B78 if _crc & 1 else 0)
    _CRC32C_TABLE.append(_crc)


def crc32c(data: bytes) -> int:
    crc = 0xFFFFFFFF
    for b in data:
        crc = _CRC32C_TABLE[(crc ^ b) & 0xFF] ^ (crc >> 8)
    return crc ^ 0xFFFFFFFF


def masked_crc(data: bytes) -> int:
    """TFRecord's masking, so that a CRC stored in the data does not checksum to itself."""
    crc = crc32c(data)
    return ((((crc >> 15) | (crc << 17)) & 0xFFFFFFFF) + 0xA282EAD8) & 0xFFFFFFFF


def _varint(value: int) -> bytes:
    out = bytearray()
    value &= (1 << 64) - 1  # int64 as two's complement, as protobuf encodes it
    while True:
        low, value = value & 0x7F, value >> 7
        out.append(low | (0x80 if value else 0))
        if not value:
            return bytes(out)


def _field(number: int, wire: int, payload: bytes) -> bytes:
    return _varint(number << 3 | wire) + payload


def _length_delimited(number: int, payload: bytes) -> bytes:
    return _field(number, 2, _varint(len(payload)) + payload)


def event(wall_time: float, step: int, *, scalars: dict[str, float] | None = None,
          file_version: str | None = None) -> bytes:
    """One `Event`, encoded."""
    data = _field(1, 1, struct.pack("<d", wall_time)) + _field(2, 0, _varint(step))
    if file_version is not None:
        data += _length_delimited(3, file_version.encode())
    if scalars:
        values = b"".join(_length_delimited(1, _length_delimited(1, tag.encode()) + _field(2, 5, struct.pack("<f", v)))
                          for tag, v in scalars.items())
        data += _length_delimited(5, values)
    return data


def record(data: bytes) -> bytes:
    header = struct.pack("<Q", len(data))
    return header + struct.pack("<I", masked_crc(header)) + data + struct.pack("<I", masked_crc(data))


class EventWriter:
    """Appends scalars to `folder/events.out.tfevents.<time>.<host>`, one file per writer."""

    def __init__(self, folder: str | Path):
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        now = time.time()
        self.path = folder / f"events.out.tfevents.{int(now)}.{socket.gethostname()}"
        with open(self.path, "ab") as f:
            f.write(record(event(now, 0, file_version=FILE_VERSION)))

    def scalars(self, step: int, values: dict[str, float], wall_time: float | None = None) -> None:
        with open(self.path, "ab") as f:  # whole records, flushed at each call: a killed run keeps its curve
            f.write(record(event(time.time() if wall_time is None else wall_time, step, scalars=values)))
