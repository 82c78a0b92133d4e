"""Reader of the oracle training data of the learned planners (numpy only).

``objview learn dataset POOL --method nbv-net --out DIR`` writes, for every object of the
pool, oracle rollouts over the Tammes-128 view set and the labels of NBV-Net (the next best
view) and MA-SCVP (the residual set cover).  This module reads that folder; its layout is the
contract below (``format_version`` 1).

``DIR/manifest.json``
    A JSON object with at least ``"format": "objview-learn-dataset"``, ``"format_version": 1``,
    ``"method"`` (``"nbv-net"`` or ``"ma-scvp"``), ``"views"`` (128), ``"grid"`` (G, 64),
    ``"settings"`` (the generator's settings), ``"version"`` (of objview), ``"objects"``
    (objects with data), ``"failed"`` (objects that failed), ``"cases"`` (the total number of
    cases) and ``"files"``: the per-object NPZ files, relative to DIR, in input order
    (``"cases/<uid>.npz"``).

``DIR/objects.jsonl``
    One JSON object per line and object: ``{"uid", "file", "cases", "universe", …}`` for an
    object with data, ``{"uid", "error"}`` for one that failed.

``DIR/cases/<uid>.npz``
    A standard numpy ``.npz`` (a zip of little-endian ``.npy`` arrays, readable with
    :func:`numpy.load`), ``n`` cases of one object:

    ================  =======  ============  ==================================================
    array             dtype    shape         meaning
    ================  =======  ============  ==================================================
    ``grid``          float32  [n, G, G, G]  occupancy probabilities in [0.1192, 0.971], 0.5
                                             unknown; C order ``[x][y][z]`` (x outermost)
    ``visited``       uint8    [n, 128]      1 where the view was visited in the case
    ``label``         int64    [n]           the oracle's next best view, 0..127 (NBV-Net)
    ``gains``         int32    [n, 128]      each view's marginal new-voxel gain (0 if visited)
    ``cover``         uint8    [n, 128]      multi-hot residual set cover (MA-SCVP); all zero
                                             when not computed
    ``cover_status``  int8     [n]           -1 not computed, 0 optimal, 1 time limit
                                             (incumbent), 2 solver error
    ``start``         int32    [n]           the rollout's start view
    ``step``          int32    [n]           the step of the rollout (visited count - 1)
    ``covered``       int32    [n]           voxels covered before the move
    ``universe``      int32    [] (0-d)      the size of the object's universe U
    ================  =======  ============  ==================================================

Reading:

- :func:`read_manifest`, :func:`read_objects`: the two JSON files, validated.
- :func:`load_object`: one NPZ file, every array checked against the table above.
- :class:`CaseDataset`: a map-style dataset of single cases (``len`` and ``ds[i]``), usable
  as it is by ``torch.utils.data.DataLoader``; files are loaded whole, lazily, and kept in a
  small LRU cache of objects.  :meth:`CaseDataset.epoch_order` is a shuffled order that stays
  within a few objects at a time (so that the cache holds), usable as a DataLoader sampler.
- :func:`iter_batches`: stacked numpy batches, deterministic for a seed.
- :func:`pool_grid`: average pooling of grids by an integer factor (64 → 32 with 2).

    from objview.learn import CaseDataset, iter_batches, pool_grid
    for batch in iter_batches("out/nbv-data", 64, shuffle=True, seed=epoch):
        x = pool_grid(batch["grid"], 2)      # [B, 32, 32, 32] float32
        y = batch["label"]                   # [B] int64
"""

from __future__ import annotations

import json
import operator
import os
import pickle
import zipfile
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ARRAYS",
    "FORMAT",
    "FORMAT_VERSION",
    "VIEWS",
    "CaseDataset",
    "collate",
    "iter_batches",
    "load_object",
    "pool_grid",
    "read_manifest",
    "read_objects",
]

#: The manifest's ``"format"``.
FORMAT = "objview-learn-dataset"
#: The ``"format_version"`` this module reads.
FORMAT_VERSION = 1
#: The number of views (Tammes-128).
VIEWS = 128

#: Every array of an object's NPZ file and its dtype (see the module's documentation).
ARRAYS: dict[str, np.dtype[Any]] = {
    "grid": np.dtype(np.float32),
    "visited": np.dtype(np.uint8),
    "label": np.dtype(np.int64),
    "gains": np.dtype(np.int32),
    "cover": np.dtype(np.uint8),
    "cover_status": np.dtype(np.int8),
    "start": np.dtype(np.int32),
    "step": np.dtype(np.int32),
    "covered": np.dtype(np.int32),
    "universe": np.dtype(np.int32),
}

#: Per-case arrays of one value per view.
_PER_VIEW = ("visited", "gains", "cover")
#: Per-case scalars; a case of :class:`CaseDataset` has them as Python ints.
_PER_CASE = ("label", "cover_status", "start", "step", "covered")


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _manifest_path(root: str | os.PathLike[str]) -> Path:
    p = Path(root)
    return p if p.is_file() else p / "manifest.json"


def _dataset_dir(root: str | os.PathLike[str]) -> Path:
    p = Path(root)
    return p.parent if p.is_file() else p


def read_manifest(root: str | os.PathLike[str]) -> dict[str, Any]:
    """The dataset's ``manifest.json`` (``root`` is the dataset folder or the file itself).

    Raises :class:`ValueError` naming the file when it is not JSON, not an objview learn
    dataset (``"format"``), of another ``"format_version"``, or when ``"files"``, ``"grid"``
    or ``"views"`` are missing or malformed.
    """
    path = _manifest_path(root)
    text = path.read_text(encoding="utf-8")
    try:
        m = json.loads(text)
    except ValueError as e:
        raise ValueError(f"{path}: not valid JSON: {e}") from None
    if not isinstance(m, dict):
        raise ValueError(f"{path}: expected a JSON object, found {type(m).__name__}")  # noqa: TRY004
    if m.get("format") != FORMAT:
        raise ValueError(
            f'{path}: "format" is {m.get("format")!r}, expected {FORMAT!r} '
            "(not an objview learn dataset)"
        )
    version = m.get("format_version")
    if version != FORMAT_VERSION or not _is_int(version):
        raise ValueError(
            f'{path}: "format_version" is {version!r}; this reader supports version '
            f"{FORMAT_VERSION} only"
        )
    for key in ("grid", "views"):
        if not _is_int(m.get(key)) or m[key] < 1:
            raise ValueError(
                f"{path}: {key!r} is {m.get(key)!r}, expected a positive integer"
            )
    files = m.get("files")
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        raise ValueError(f'{path}: "files" must be a list of relative paths')
    if len(set(files)) != len(files):
        raise ValueError(f'{path}: "files" lists a file twice')
    return m


def read_objects(root: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The lines of the dataset's objects files, in order (blank lines skipped).

    The files are the manifest's ``objects_files`` (``objects.jsonl``, or one
    ``objects.shard-I-of-N.jsonl`` per shard written into the folder), in that order;
    ``objects.jsonl`` when the manifest does not list them.  Raises :class:`ValueError` naming
    the file and line when a line is not a JSON object with a ``"uid"``.
    """
    folder = _dataset_dir(root)
    names: list[str] = ["objects.jsonl"]
    manifest_path = folder / "manifest.json"
    if manifest_path.is_file():
        try:
            listed = json.loads(manifest_path.read_text(encoding="utf-8")).get(
                "objects_files"
            )
        except ValueError:
            listed = None
        if (
            isinstance(listed, list)
            and listed
            and all(isinstance(n, str) for n in listed)
        ):
            names = listed
    out: list[dict[str, Any]] = []
    for name in names:
        if Path(name).name != name:
            raise ValueError(
                f"{manifest_path}: objects file {name!r} is not a plain file name"
            )
        path = folder / name
        with open(path, encoding="utf-8") as f:
            for no, line in enumerate(f, 1):
                if not line.strip():
                    continue
                try:
                    rec = json.loads(line)
                except ValueError as e:
                    raise ValueError(f"{path}:{no}: not valid JSON: {e}") from None
                if not isinstance(rec, dict) or "uid" not in rec:
                    raise ValueError(
                        f'{path}:{no}: expected a JSON object with a "uid"'
                    )
                out.append(rec)
    return out


def load_object(
    path: str | os.PathLike[str], *, grid: int | None = None, views: int = VIEWS
) -> dict[str, np.ndarray]:
    """Load one object's NPZ file fully: every array of :data:`ARRAYS` (extra arrays are kept).

    The arrays are checked against the contract: present, of the right dtype (returned in the
    native byte order) and of consistent shapes, ``n`` cases of ``[G, G, G]`` grids (``G`` =
    ``grid`` when given) and ``views`` views.  Raises :class:`ValueError` naming the file and
    the array otherwise (:class:`FileNotFoundError` for a missing file).
    """
    path = Path(path)
    unreadable = (
        OSError,
        ValueError,
        EOFError,
        zipfile.BadZipFile,
        pickle.UnpicklingError,
    )
    try:
        loaded = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except unreadable as e:
        raise ValueError(f"{path}: not a readable .npz file: {e}") from None
    if not isinstance(loaded, np.lib.npyio.NpzFile):  # a plain .npy gives an array
        raise ValueError(f"{path}: not an .npz file (a zip of .npy arrays)")  # noqa: TRY004
    arrays: dict[str, np.ndarray] = {}
    with loaded as npz:
        for name in npz.files:
            try:
                arrays[name] = npz[name]
            except unreadable as e:
                raise ValueError(f"{path}: array {name!r} is unreadable: {e}") from None
    missing = [name for name in ARRAYS if name not in arrays]
    if missing:
        raise ValueError(
            f"{path}: missing array(s) {', '.join(repr(m) for m in missing)} "
            f"(the file has {sorted(arrays)})"
        )
    for name, dtype in ARRAYS.items():
        a = arrays[name]
        if a.dtype.kind != dtype.kind or a.dtype.itemsize != dtype.itemsize:
            raise ValueError(
                f"{path}: array {name!r} has dtype {a.dtype}, expected {dtype}"
            )
        arrays[name] = a.astype(dtype, copy=False)

    def bad_shape(name: str, expected: str) -> ValueError:
        shape = tuple(arrays[name].shape)
        return ValueError(
            f"{path}: array {name!r} has shape {shape}, expected {expected}"
        )

    if arrays["label"].ndim != 1:
        raise bad_shape("label", "[n]")
    n = int(arrays["label"].shape[0])
    g = arrays["grid"]
    want_g = "G" if grid is None else str(grid)
    if (
        g.ndim != 4
        or g.shape[0] != n
        or not (g.shape[1] == g.shape[2] == g.shape[3])
        or (grid is not None and g.shape[1] != grid)
    ):
        raise bad_shape("grid", f"[{n}, {want_g}, {want_g}, {want_g}] (n = {n} labels)")
    for name in _PER_VIEW:
        if arrays[name].shape != (n, views):
            raise bad_shape(name, f"[{n}, {views}]")
    for name in _PER_CASE:
        if arrays[name].shape != (n,):
            raise bad_shape(name, f"[{n}]")
    if arrays["universe"].shape != ():
        raise bad_shape("universe", "[] (0-d)")
    return arrays


def pool_grid(grid: np.ndarray, factor: int) -> np.ndarray:
    """Average-pool ``[..., A, B, C]`` grids by an integer ``factor`` along the last 3 axes.

    Each output voxel is the mean of its ``factor³`` block (64 → 32 with ``factor`` 2),
    computed in float64 and returned as float32.  Raises :class:`ValueError` when ``factor``
    does not divide the grid's size.
    """
    f = operator.index(factor)
    if f < 1:
        raise ValueError(
            f"pool_grid: factor must be a positive integer, not {factor!r}"
        )
    g = np.asarray(grid)
    if g.ndim < 3:
        raise ValueError(
            f"pool_grid: expected [..., A, B, C] grids, got shape {g.shape}"
        )
    *lead, a, b, c = g.shape
    if a % f or b % f or c % f:
        raise ValueError(
            f"pool_grid: factor {f} does not divide the grid size {(a, b, c)}"
        )
    blocks = g.reshape(*lead, a // f, f, b // f, f, c // f, f)
    nd = blocks.ndim
    pooled = blocks.mean(axis=(nd - 5, nd - 3, nd - 1), dtype=np.float64)
    return np.asarray(pooled, dtype=np.float32)


def collate(items: Sequence[dict[str, Any]]) -> dict[str, np.ndarray]:
    """Stack cases (dicts of arrays and ints) into a batch: one array per key, cases first.

    Python ints become int64 arrays; anything else is stacked with :func:`numpy.stack`.
    """
    if not items:
        raise ValueError("collate: no cases")
    out: dict[str, np.ndarray] = {}
    for key in items[0]:
        values = [it[key] for it in items]
        if all(_is_int(v) for v in values):
            out[key] = np.asarray(values, dtype=np.int64)
        else:
            out[key] = np.stack([np.asarray(v) for v in values])
    return out


class CaseDataset:
    """The cases of a learn dataset, one per index: a map-style dataset (PyTorch's sense).

    ``ds[i]`` is a dict of one case: ``grid`` ``[G, G, G]`` float32, ``visited``, ``gains``
    and ``cover`` ``[128]`` arrays (uint8, int32, uint8) and ``label``, ``cover_status``,
    ``start``, ``step``, ``covered`` as Python ints; arrays are copies (the caller may modify
    them).  ``transform``, when given, is applied to that dict.  Cases are ordered by file (the
    manifest's order, or ``files``'), then as in the file.

    ``files``: a subset of the manifest's ``"files"`` (relative paths, in the order to use).
    ``objects``: keep only these uids (mapped to files through ``objects.jsonl``; an unknown
    or failed uid is a :class:`ValueError`; with ``files`` too, both apply).  ``cache_size``: how many whole objects stay
    loaded (an object of n cases holds n MiB of 64³ grids).

    The case counts come from ``objects.jsonl`` (a file without one there is loaded once to
    count); a file whose count differs when it is loaded raises :class:`ValueError`.  The cache
    is not pickled, so the dataset can go to DataLoader worker processes.
    """

    def __init__(
        self,
        root: str | os.PathLike[str],
        *,
        files: Iterable[str | os.PathLike[str]] | None = None,
        objects: Iterable[str] | str | None = None,
        cache_size: int = 4,
        transform: Callable[[dict[str, Any]], Any] | None = None,
    ):
        self.root = _dataset_dir(root)
        self.manifest = read_manifest(self.root)
        self.grid = int(self.manifest["grid"])
        self.views = int(self.manifest["views"])
        self.cache_size = max(0, int(cache_size))
        self.transform = transform
        listed: list[str] = list(self.manifest["files"])
        records = (
            read_objects(self.root) if (self.root / "objects.jsonl").is_file() else []
        )
        by_file = {r["file"]: r for r in records if isinstance(r.get("file"), str)}

        if files is None:
            selected = listed
        else:
            selected = []
            known = set(listed)
            for f in files:
                rel = self._relative(f)
                if rel not in known:
                    raise ValueError(
                        f'{self.root / "manifest.json"}: {rel!r} is not one of its "files"'
                    )
                if rel in selected:
                    raise ValueError(f"CaseDataset: file {rel!r} given twice")
                selected.append(rel)

        if objects is not None:
            uids = [objects] if isinstance(objects, str) else list(objects)
            uid_file: dict[str, str] = {}
            if records:
                for r in records:
                    if isinstance(r.get("file"), str):
                        uid_file[str(r["uid"])] = r["file"]
                errors = {
                    str(r["uid"]): r.get("error") for r in records if "error" in r
                }
            else:  # no objects.jsonl: the uid is the file's stem
                uid_file = {Path(f).stem: f for f in listed}
                errors = {}
            wanted = set()
            for uid in uids:
                if uid in errors:
                    raise ValueError(
                        f"{self.root}: object {uid!r} has no data (it failed: {errors[uid]})"
                    )
                if uid not in uid_file:
                    raise ValueError(f"{self.root}: no object {uid!r} in the dataset")
                wanted.add(uid_file[uid])
            selected = [f for f in selected if f in wanted]

        self.files: list[str] = selected
        self._cache: OrderedDict[str, dict[str, np.ndarray]] = OrderedDict()
        counts: list[int] = []
        for rel in selected:
            n: Any = by_file.get(rel, {}).get("cases")
            if _is_int(n) and n >= 0:
                counts.append(n)
            else:  # no count in objects.jsonl: load the file to count
                counts.append(int(self._load(rel)["label"].shape[0]))
        self.counts = counts
        self._offsets = np.zeros(len(counts) + 1, dtype=np.int64)
        np.cumsum(counts, out=self._offsets[1:])

    def _relative(self, f: str | os.PathLike[str]) -> str:
        p = Path(f)
        if p.is_absolute():
            try:
                p = p.relative_to(self.root)
            except ValueError:
                raise ValueError(f"CaseDataset: {p} is not under {self.root}") from None
        return p.as_posix()

    def __repr__(self) -> str:
        return (
            f"CaseDataset({str(self.root)!r}: {len(self)} cases of {len(self.files)} objects, "
            f"method {self.manifest.get('method')!r}, grid {self.grid})"
        )

    def __len__(self) -> int:
        return int(self._offsets[-1])

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_cache"] = OrderedDict()
        return state

    def locate(self, index: int) -> tuple[str, int]:
        """The file of case ``index`` and the case's index in it (negative indices count back)."""
        i = operator.index(index)
        total = len(self)
        if i < 0:
            i += total
        if not 0 <= i < total:
            raise IndexError(f"case index {index} out of range for {total} cases")
        k = int(np.searchsorted(self._offsets, i, side="right")) - 1
        return self.files[k], i - int(self._offsets[k])

    def _load(self, rel: str) -> dict[str, np.ndarray]:
        arrays = load_object(self.root / rel, grid=self.grid, views=self.views)
        if self.cache_size:
            self._cache[rel] = arrays
            while len(self._cache) > self.cache_size:
                self._cache.popitem(last=False)
        return arrays

    def object_arrays(self, file: str) -> dict[str, np.ndarray]:
        """All arrays of one selected file (through the cache; do not modify them)."""
        arrays = self._cache.get(file)
        if arrays is not None:
            self._cache.move_to_end(file)
            return arrays
        k = self.files.index(file)
        arrays = self._load(file)
        n = int(arrays["label"].shape[0])
        if n != self.counts[k]:
            raise ValueError(
                f"{self.root / file}: has {n} cases, objects.jsonl says {self.counts[k]}"
            )
        return arrays

    def __getitem__(self, index: int) -> Any:
        rel, j = self.locate(index)
        a = self.object_arrays(rel)
        case: dict[str, Any] = {"grid": a["grid"][j].copy()}
        for name in _PER_VIEW:
            case[name] = a[name][j].copy()
        for name in _PER_CASE:
            case[name] = int(a[name][j])
        return self.transform(case) if self.transform is not None else case

    def epoch_order(self, seed: int = 0, *, window: int | None = None) -> np.ndarray:
        """A shuffled order of all case indices (each once), deterministic for ``seed``.

        The objects are shuffled, then taken ``window`` at a time (default: ``cache_size``, at
        least 1) and the cases of each window shuffled together, so that a pass in this order
        loads every file once.  Use a different seed per epoch; the array can be a DataLoader's
        ``sampler``.
        """
        w = max(1, self.cache_size) if window is None else operator.index(window)
        if w < 1:
            raise ValueError(f"epoch_order: window must be positive, not {window!r}")
        rng = np.random.default_rng(seed)
        objs = rng.permutation(len(self.files))
        parts = []
        for s in range(0, len(objs), w):
            idx = [
                np.arange(self._offsets[k], self._offsets[k + 1])
                for k in objs[s : s + w]
            ]
            parts.append(rng.permutation(np.concatenate(idx)))
        if not parts:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate(parts).astype(np.int64)


def iter_batches(
    root: str | os.PathLike[str] | CaseDataset,
    batch_size: int,
    *,
    shuffle: bool = False,
    seed: int = 0,
    drop_last: bool = False,
    window: int | None = None,
    files: Iterable[str | os.PathLike[str]] | None = None,
    objects: Iterable[str] | str | None = None,
) -> Iterator[dict[str, np.ndarray]]:
    """One epoch of stacked batches (:func:`collate` of ``batch_size`` cases).

    ``root``: a dataset folder (``files``/``objects`` select from it as in
    :class:`CaseDataset`) or a :class:`CaseDataset`.  Without ``shuffle`` the cases come in
    dataset order; with it, in :meth:`CaseDataset.epoch_order` of ``seed`` (and ``window``).
    Every case comes once; the last batch is smaller unless ``drop_last``.
    """
    bs = operator.index(batch_size)
    if bs < 1:
        raise ValueError(
            f"iter_batches: batch_size must be positive, not {batch_size!r}"
        )
    if isinstance(root, CaseDataset):
        if files is not None or objects is not None:
            raise ValueError(
                "iter_batches: files/objects select from a folder, not a dataset"
            )
        ds = root
    else:
        ds = CaseDataset(root, files=files, objects=objects)
    order = ds.epoch_order(seed, window=window) if shuffle else np.arange(len(ds))
    for s in range(0, len(order), bs):
        chunk = order[s : s + bs]
        if drop_last and len(chunk) < bs:
            break
        yield collate([ds[int(i)] for i in chunk])
