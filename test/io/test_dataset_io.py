"""Input kind detection (clusterfilter_ros.io.dataset): paths the OS refuses to inspect."""

from __future__ import annotations

from pathlib import Path

import pytest

from clusterfilter_ros.errors import InputError
from clusterfilter_ros.io.dataset import detect_input_kind, is_bag


def test_unreadable_bag_folder_is_an_input_error(tmp_path: Path, deny_inside) -> None:
    bag = tmp_path / "bag"
    bag.mkdir()
    deny_inside("is_file", bag)
    culprit = r"bag/metadata\.yaml: cannot access \(Permission denied\)"
    with pytest.raises(InputError, match=culprit):
        is_bag(bag)
    with pytest.raises(InputError, match=culprit):
        detect_input_kind(bag)


def test_input_in_an_unsearchable_folder_is_an_input_error(tmp_path: Path, monkeypatch) -> None:
    real_exists = Path.exists

    def exists(self: Path) -> bool:
        if self.name == "inside":
            raise PermissionError(13, "Permission denied", str(self))
        return real_exists(self)

    monkeypatch.setattr(Path, "exists", exists)
    with pytest.raises(InputError, match=r"inside: cannot access \(Permission denied\)"):
        detect_input_kind(tmp_path / "inside")
