"""The suite's report of program building (tests/build_time.py) counts overlapping compile events once."""

from build_time import covered


def test_nested_and_overlapping_spans_count_once():
    # A jit traced inside another's trace: its span lies within the outer one's.
    assert covered([(0.0, 10.0), (2.0, 3.0)]) == 10.0
    assert covered([(5.0, 6.0), (0.0, 2.0), (1.0, 3.0)]) == 4.0  # unsorted, overlapping, apart
    assert covered([]) == 0.0
