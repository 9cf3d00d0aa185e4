"""Dependencies point one way: core <- sim, io <- ros <- cli. Checked on the source."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "clusterfilter_ros"

#: layer -> packages it must not import (anywhere in the module, lazily or not)
FORBIDDEN = {
    "core": (
        "clusterfilter_ros.io",
        "clusterfilter_ros.ros",
        "clusterfilter_ros.cli",
        "clusterfilter_ros.sim",
        "rclpy",
        "rosbags",
        "matplotlib",
        "sensor_msgs",
    ),
    "sim": ("clusterfilter_ros.io", "clusterfilter_ros.ros", "clusterfilter_ros.cli", "rclpy"),
    "io": ("clusterfilter_ros.ros", "clusterfilter_ros.cli", "clusterfilter_ros.sim"),
    "ros": ("clusterfilter_ros.cli",),
}


def _imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, module, at module level) for every import in ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    top = {id(n) for n in tree.body}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, id(node) in top) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module, id(node) in top))
    return out


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_layer_does_not_import_upwards(layer):
    bad = []
    for path in sorted((PACKAGE / layer).rglob("*.py")):
        for line, module, _ in _imports(path):
            if any(module == f or module.startswith(f + ".") for f in FORBIDDEN[layer]):
                bad.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {module}")
    assert not bad, "\n".join(bad)


def test_io_imports_rclpy_only_lazily():
    bad = [
        f"{p.relative_to(PACKAGE.parent)}:{line}"
        for p in sorted((PACKAGE / "io").rglob("*.py"))
        for line, module, top in _imports(p)
        if top and module.split(".")[0] in ("rclpy", "sensor_msgs", "std_msgs", "geometry_msgs")
    ]
    assert not bad, f"io must work without ROS; module-level ROS imports at {bad}"
