"""hopper_mjx: batched MJX simulation of the seed monoped under per-instance gravity."""
