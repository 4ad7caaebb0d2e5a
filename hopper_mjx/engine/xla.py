"""XLA:CPU compiler options for a jit of an engine's step, and its trace kept (`trace_once`)."""

import jax

# XLA:CPU's emitters, chosen per engine and floor (`Engine.compiler_options`; every jit of an engine step on CPU
# passes its engine's). The newer fusion emitters recompute the chained body transforms of mjx.kinematics inside
# each fused consumer; the classic ones keep that step ~35% cheaper (docs/performance.md), and compile it much
# faster. The chain on a heightfield, thousands of small kernels a step, is the other way round: its rough-ground
# step is ~20% cheaper with the fusion emitters (docs/performance.md, lever c12). The same equations either way;
# only float32 rounding differs, as kernels fuse differently.
CPU_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}
FUSION_EMITTERS = {"xla_cpu_use_fusion_emitters": True}
# The chain's step is per-instance scalars that vmap makes vectors of its chunk: 512-bit vectors, where the CPU has
# them, took 7-8 % off its step on the plane and on rough ground (docs/performance.md, lever c20); 128-bit added 21 %.
# LLVM keeps to the widths the host supports.
WIDE_VECTORS = {"xla_cpu_prefer_vector_width": 512}


def trace_once(engine) -> None:
    """Makes `engine.forward` and `.integrate` nested jits, so that their Python is traced once per engine
    (per argument shapes and batch axis): every later function that steps the engine (training's update,
    its evaluation, the core's step, a transform of one) replays the recorded step. The chain's step takes
    10-16 s to trace under vmap and a training run traced it three times. The compiled program is the same:
    XLA inlines the nested call."""
    engine.forward, engine.integrate = jax.jit(engine.forward), jax.jit(engine.integrate)
