"""Tests of objview.learn, the reader of `objview learn dataset` output; no server needed.

The datasets are written here with numpy itself, following the contract of the module's
documentation.  ``test_reads_rust_written_dataset`` checks a dataset that the Rust writer
produced; it runs only when ``$OBJVIEW_LEARN_DATASET`` names its folder.
"""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

# isort: split
# (objview is first-party seen from python/, third-party from the repository root)
from objview import learn
from objview.learn import (
    CaseDataset,
    iter_batches,
    load_object,
    pool_grid,
    read_manifest,
)

V = 128


def make_object(rng: np.random.Generator, n: int, g: int, first_covered: int) -> dict:
    """n valid cases of one object (``covered`` numbers the cases from ``first_covered``)."""
    grid = rng.uniform(0.1192, 0.971, size=(n, g, g, g)).astype(np.float32)
    visited = np.zeros((n, V), dtype=np.uint8)
    gains = rng.integers(1, 1000, size=(n, V)).astype(np.int32)
    start = rng.integers(0, V, size=n).astype(np.int32)
    step = np.zeros(n, dtype=np.int32)
    for i in range(n):
        k = int(rng.integers(0, 5))
        seen = {int(start[i])} | {int(x) for x in rng.choice(V, size=k, replace=False)}
        visited[i, sorted(seen)] = 1
        gains[i, visited[i] == 1] = 0
        step[i] = len(seen) - 1
    label = gains.argmax(axis=1).astype(np.int64)
    cover = (rng.random((n, V)) < 0.05).astype(np.uint8) * (1 - visited)
    status = rng.integers(-1, 3, size=n).astype(np.int8)
    cover[status == -1] = 0
    return {
        "grid": grid,
        "visited": visited,
        "label": label,
        "gains": gains,
        "cover": cover,
        "cover_status": status,
        "start": start,
        "step": step,
        "covered": np.arange(first_covered, first_covered + n, dtype=np.int32),
        "universe": np.array(5000, dtype=np.int32),
    }


def write_dataset(
    root: Path,
    sizes: dict[str, int],
    *,
    g: int = 4,
    failed: tuple[str, ...] = ("broken",),
    seed: int = 0,
) -> dict[str, dict]:
    """A dataset of objects ``uid -> n cases`` (and failed ones) under root; its arrays by uid."""
    rng = np.random.default_rng(seed)
    (root / "cases").mkdir(parents=True)
    data, files, lines, total = {}, [], [], 0
    for uid, n in sizes.items():
        arrays = make_object(rng, n, g, total)
        rel = f"cases/{uid}.npz"
        np.savez_compressed(root / rel, **arrays)
        data[uid] = arrays
        files.append(rel)
        lines.append({"uid": uid, "file": rel, "cases": n, "universe": 5000})
        total += n
    lines += [{"uid": uid, "error": "no surface"} for uid in failed]
    manifest = {
        "format": "objview-learn-dataset",
        "format_version": 1,
        "method": "nbv-net",
        "views": V,
        "grid": g,
        "settings": {"seed": seed},
        "version": "test",
        "objects": len(sizes),
        "failed": len(failed),
        "cases": total,
        "files": files,
    }
    (root / "manifest.json").write_text(json.dumps(manifest, indent=1))
    (root / "objects.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return data


def expected_cases(data: dict[str, dict]) -> list[dict[str, Any]]:
    return [
        {k: v[j] for k, v in arrays.items() if k != "universe"}
        for arrays in data.values()
        for j in range(len(arrays["label"]))
    ]


def rewrite(path: Path, **changes: Any) -> None:
    """Rewrite an NPZ file with arrays replaced (a value None removes the array)."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            del arrays[k]
        else:
            arrays[k] = v
    np.savez_compressed(path, **arrays)


@pytest.fixture
def dataset(tmp_path: Path) -> tuple[Path, dict[str, dict]]:
    root = tmp_path / "ds"
    return root, write_dataset(root, {"cube": 3, "cone": 0, "bunny": 5, "torus": 2})


def test_round_trip_every_case(dataset):
    root, data = dataset
    m = read_manifest(root)
    assert m["cases"] == 10 and m["grid"] == 4
    assert read_manifest(root / "manifest.json") == m
    ds = CaseDataset(root)
    assert len(ds) == 10 and ds.counts == [3, 0, 5, 2]
    want = expected_cases(data)
    for i, exp in enumerate(want):
        case = ds[i]
        assert case["grid"].dtype == np.float32 and case["grid"].shape == (4, 4, 4)
        assert case["visited"].dtype == np.uint8 and case["visited"].shape == (V,)
        assert case["gains"].dtype == np.int32 and case["cover"].dtype == np.uint8
        assert type(case["label"]) is int and case["label"] == exp["label"]
        for k in ("grid", "visited", "gains", "cover"):
            np.testing.assert_array_equal(case[k], exp[k], err_msg=f"case {i} {k}")
        for k in ("cover_status", "start", "step", "covered"):
            assert case[k] == int(exp[k]), (i, k)
    assert ds[-1]["covered"] == 9 and ds[-10]["covered"] == 0
    assert ds.locate(3) == ("cases/bunny.npz", 0)
    with pytest.raises(IndexError):
        ds[10]
    with pytest.raises(IndexError):
        ds[-11]


def test_load_object_keeps_dtypes(dataset):
    root, data = dataset
    arrays = load_object(root / "cases" / "bunny.npz", grid=4)
    for name, dtype in learn.ARRAYS.items():
        assert arrays[name].dtype == dtype, name
        np.testing.assert_array_equal(arrays[name], data["bunny"][name])
    assert arrays["universe"].shape == () and int(arrays["universe"]) == 5000
    assert load_object(root / "cases" / "cone.npz")["grid"].shape == (0, 4, 4, 4)


def test_cases_are_copies(dataset):
    root, _ = dataset
    ds = CaseDataset(root)
    ds[0]["grid"][:] = 7
    assert ds[0]["grid"].max() < 1


@pytest.mark.parametrize(
    "change,words",
    [
        ({"format_version": 2}, ["format_version", "2"]),
        ({"format_version": True}, ["format_version"]),
        ({"format": "something-else"}, ["format", "something-else"]),
        ({"grid": "64"}, ["grid"]),
        ({"files": "cases/cube.npz"}, ["files"]),
    ],
)
def test_bad_manifest_names_the_file(dataset, change, words):
    root, _ = dataset
    path = root / "manifest.json"
    m = json.loads(path.read_text())
    m.update(change)
    path.write_text(json.dumps(m))
    with pytest.raises(ValueError, match="manifest.json") as e:
        read_manifest(root)
    for w in words:
        assert w in str(e.value)
    with pytest.raises(ValueError, match="manifest.json"):
        CaseDataset(root)


def test_manifest_that_is_not_json(dataset):
    root, _ = dataset
    (root / "manifest.json").write_text("{nope")
    with pytest.raises(ValueError, match=r"manifest\.json.*JSON"):
        read_manifest(root)


def test_wrong_grid_shape_names_file_and_array(dataset):
    root, data = dataset
    path = root / "cases" / "cube.npz"
    rewrite(path, grid=np.zeros((3, 4, 4, 5), dtype=np.float32))
    with pytest.raises(ValueError, match=r"cube\.npz.*'grid'.*shape"):
        load_object(path)
    # a cubic grid of another size than the manifest's
    rewrite(path, grid=np.zeros((3, 2, 2, 2), dtype=np.float32))
    load_object(path)  # consistent in itself
    with pytest.raises(ValueError, match=r"cube\.npz.*'grid'"):
        load_object(path, grid=4)
    ds = CaseDataset(root)
    with pytest.raises(ValueError, match=r"cube\.npz.*'grid'"):
        ds[0]
    # the cases of another file still load
    assert ds[3]["covered"] == int(data["bunny"]["covered"][0])


def test_wrong_case_count_names_file_and_array(dataset):
    root, _ = dataset
    path = root / "cases" / "bunny.npz"
    rewrite(path, visited=np.zeros((4, V), dtype=np.uint8))
    with pytest.raises(ValueError, match=r"bunny\.npz.*'visited'.*\[5, 128\]"):
        load_object(path)


def test_missing_array_names_file_and_array(dataset):
    root, _ = dataset
    path = root / "cases" / "torus.npz"
    rewrite(path, cover=None)
    with pytest.raises(ValueError, match=r"torus\.npz.*'cover'"):
        load_object(path)


def test_wrong_dtype_names_file_and_array(dataset):
    root, data = dataset
    path = root / "cases" / "torus.npz"
    rewrite(path, label=data["torus"]["label"].astype(np.int32))
    with pytest.raises(ValueError, match=r"torus\.npz.*'label'.*int32"):
        load_object(path)


def test_not_an_npz_names_the_file(dataset):
    root, _ = dataset
    path = root / "cases" / "torus.npz"
    path.write_bytes(b"garbage")
    with pytest.raises(ValueError, match=r"torus\.npz"):
        load_object(path)
    np.save(root / "plain.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"plain\.npy.*not an \.npz"):
        load_object(root / "plain.npy")


def test_count_differing_from_objects_jsonl(dataset):
    root, _ = dataset
    lines = [json.loads(x) for x in (root / "objects.jsonl").read_text().splitlines()]
    lines[0]["cases"] = 4
    (root / "objects.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    ds = CaseDataset(root)
    assert len(ds) == 11
    with pytest.raises(ValueError, match=r"cube\.npz.*3 cases.*objects\.jsonl.*4"):
        ds[0]


def test_without_objects_jsonl_counts_by_loading(dataset):
    root, data = dataset
    (root / "objects.jsonl").unlink()
    ds = CaseDataset(root, objects=["torus"])
    assert len(ds) == 2 and ds[1]["covered"] == int(data["torus"]["covered"][1])
    assert len(CaseDataset(root)) == 10


def test_files_and_objects_select(dataset):
    root, data = dataset
    ds = CaseDataset(root, files=["cases/torus.npz", root / "cases" / "cube.npz"])
    assert ds.files == ["cases/torus.npz", "cases/cube.npz"] and len(ds) == 5
    assert ds[0]["covered"] == int(data["torus"]["covered"][0])
    assert ds[2]["covered"] == int(data["cube"]["covered"][0])
    ds = CaseDataset(root, objects=["bunny", "cube"])  # manifest order
    assert ds.files == ["cases/cube.npz", "cases/bunny.npz"] and len(ds) == 8
    assert len(CaseDataset(root, objects="torus")) == 2
    ds = CaseDataset(root, files=["cases/torus.npz"], objects=["torus", "cube"])
    assert ds.files == ["cases/torus.npz"]
    with pytest.raises(ValueError, match="broken.*no surface"):
        CaseDataset(root, objects=["broken"])
    with pytest.raises(ValueError, match="'teapot'"):
        CaseDataset(root, objects=["teapot"])
    with pytest.raises(ValueError, match=r"cases/teapot\.npz"):
        CaseDataset(root, files=["cases/teapot.npz"])


def count_loads(monkeypatch) -> list[str]:
    """Records the file name of every ``learn.load_object`` call (the list grows as it runs)."""
    loads: list[str] = []
    real = learn.load_object

    def counting(path, **kw):
        loads.append(Path(path).name)
        return real(path, **kw)

    monkeypatch.setattr(learn, "load_object", counting)
    return loads


def test_lru_cache_loads_each_object_once(dataset, monkeypatch):
    root, _ = dataset
    loads = count_loads(monkeypatch)
    ds = CaseDataset(root, cache_size=2)
    for i in range(len(ds)):
        ds[i]
    assert loads == ["cube.npz", "bunny.npz", "torus.npz"]
    ds[3]  # bunny: still cached
    assert len(loads) == 3
    ds[0]  # cube: evicted by torus
    assert loads[-1] == "cube.npz" and len(loads) == 4
    ds[4]  # bunny: used more recently than torus, so torus was evicted, not bunny
    assert len(loads) == 4
    ds[8]
    assert loads[-1] == "torus.npz" and len(loads) == 5
    ds0 = CaseDataset(root, cache_size=0)
    ds0[0]
    ds0[0]
    assert loads[-2:] == ["cube.npz", "cube.npz"]


def test_dataset_pickles_without_its_cache(dataset):
    root, _ = dataset
    ds = CaseDataset(root)
    ds[0]
    clone = pickle.loads(pickle.dumps(ds))
    assert clone._cache == {} and len(clone) == len(ds)
    np.testing.assert_array_equal(clone[4]["grid"], ds[4]["grid"])


def test_transform_is_applied(dataset):
    root, _ = dataset
    ds = CaseDataset(root, transform=lambda c: {**c, "grid": pool_grid(c["grid"], 2)})
    assert ds[0]["grid"].shape == (2, 2, 2)


def brute_pool(grid: np.ndarray, f: int) -> np.ndarray:
    a, b, c = (s // f for s in grid.shape)
    out = np.zeros((a, b, c), dtype=np.float64)
    for i in range(a):
        for j in range(b):
            for k in range(c):
                total = 0.0
                for di in range(f):
                    for dj in range(f):
                        for dk in range(f):
                            total += float(grid[i * f + di, j * f + dj, k * f + dk])
                out[i, j, k] = total / f**3
    return out


def test_pool_grid_is_the_block_mean():
    rng = np.random.default_rng(3)
    grid = rng.random((4, 4, 4)).astype(np.float32)
    pooled = pool_grid(grid, 2)
    assert pooled.dtype == np.float32 and pooled.shape == (2, 2, 2)
    np.testing.assert_allclose(pooled, brute_pool(grid, 2), rtol=1e-6, atol=0)
    assert pool_grid(grid, 4).item() == pytest.approx(
        float(grid.astype(np.float64).mean())
    )
    np.testing.assert_array_equal(pool_grid(grid, 1), grid)
    # leading axes are kept; every grid of a batch is pooled on its own
    batch = rng.random((3, 2, 6, 6, 6)).astype(np.float32)
    pooled = pool_grid(batch, 3)
    assert pooled.shape == (3, 2, 2, 2, 2)
    for i in range(3):
        for j in range(2):
            np.testing.assert_allclose(
                pooled[i, j], brute_pool(batch[i, j], 3), rtol=1e-6
            )
    with pytest.raises(ValueError, match="divide"):
        pool_grid(grid, 3)
    with pytest.raises(ValueError):
        pool_grid(grid, 0)
    with pytest.raises(ValueError):
        pool_grid(np.zeros((4, 4)), 2)


def batches_covered(batches: list[dict[str, np.ndarray]]) -> list[int]:
    return [int(c) for b in batches for c in b["covered"]]


def test_iter_batches_in_order(dataset):
    root, data = dataset
    batches = list(iter_batches(root, 4))
    assert [len(b["label"]) for b in batches] == [4, 4, 2]
    assert batches_covered(batches) == list(range(10))
    b = batches[0]
    assert b["grid"].shape == (4, 4, 4, 4) and b["grid"].dtype == np.float32
    assert b["label"].dtype == np.int64 and b["visited"].shape == (4, V)
    assert b["cover_status"].dtype == np.int64
    np.testing.assert_array_equal(b["label"][:3], data["cube"]["label"])
    np.testing.assert_array_equal(b["gains"][3], data["bunny"]["gains"][0])
    assert [len(b["label"]) for b in iter_batches(root, 4, drop_last=True)] == [4, 4]
    with pytest.raises(ValueError):
        next(iter_batches(root, 0))


@pytest.mark.parametrize("window", [None, 1, 2, 10])
def test_iter_batches_shuffle_is_deterministic_and_complete(tmp_path, window):
    sizes = {f"obj{i}": n for i, n in enumerate([7, 0, 3, 12, 5, 1, 9])}
    root = tmp_path / "ds"
    write_dataset(root, sizes, g=2)
    total = sum(sizes.values())

    def epoch(seed: int) -> list[int]:
        return batches_covered(
            list(iter_batches(root, 5, shuffle=True, seed=seed, window=window))
        )

    a, b, c = epoch(1), epoch(1), epoch(2)
    assert a == b
    assert sorted(a) == list(range(total)) and sorted(c) == list(range(total))
    assert a != c and a != list(range(total))
    ds = CaseDataset(root)
    order = ds.epoch_order(1, window=window)
    assert order.dtype == np.int64 and order.tolist() == a
    # the cases of an object are shuffled too, not only the objects
    obj_of = np.searchsorted(ds._offsets, order, side="right") - 1
    runs = [order[obj_of == k].tolist() for k in range(len(ds.files))]
    assert any(r != sorted(r) for r in runs)
    if window == 1:  # one object at a time
        changes = int((np.diff(obj_of) != 0).sum())
        assert changes == sum(1 for n in sizes.values() if n) - 1


def test_shuffled_epoch_loads_each_object_once(tmp_path, monkeypatch):
    root = tmp_path / "ds"
    write_dataset(root, {f"obj{i}": 4 for i in range(9)}, g=2)
    loads = count_loads(monkeypatch)
    ds = CaseDataset(root, cache_size=3)
    every = sorted(f"obj{i}.npz" for i in range(9))
    for seed in range(3):
        loads.clear()
        assert len(list(iter_batches(ds, 4, shuffle=True, seed=seed))) == 9
        assert len(set(loads)) == len(loads), (
            seed
        )  # (objects still cached are not reloaded)
        if seed == 0:
            assert sorted(loads) == every
        ds._cache.clear()
        loads.clear()
        assert len(list(iter_batches(ds, 4, shuffle=True, seed=seed))) == 9
        assert sorted(loads) == every, seed
    with pytest.raises(ValueError):
        next(iter_batches(ds, 4, objects=["obj1"]))


def test_torch_dataloader(dataset):
    torch = pytest.importorskip("torch")
    from torch.utils.data import DataLoader

    root, _ = dataset
    ds = CaseDataset(root)
    loader = DataLoader(ds, batch_size=4, sampler=ds.epoch_order(0).tolist())
    seen = []
    for batch in loader:
        assert batch["grid"].dtype == torch.float32 and batch["grid"].shape[1:] == (
            4,
            4,
            4,
        )
        assert batch["label"].dtype == torch.int64
        seen += batch["covered"].tolist()
    assert sorted(seen) == list(range(10))


# ----------------------------------------------------------------------- Rust-written output
def check_case_arrays(path: Path, a: dict[str, np.ndarray], grid: int) -> None:
    """The contract's value ranges on one object's arrays (load_object checked the shapes)."""
    n = len(a["label"])
    where = str(path)
    assert a["grid"].shape == (n, grid, grid, grid), where
    if n:
        assert a["grid"].min() >= 0.1192 - 1e-6, where
        assert a["grid"].max() <= 0.971 + 1e-6, where
    assert np.isin(a["visited"], [0, 1]).all(), where
    assert np.isin(a["cover"], [0, 1]).all(), where
    label = a["label"]
    assert ((label >= 0) & (label < V)).all(), where
    rows = np.arange(n)
    assert (a["visited"][rows, label] == 0).all(), f"{where}: a label view was visited"
    gains = a["gains"]
    assert (gains >= 0).all(), where
    assert (gains[rows, label] == gains.max(axis=1)).all(), (
        f"{where}: label is not a best gain"
    )
    assert (gains[a["visited"] == 1] == 0).all(), f"{where}: a visited view has a gain"
    status = a["cover_status"]
    assert np.isin(status, [-1, 0, 1, 2]).all(), where
    assert (a["cover"][status == -1] == 0).all(), (
        f"{where}: a cover that was not computed"
    )
    assert ((a["start"] >= 0) & (a["start"] < V)).all(), where
    assert (a["visited"][rows, a["start"]] == 1).all(), (
        f"{where}: the start view not visited"
    )
    assert (a["step"] == a["visited"].sum(axis=1).astype(np.int32) - 1).all(), where
    universe = int(a["universe"])
    assert ((a["covered"] >= 0) & (a["covered"] <= universe)).all(), where


@pytest.mark.skipif(
    not os.environ.get("OBJVIEW_LEARN_DATASET"),
    reason="$OBJVIEW_LEARN_DATASET is not set (scripts/test.sh sets it)",
)
def test_reads_rust_written_dataset():
    # Set but missing is a failure: the Rust test that writes the folder did not run or keep it.
    root = Path(os.environ["OBJVIEW_LEARN_DATASET"])
    assert root.is_dir(), f"{root}: no dataset (the Rust dataset test keeps one there)"
    m = read_manifest(root)
    assert m["method"] in ("nbv-net", "ma-scvp")
    assert m["views"] == V and m["grid"] == 64
    assert isinstance(m["settings"], dict) and isinstance(m["version"], str)
    assert len(m["files"]) == m["objects"]
    records = learn.read_objects(root)
    with_data = [r for r in records if "error" not in r]
    assert len(with_data) == m["objects"]
    assert len(records) - len(with_data) == m["failed"]
    assert [r["file"] for r in with_data] == m["files"]
    total = 0
    for rec in with_data:
        path = root / rec["file"]
        a = load_object(path, grid=m["grid"], views=m["views"])
        for name, dtype in learn.ARRAYS.items():
            assert a[name].dtype == dtype, (path, name)
        check_case_arrays(path, a, m["grid"])
        assert len(a["label"]) == rec["cases"], path
        assert int(a["universe"]) == rec["universe"], path
        total += len(a["label"])
    assert total == m["cases"]
    ds = CaseDataset(root)
    assert len(ds) == m["cases"]
    if len(ds):
        case = ds[len(ds) - 1]
        assert case["grid"].shape == (64, 64, 64) and 0 <= case["label"] < V
