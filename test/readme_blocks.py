"""The README's runnable examples, for the tests that execute them.

An example is the first fenced block (``python``, ``text`` ...) after an HTML comment
``<!-- readme-example: NAME -->`` in README.md, so that the README shows exactly the code
the tests run.
"""

from __future__ import annotations

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_example(name: str) -> str:
    """The source of README example ``name`` (ValueError when there is none)."""
    text = README.read_text(encoding="utf-8")
    found = re.search(r"<!-- readme-example: %s -->\s*```\w*\n(.*?)\n```" % re.escape(name), text, re.S)
    if found is None:
        raise ValueError(f"README.md has no example {name!r}")
    return found.group(1)


def run_readme_example(name: str) -> dict:
    """Execute README example ``name`` in a fresh namespace; returns that namespace."""
    namespace: dict = {"__name__": f"readme_{name}"}
    exec(compile(readme_example(name), f"README.md:{name}", "exec"), namespace)  # noqa: S102
    return namespace
