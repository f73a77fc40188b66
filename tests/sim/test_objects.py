"""The 29-object library and the `relaff objects` command."""
import json

import numpy as np
import pytest

from relaff_jax import cli
from relaff_jax.sim import objects as lib


def test_paper_counts():
    assert len(lib.OBJECTS) == 29
    assert {g: len(lib.members(g)) for g in lib.GROUPS} == {"toy": 5, "base": 15, "obstacle": 5, "rake": 5}
    assert set(lib.members("toy")) & set(lib.members("base")) == {"cup"}


def test_bases_include_real_containers_and_flat_supports():
    kinds = [lib.get(n).kind for n in lib.members("base")]
    assert kinds.count("container") >= 4
    assert kinds.count("flat") >= 4
    for n in lib.members("base"):
        spec = lib.get(n)
        if spec.kind == "container":
            ix, iy, rim = spec.inner
            # walls a toy can sit inside: the block toy (5 cm) fits every container
            assert 2 * ix > 0.05, n
            assert 2 * iy > 0.05, n
            assert rim > 0.05, n


def test_rakes_have_handle_and_head():
    for n in lib.members("rake"):
        parts = dict(lib.get(n).parts)
        assert set(parts) == {"base", "wall_xp"}, n
        handle, head = parts["base"], parts["wall_xp"]
        assert handle.size[0] > 0.3, n
        assert head.size[1] > handle.size[1] * 3, n


def test_colours_unique_and_sizes_realistic():
    colours = np.array([s.colour for s in lib.OBJECTS.values()])
    dist = np.linalg.norm(colours[:, None] - colours[None], axis=-1) + np.eye(29)
    assert dist.min() > 0.05
    for s in lib.OBJECTS.values():
        assert 0.01 < s.mass < 2.0
        assert all(0.005 <= e <= 0.7 for e in s.extent), s.name


def test_pairs():
    pairs = lib.pairs()
    assert len(pairs) == 124
    assert len(set(pairs)) == 124
    assert ("cup", "cup", "toy+base") not in pairs
    assert {p[2] for p in pairs} == set(lib.PAIRINGS)


def test_unknown_name_lists_valid_ones():
    with pytest.raises(KeyError, match="unknown object 'spoon'.*ball.*l_hook"):
        lib.get("spoon")
    with pytest.raises(KeyError, match="unknown group"):
        lib.members("tools")


def test_cli_objects_json(capsys):
    assert cli.main(["objects", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert len(rows) == 29
    assert {r["name"] for r in rows} == set(lib.OBJECT_NAMES)
    assert sum(r["container"] for r in rows) == sum(
        lib.get(n).kind == "container" for n in lib.OBJECT_NAMES)
    assert cli.main(["objects"]) == 0
    assert "29 objects: 5 toys, 15 bases, 5 obstacles, 5 rakes" in capsys.readouterr().out


def test_cli_offers_every_stage_command(capsys):
    # the README's commands and `relaff reproduce`: each stage module registers its own
    with pytest.raises(SystemExit) as e:
        cli.main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for command in ("objects", "scenes", "generate", "info", "features", "show", "experiment", "report",
                    "reproduce"):
        assert f"    {command} " in text or f"    {command}\n" in text, command
