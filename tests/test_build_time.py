"""The suite's report of program building (tests/build_time.py) counts overlapping compile events once."""

from build_time import covered


def test_nested_and_overlapping_spans_count_once():
    # A jit traced inside another's trace: its span lies within the outer one's.
    assert covered([(0.0, 10.0), (2.0, 3.0)]) == 10.0
    assert covered([(5.0, 6.0), (0.0, 2.0), (1.0, 3.0)]) == 4.0  # unsorted, overlapping, apart
    assert covered([]) == 0.0


def test_each_stage_of_a_build_is_filed_under_the_programs_name():
    """JAX's compile events carry the function's name: a fresh jit's trace, lowering and compile are filed under it
    (the trace as `f`, the compile as `jit(f)`: one name), with their seconds."""
    import build_time
    import jax
    import numpy as np

    def a_program_of_this_test(x):
        return x * 3 + 1

    build_time._built.clear()
    assert float(jax.jit(a_program_of_this_test)(np.float32(2))) == 7.0
    stages = {stage: s for name, stage, s in build_time._built if name == "a_program_of_this_test"}
    assert set(stages) == {"trace", "lower", "compile"} and all(s >= 0 for s in stages.values())
    assert {build_time.program(n) for n in ("rollout", "jit(rollout)", "jit_rollout", "pmap(rollout)")} == {"rollout"}
