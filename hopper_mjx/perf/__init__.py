"""Performance: the core against native MuJoCo (bench), and where the step's time goes (profile)."""
