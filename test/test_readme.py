"""README.md's generated parameter table matches the parameter definitions."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _sync_module():
    spec = importlib.util.spec_from_file_location("sync_readme", ROOT / "tools" / "sync_readme.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_parameter_table_in_sync():
    text = (ROOT / "README.md").read_text()
    assert _sync_module().synced(text) == text, (
        "README parameter table is stale: run `.venv/bin/python tools/sync_readme.py`"
    )


def test_readme_opens_with_the_two_commands():
    head = (ROOT / "README.md").read_text().splitlines()[:6]
    assert any(line.startswith("./dev.sh demo") for line in head)
    assert any(line.startswith("./dev.sh test") for line in head)
    assert "./dev.sh test" in (ROOT / ".ci" / "run").read_text()
