"""TensorBoard event files (tensorboardX's encoding) read back by TensorBoard's own reader."""

import pytest

from hopper_mjx.envs import tfevents


def read_scalars(folder) -> dict[str, list[tuple[float, int, float]]]:
    """{tag: [(wall time, step, value)]} of every event file in `folder`, as TensorBoard loads them."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    board = EventAccumulator(str(folder), size_guidance={"scalars": 0})  # 0: keep every point
    board.Reload()
    return {tag: [(e.wall_time, e.step, e.value) for e in board.Scalars(tag)] for tag in board.Tags()["scalars"]}


def test_a_written_curve_reads_back_exactly(tmp_path):
    writer = tfevents.EventWriter(tmp_path / "tb")
    writer.scalars(1_000_000, {"eval/episode_reward": 623.5, "training/sps": 31000.0}, wall_time=12.5)
    # On disk when the call returns (a killed run keeps its curve): read before the writer is closed.
    assert read_scalars(tmp_path / "tb") == {"eval/episode_reward": [(12.5, 1_000_000, 623.5)],
                                             "training/sps": [(12.5, 1_000_000, 31000.0)]}
    writer.scalars(2_000_000, {"eval/episode_reward": -100.25}, wall_time=25.0)
    writer.close()
    assert [p.name for p in (tmp_path / "tb").iterdir()] == [writer.path.name]
    assert writer.path.name.startswith("events.out.tfevents.")
    assert read_scalars(tmp_path / "tb") == {
        "eval/episode_reward": [(12.5, 1_000_000, 623.5), (25.0, 2_000_000, -100.25)],
        "training/sps": [(12.5, 1_000_000, 31000.0)]}


def test_values_are_stored_as_float32(tmp_path):
    """TensorBoard's scalars are 32-bit: a value keeps float32's precision, not more."""
    writer = tfevents.EventWriter(tmp_path)
    writer.scalars(-1, {"x": 0.1})
    ((_, step, value),) = read_scalars(tmp_path)["x"]
    assert step == -1 and value == pytest.approx(0.1, rel=1e-7) and value != 0.1
