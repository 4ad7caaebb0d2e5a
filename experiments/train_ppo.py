"""Kept for old commands: `train_ppo.py ARGS` is `train.py --task hop --algo ppo ARGS`."""

import runpy
import sys
from pathlib import Path

if __name__ == "__main__":
    train = runpy.run_path(str(Path(__file__).with_name("train.py")))
    sys.exit(train["main"](["--task", "hop", "--algo", "ppo", *sys.argv[1:]]))
