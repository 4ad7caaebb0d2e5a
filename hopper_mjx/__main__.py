"""python -m hopper_mjx: the package's commands, a line each. Each takes --help."""

from __future__ import annotations

import sys

from hopper_mjx import cli, registry
from hopper_mjx.shell import process


def listing() -> str:
    """The commands (`registry.COMMANDS`) as a user types them, each with what it is for."""
    typed = {name: f"python {name}" if name.endswith(".py") else f"python -m {name}" for name in registry.COMMANDS}
    width = max(map(len, typed.values()))
    return "\n".join(f"  {typed[name]:<{width}}  {what}" for name, what in registry.COMMANDS.items())


def main(argv=None) -> int:
    text = f"{__doc__}\n\n{listing()}"
    cli.parser("python -m hopper_mjx", text).parse_args(argv)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(process.run(main))
