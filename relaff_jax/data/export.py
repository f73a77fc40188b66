"""Export a finished dataset for other tools: one Parquet file, a feature schema, a dataset card.

Takes a dataset directory and ``out`` (a ``.parquet`` file path, or a folder); gives the
selected samples as one Parquet table (pyarrow), ``features_schema.json`` (every column's
dtype, shape and meaning; the element names of the PCA and RHF vectors, RHF bin ranges from
the features sidecar) and ``README.md`` (a dataset card: columns, how the data was made,
package versions). With a file path ``data.parquet`` the schema and card go beside it as
``data.schema.json`` and ``data.md``; with a folder they are ``data.parquet``,
``features_schema.json`` and ``README.md`` inside it. Every file is written atomically.

Column layout: one row per selected sample; scalar fields are plain columns (strings as
``string``, numbers and bools with their stored dtype) and vector fields are fixed-size list
columns (``pca`` = ``fixed_size_list<float>[18]``, ``rhf`` = ``[300]``, ``qpos_settled`` =
``[14]``, a 2-D field a list of lists). One column per vector rather than 318 ``pca_*``/
``rhf_*`` columns because that is the shape every reader keeps: Polars loads it as an
``Array(dtype, n)`` column, Hugging Face ``datasets`` as ``Sequence(length=n)`` (and
``with_format("numpy")`` gives (N, n) arrays), pandas as one numpy array per cell
(``np.stack(df["rhf"])`` is the (N, 300) matrix), while 300 RHF columns make wide, slow
schemas in all three; the element names are in the schema file instead. Values are the
stored arrays bit for bit (no dtype conversion).
"""
from __future__ import annotations

import io as bytes_io
import json
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from relaff_jax import io as rio
from relaff_jax.constants import RELATIONS
from relaff_jax.data.layout import FEATURES_SIDECAR, SIDECAR
from relaff_jax.data.errors import DatasetError
from relaff_jax.data.load import load_dataset, read_features_sidecar
from relaff_jax.data.store import read_sidecar
from relaff_jax.errors import UserError
from relaff_jax.config.perception import PCA_NAMES, RHF_NAMES

FORMATS = ("parquet",)
OBJECTS = ("toy", "other")

# What the fields of a scene dataset (sim.rollouts) and of perception's features mean.
MEANING = {
    "action": "the action tried (constant within one dataset)",
    "rollout": "global rollout index (chunk * batch + i) inside the dataset",
    "label": "True when the action succeeded (positive sample)",
    "relation": f"spatial relation of the settled pair, one of {', '.join(RELATIONS)}",
    "cog_distance": "distance between the two objects' centres of gravity after settling (m)",
    "toy": "name of the object acted on",
    "other": "name of the second object",
    "pair": "index of the (toy, other) pair in the world's pair table",
    "at_rest": "both objects slower than SceneConfig.rest_speed at the end of settling",
    "feasible": "the motor program was executable (every waypoint reachable by IK, the object fits the "
                "gripper); an infeasible program is not run and its label is False",
    "ik_error": "largest IK position error over the program's waypoints (m); NaN where the reach screen "
                "found a target beyond the arm's reach and no IK was solved (action.arm.reach_screen)",
    "intended": "the relation the scene sampler aimed for (index into beside, on_top, inside), before settling",
    "reach_before": "the toy was reachable by the arm before the action (used by unobstruct)",
    "reach_after": "the toy was reachable by the arm after the action (used by unobstruct)",
    "simulated": "the program was simulated (feasible programs only, by the dataset's engine)",
    "rollout_id": "per-scene id (seeds the scene and the depth noise of its features)",
    "qpos0": "object joint positions as placed: toy then other, xyz + quaternion wxyz each",
    "qpos_settled": "object joint positions after settling (the scene the robot sees)",
    "qpos_final": "object joint positions after the action",
    "pca": "PCA state space: 9 values per object, toy then other (see names)",
    "rhf": "relational histogram features: 6 histograms x bins over (toy point, other point) pairs",
    "unseen": "per object (toy, other): too few points to compute its PCA features",
    "n_points": "voxel count per object (toy, other)",
    "overflow": "a perception capacity was exceeded (such samples are refused, so always False)",
}


def export_paths(out: str | os.PathLike, format: str = "parquet") -> dict[str, Path]:
    """The three files ``export_dataset`` writes for ``out``, or a ``UserError`` for an out
    path that cannot be used (checked before any work)."""
    if format not in FORMATS:
        raise UserError(f"unknown export format {format!r}; valid formats: {', '.join(FORMATS)}")
    out = Path(out)
    if out.suffix.lower() == ".parquet":
        if out.is_dir():
            raise UserError(f"{out}: is a folder; give a new .parquet file name or the folder without .parquet")
        paths = {"data": out, "schema": out.with_name(out.stem + ".schema.json"), "card": out.with_name(out.stem + ".md")}
        folder = out.parent
    else:
        if out.exists() and not out.is_dir():
            raise UserError(f"{out}: exists and is not a folder; give a folder or a .parquet file name")
        if out.suffix and not out.exists():
            raise UserError(f"{out}: give a .parquet file name or a folder (a name without a suffix)")
        paths = {"data": out / "data.parquet", "schema": out / "features_schema.json", "card": out / "README.md"}
        folder = out
    rio.check_writable_dir(folder, "--out")  # the one check of every command (relaff_jax.io)
    for p in paths.values():
        if p.is_dir():
            raise UserError(f"{p}: is a folder, cannot write the export there")
    return paths


def export_dataset(dataset_dir: str | os.PathLike, out: str | os.PathLike, format: str = "parquet",
                   *, overwrite: bool = False) -> dict[str, Path]:
    """Write the finished dataset at ``dataset_dir`` as Parquet + feature schema + dataset card.

    Returns ``{"data", "schema", "card"}`` paths. Existing output files are an error unless
    ``overwrite``. Bad ``out``/``format`` and unusable datasets are ``UserError``s, raised
    before anything is loaded or written.
    """
    paths = export_paths(out, format)
    existing = [str(p) for p in paths.values() if p.exists()]
    if existing and not overwrite:
        raise UserError(f"{', '.join(existing)}: already exist; pass overwrite (--overwrite) to replace")
    src = Path(dataset_dir)
    meta = read_sidecar(src)
    if meta["status"] != "complete":
        raise DatasetError(f"{src}: generation not finished; only a finished dataset can be exported")
    fmeta = read_features_sidecar(src)
    data = load_dataset(src)
    table = to_arrow(data)
    schema = feature_schema(data, meta, fmeta)
    buf = _parquet_bytes(table, meta, fmeta)
    rio.atomic_write_bytes(paths["data"], buf)
    rio.atomic_write_json(paths["schema"], schema)
    rio.atomic_write_text(paths["card"], dataset_card(data, meta, fmeta, schema, paths))
    return paths


def columns(data: Mapping[str, Any]) -> list[str]:
    """Column order: action, rollout, label, relation, names, other stored fields, features."""
    first = ["action", "rollout", "label", "relation", "cog_distance", "toy", "other"]
    rest = [k for k in data if k not in first]
    return [k for k in first if k in data] + rest


def to_arrow(data: Mapping[str, Any]):
    """A pyarrow Table of ``load_dataset``'s dict (vectors as fixed-size lists, same dtypes)."""
    import pyarrow as pa

    n = len(data["label"])
    cols = {}
    for k in columns(data):
        v = data[k]
        if k == "action":
            cols[k] = pa.array([v] * n, pa.string())
            continue
        a = np.asarray(v)
        flat = a.reshape(-1)
        arr = pa.array(flat.tolist(), pa.string()) if a.dtype.kind == "U" else pa.array(np.ascontiguousarray(flat))
        for size in reversed(a.shape[1:]):
            arr = pa.FixedSizeListArray.from_arrays(arr, size)
        cols[k] = arr
    return pa.table(cols)


def from_arrow_column(table, name: str) -> np.ndarray:
    """A column of an exported table back as an (N, ...) numpy array with its stored dtype."""
    import pyarrow as pa

    col = table.column(name).combine_chunks()
    shape = [len(col)]
    while pa.types.is_fixed_size_list(col.type):
        shape.append(col.type.list_size)
        col = col.flatten()
    if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
        return np.asarray(col.to_pylist(), dtype=str).reshape(shape)
    return col.to_numpy(zero_copy_only=False).reshape(shape)


def _parquet_bytes(table, meta: Mapping[str, Any], fmeta: Mapping[str, Any] | None) -> bytes:
    import pyarrow.parquet as pq

    info = {"format": meta["format"], "action": meta["action"], "seed": meta["seed"], "n_samples": meta["n_samples"],
            "selection_sha256": meta.get("selection", {}).get("sha256"),
            "features_config": None if fmeta is None else fmeta.get("config")}
    table = table.replace_schema_metadata({b"relaff_jax": json.dumps(info, sort_keys=True).encode()})
    buf = bytes_io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def _rhf_elements(fmeta: Mapping[str, Any] | None, length: int) -> tuple[list[str] | None, list | None]:
    """RHF element names and per-histogram (lo, hi, bins) from the features sidecar config."""
    rhf = ((fmeta or {}).get("config") or {}).get("perception", {}).get("rhf")
    if not rhf or length != len(RHF_NAMES) * int(rhf["bins"]):
        bins = length // len(RHF_NAMES) if length % len(RHF_NAMES) == 0 else None
        if bins is None:
            return None, None
        names = [f"{h}_bin{j:02d}" for h in RHF_NAMES for j in range(bins)]
        return names, [{"histogram": h, "bins": bins, "range": None} for h in RHF_NAMES]
    bins = int(rhf["bins"])
    names = [f"{h}_bin{j:02d}" for h in RHF_NAMES for j in range(bins)]
    hists = [{"histogram": h, "bins": bins, "range": [float(lo), float(hi)],
              "unit": "rad" if h.startswith("angle") else "m"} for h, (lo, hi) in zip(RHF_NAMES, rhf["ranges"])]
    return names, hists


def feature_schema(data: Mapping[str, Any], meta: Mapping[str, Any], fmeta: Mapping[str, Any] | None) -> dict[str, Any]:
    """A JSON Schema (draft 2020-12) of one exported row, with ``x-dtype``, ``x-shape``,
    ``x-feature`` (an attached feature, not a stored rollout field) and ``x-names`` (the
    meaning of each element of a vector column, in order)."""
    feature_names = set(((fmeta or {}).get("features") or {}))
    props: dict[str, Any] = {}
    for k in columns(data):
        if k == "action":
            props[k] = {"type": "string", "x-dtype": "string", "x-shape": [], "description": MEANING[k]}
            continue
        a = np.asarray(data[k])
        dtype = "string" if a.dtype.kind == "U" else a.dtype.name
        item = {"string": "string", "bool": "boolean"}.get(dtype, "integer" if a.dtype.kind in "iu" else "number")
        p: dict[str, Any] = {"x-dtype": dtype, "x-shape": list(a.shape[1:]), "x-feature": k in feature_names}
        if a.ndim == 1:
            p["type"] = item
        else:
            p.update(_nested_array(item, list(a.shape[1:])))
        if k in MEANING:
            p["description"] = MEANING[k]
        if k == "pca" and a.shape[1:] == (2 * len(PCA_NAMES),):
            p["x-names"] = [f"{o}_{n}" for o in OBJECTS for n in PCA_NAMES]
            p["description"] += ("; x, y, z: centroid (m, robot frame); roll, pitch, yaw: the eigenvector "
                                 "frame (rad); eig_*: eigenvalues of the point covariance (m^2), largest first")
        elif k == "rhf" and a.ndim == 2:
            names, hists = _rhf_elements(fmeta, a.shape[1])
            if names is not None:
                p["x-names"] = names
                p["x-histograms"] = hists
                p["description"] += ("; values outside a range go to its end bin; dx, dy, dz "
                                     "of (other point - toy point), dist its length, angle_na_nb between the "
                                     "normals, angle_na_d between the toy normal and the offset")
        elif k in ("unseen", "n_points") and a.shape[1:] == (2,):
            p["x-names"] = list(OBJECTS)
        props[k] = p
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": f"relaff_jax dataset '{meta['action']}': one row per selected sample",
        "type": "object",
        "properties": props,
        "required": list(props),
        "x-rows": int(len(data["label"])),
        "x-features-config": None if fmeta is None else fmeta.get("config"),
    }


def _js(v: Any) -> str:
    return json.dumps(v, indent=2, sort_keys=True, default=str)


def _nested_array(item: str, shape: list[int]) -> dict[str, Any]:
    inner: dict[str, Any] = {"type": item}
    for size in reversed(shape):
        inner = {"type": "array", "items": inner, "minItems": size, "maxItems": size}
    return inner


def dataset_card(data: Mapping[str, Any], meta: Mapping[str, Any], fmeta: Mapping[str, Any] | None,
                 schema: Mapping[str, Any], paths: Mapping[str, Path]) -> str:
    """The README.md dataset card: what the rows are, how they were made, the columns."""
    n = len(data["label"])
    pos = int(np.asarray(data["label"]).sum())
    sel = meta.get("selection", {})
    lines = [
        f"# relaff_jax dataset: action `{meta['action']}`",
        "",
        f"{n} balanced samples ({pos} positive, {n - pos} negative) of the action `{meta['action']}`, "
        f"selected from {meta['counts']['rollouts']} simulated rollouts "
        f"({meta['counts']['positives']} positive) in {meta['counts']['chunks']} chunks of {meta['batch']}.",
        "",
        "Made by `relaff_jax` (a JAX/MuJoCo-MJX reimplementation of Fichtl et al., \"Bootstrapping "
        "Relational Affordances of Object Pairs using Transfer\"): each rollout places an object pair, "
        "settles it, runs the action's motor program and labels success. The selection takes N/2 "
        "positives uniformly and N/2 negatives whose distribution of the distance between the two "
        "objects' centres of gravity matches the positives' (paper IV-D), so that a classifier cannot "
        "learn \"close => success\".",
        "",
        "## Files",
        "",
        f"- `{paths['data'].name}`: the samples, one row each (Parquet).",
        f"- `{paths['schema'].name}`: JSON schema of the columns, with the names of the PCA and RHF elements.",
        f"- `{paths['card'].name}`: this card.",
        "",
        "## Columns",
        "",
        "| column | dtype | shape | meaning |",
        "|---|---|---|---|",
    ]
    for k, p in schema["properties"].items():
        lines.append(f"| `{k}` | {p['x-dtype']} | {tuple(p['x-shape'])} | {p.get('description', '')} |")
    lines += [
        "",
        "Vector columns are Arrow fixed-size lists: `np.stack(pandas_df[\"rhf\"])`, Polars `Array`, "
        "Hugging Face `Sequence(length=...)`.",
        "",
        "```python",
        "import pyarrow.parquet as pq, numpy as np",
        f"t = pq.read_table(\"{paths['data'].name}\")",
        "df = t.to_pandas(); X = np.stack(df[\"pca\"]); y = df[\"label\"].to_numpy()" if "pca" in data else
        "df = t.to_pandas(); y = df[\"label\"].to_numpy()",
        "```",
        "",
        "## How it was made",
        "",
        f"- action: `{meta['action']}`, seed {meta['seed']}, N = {meta['n_samples']}, rollout batch {meta['batch']}",
        f"- negatives borrowed outside their distance bin: {sel.get('borrowed')}; rollout cap reached: {sel.get('at_cap')}",
        f"- selection checksum (sha256 of the selected rollout indices): `{sel.get('sha256')}`",
        "",
        f"Simulation config (`{SIDECAR}` `config`):",
        "",
        "```json", _js(meta.get("config")), "```",
        "",
        "Dataset settings (`dataset_config`, `selection_scheme`):",
        "",
        "```json", _js({"dataset_config": meta.get("dataset_config"), "selection_scheme": meta.get("selection_scheme")}), "```",
        "",
    ]
    if fmeta is not None:
        lines += [f"Features (`{FEATURES_SIDECAR}`): status {fmeta.get('status')}, batch {fmeta.get('batch')}, config:",
                  "", "```json", _js(fmeta.get("config")), "```", ""]
    else:
        lines += ["No features were attached to this dataset.", ""]
    lines += ["## Package versions", "", "Generation:", "", "```json", _js(meta.get("versions")), "```", ""]
    if fmeta is not None:
        lines += ["Features:", "", "```json", _js(fmeta.get("versions")), "```", ""]
    return "\n".join(lines)
