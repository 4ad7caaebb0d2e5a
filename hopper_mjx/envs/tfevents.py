"""TensorBoard event files through tensorboardX: training curves the ecosystem reads.

tensorboardX encodes the events (its protocol buffers, TFRecord framing and CRC-32C); this module only
says what a training run writes: every metric of one progress report as one event at its env step.
It uses tensorboardX's synchronous events writer rather than `SummaryWriter`, whose background thread
writes on its own schedule: here each report is on disk when `scalars` returns, so a killed run keeps its curve.
"""

from __future__ import annotations

import time
from pathlib import Path

from tensorboardX.event_file_writer import EventsWriter
from tensorboardX.proto.event_pb2 import Event
from tensorboardX.proto.summary_pb2 import Summary
from tensorboardX.summary import scalar


class EventWriter:
    """Appends scalars to `folder/events.out.tfevents.<time>.<host>`, one file per writer."""

    def __init__(self, folder: str | Path):
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        self._writer = EventsWriter(str(folder / "events"))  # writes the file-version event first
        self._writer.flush()
        self.path = Path(self._writer._file_name)

    def scalars(self, step: int, values: dict[str, float], wall_time: float | None = None) -> None:
        summary = Summary(value=[v for tag, value in values.items() for v in scalar(tag, value).value])
        self._writer.write_event(Event(wall_time=time.time() if wall_time is None else wall_time, step=step,
                                       summary=summary))
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()
