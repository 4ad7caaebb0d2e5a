"""What a run measured: hop events and per-hop metrics from recorded signals (`hops`), and each task's bar on
those metrics with the ranking of checkpoints (`thresholds`)."""
