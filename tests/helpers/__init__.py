"""What several test files share: paths, stand-in rollouts and features, hand-built scenes,
and the session fixtures of ``helpers.fixtures`` (loaded as a pytest plugin by
tests/conftest.py). Importable as ``helpers`` because pytest puts tests/ on ``sys.path``
(tests/conftest.py sits there, in a folder without ``__init__.py``); subprocess scripts insert
``TESTS`` themselves."""
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
ROOT = TESTS.parent
OSD = TESTS / "data" / "osd"  # three Object Segmentation Database scenes (README.md there)
