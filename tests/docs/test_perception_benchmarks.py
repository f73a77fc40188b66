"""``benchmarks/perception_culled.py`` and ``perception_stages.py`` load their scenes through
``benchmarks/settled_scenes.py``: both scripts start (their imports resolve) and offer its options."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("script, own", [("perception_culled.py", []), ("perception_stages.py", ["--rounds"])])
def test_scripts_share_the_scene_options(script, own):
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--help"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    for opt in ["--actions", "--scenes", "--seed", *own]:
        assert opt in out.stdout, (script, opt)
