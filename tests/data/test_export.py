"""``relaff export``: a dataset as Parquet + feature schema + dataset card, values bit for bit.

Built with the synthetic numpy rollout and feature functions of tests/helpers/standins.py (not physics).
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
import pyarrow.parquet as pq  # noqa: E402

from relaff_jax import data as D  # noqa: E402
from relaff_jax.cli import data as cli_data  # noqa: E402
from relaff_jax.data import export as X  # noqa: E402
from relaff_jax.errors import UserError  # noqa: E402

import helpers.standins as t  # noqa: E402

PERCEPTION = {"perception": {"rhf": {"bins": 50, "ranges": [[-0.5, 0.5]] * 3 + [[0.0, 0.75]] + [[0.0, 3.1]] * 2}}}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    p = tmp_path_factory.mktemp("exp") / "lift"
    t.gen(p)
    D.add_features(p, t.feature_fn(), batch=16, progress=False, config_dict=PERCEPTION)
    return p


def test_export_folder_round_trip(dataset, tmp_path):
    out = tmp_path / "export"
    paths = D.export_dataset(dataset, out)
    assert paths == {"data": out / "data.parquet", "schema": out / "features_schema.json", "card": out / "README.md"}
    d = D.load_dataset(dataset)
    table = pq.read_table(paths["data"])
    assert table.num_rows == 40
    assert table.column_names[:7] == ["action", "rollout", "label", "relation", "cog_distance", "toy", "other"]
    assert set(table.column_names) == set(d)
    assert pa.types.is_fixed_size_list(table.schema.field("pca").type)
    assert table.schema.field("rhf").type.list_size == 300
    for k, v in d.items():
        got = X.from_arrow_column(table, k)
        if k == "action":
            assert set(got.tolist()) == {v}
            continue
        assert got.dtype == v.dtype, k
        np.testing.assert_array_equal(got, v, err_msg=k)
    assert json.loads(table.schema.metadata[b"relaff_jax"])["action"] == "lift"

    schema = json.loads(paths["schema"].read_text())
    pca, rhf = schema["properties"]["pca"], schema["properties"]["rhf"]
    assert pca["x-shape"] == [18]
    assert pca["x-dtype"] == "float32"
    assert pca["x-feature"] is True
    assert pca["x-names"][:3] == ["toy_x", "toy_y", "toy_z"]
    assert pca["x-names"][9] == "other_x"
    assert rhf["x-names"][0] == "dx_bin00"
    assert rhf["x-names"][-1] == "angle_na_d_bin49"
    assert [h["range"] for h in rhf["x-histograms"]] == PERCEPTION["perception"]["rhf"]["ranges"]
    assert schema["properties"]["qpos"]["x-shape"] == [2, 7]
    assert schema["properties"]["qpos"]["x-feature"] is False
    card = paths["card"].read_text()
    assert "action `lift`" in card
    assert "seed 3" in card
    assert "orbax-checkpoint" in card
    assert "| `rhf` |" in card


def test_export_file_path_and_pandas(dataset, tmp_path):
    out = tmp_path / "sets" / "lift.parquet"
    paths = D.export_dataset(dataset, out)
    assert paths["schema"] == tmp_path / "sets" / "lift.schema.json"
    assert paths["card"] == tmp_path / "sets" / "lift.md"
    assert all(p.is_file() for p in paths.values())
    with pytest.raises(UserError, match="already exist"):
        D.export_dataset(dataset, out)
    D.export_dataset(dataset, out, overwrite=True)
    pd = pytest.importorskip("pandas")
    df = pd.read_parquet(out)
    d = D.load_dataset(dataset)
    np.testing.assert_array_equal(np.stack(df["pca"]), d["pca"])
    np.testing.assert_array_equal(df["label"].to_numpy(), d["label"])
    assert df["relation"].tolist() == d["relation"].tolist()


def test_polars_reads_the_feature_columns_as_fixed_size_arrays(dataset, tmp_path):
    pl = pytest.importorskip("polars")
    paths = D.export_dataset(dataset, tmp_path / "out")
    df = pl.read_parquet(paths["data"])
    d = D.load_dataset(dataset)
    assert df.schema["pca"] == pl.Array(pl.Float32, 18)
    assert df.schema["rhf"] == pl.Array(pl.Float32, 300)
    np.testing.assert_array_equal(df["pca"].to_numpy(), d["pca"])
    np.testing.assert_array_equal(df["rhf"].to_numpy(), d["rhf"])


def test_export_bad_out_and_input(dataset, tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    for out, match in [(f / "x.parquet", "not a folder"), (f, "not a folder"), (tmp_path / "x.csv", "parquet"),
                       (tmp_path, "")]:
        if out == tmp_path:
            (tmp_path / "data.parquet").mkdir()
            match = "is a folder"
        with pytest.raises(UserError, match=match):
            D.export_dataset(dataset, out)
    with pytest.raises(UserError, match="unknown export format"):
        D.export_dataset(dataset, tmp_path / "o", format="csv")
    with pytest.raises(UserError, match="not a relaff dataset"):
        D.export_dataset(tmp_path, tmp_path / "o2")
    assert not (tmp_path / "o").exists()
    assert not (tmp_path / "o2").exists()


def test_export_cli(dataset, tmp_path, capsys):
    parser = argparse.ArgumentParser()
    cli_data.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["export", str(dataset), "--format", "parquet", "--out", str(tmp_path / "c")])
    assert args.func(args) == 0
    assert "data.parquet" in capsys.readouterr().out
    assert pq.read_table(tmp_path / "c" / "data.parquet").num_rows == 40
