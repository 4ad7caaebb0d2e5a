"""The training behind `experiments/train.py`: its options (`options`), the learners (`learners`), one run
(`loop`), and the judging of a policy in the core (`evaluation`)."""
