"""Shared helpers of the I/O tests."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest


@pytest.fixture
def deny_inside(monkeypatch: pytest.MonkeyPatch) -> Callable[[str, Path], None]:
    """``deny_inside("is_dir", folder)``: that ``Path`` method raises PermissionError for
    every path directly inside ``folder``, as the OS does for a user without the right
    to look (chmod does not stop root, and CI runs as root)."""

    def deny(method: str, folder: Path) -> None:
        real = getattr(Path, method)

        def refused(self: Path, *args: object, **kwargs: object) -> object:
            if self.parent == folder:
                raise PermissionError(13, "Permission denied", str(self))
            return real(self, *args, **kwargs)

        monkeypatch.setattr(Path, method, refused)

    return deny
