"""Per-instance robots: the `--randomize` spec, checked whole in pure Python (`spec`), and its seeded draw
into MuJoCo model fields with the constants MuJoCo C derives from them (`draw`)."""
