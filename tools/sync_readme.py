"""Rewrite the generated blocks of README.md: the parameter table.

Run after changing any ParamSpec: ``.venv/bin/python tools/sync_readme.py``.
``test/test_readme.py`` fails while the README is out of date.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from clusterfilter_ros.config import all_param_specs
from clusterfilter_ros.core.params import markdown_table

README = Path(__file__).resolve().parents[1] / "README.md"
BEGIN, END = "<!-- params:begin -->", "<!-- params:end -->"


def params_block() -> str:
    return f"{BEGIN}\n{markdown_table(all_param_specs())}\n{END}"


def synced(text: str) -> str:
    pattern = re.compile(re.escape(BEGIN) + ".*?" + re.escape(END), re.S)
    if not pattern.search(text):
        raise SystemExit(f"{README}: markers {BEGIN} ... {END} not found")
    return pattern.sub(lambda _: params_block(), text)


def main() -> int:
    text = README.read_text()
    new = synced(text)
    if new != text:
        README.write_text(new)
        print(f"updated {README}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
