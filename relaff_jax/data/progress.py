"""Progress bars for the dataset writers: a tqdm bar on stderr, or a silent stand-in.

Takes ``progress`` (bool), a total, a description and a unit; gives an object with
``update``, ``set_postfix``, ``set_description``, ``close`` and the count ``n``.
"""
from __future__ import annotations

from typing import Any


class NoBar:
    n = 0

    def update(self, k: int) -> None:
        self.n += k

    def set_postfix(self, **kw: Any) -> None:
        pass

    def set_description(self, desc: str) -> None:
        pass

    def close(self) -> None:
        pass


def progress_bar(progress: bool, total: int, desc: str, unit: str = "pos"):
    if not progress:
        return NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit=unit, dynamic_ncols=True)
